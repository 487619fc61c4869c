"""Aggregation rules (eqs. (8)-(20)) and the UCBs of Theorems 1-3."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents import aggregation as agg
from agents import gp

METHODS = ["poe", "gpoe", "bcm", "rbcm"]


@pytest.mark.parametrize("method", METHODS)
def test_one_expert_is_returned_unchanged(method):
    result = agg.aggregate(method, np.array([[3.0]]), np.array([[0.5]]), np.array([2.0]))
    assert result.mean[0] == 3.0 and result.var[0] == 0.5


def test_poe_of_identical_experts_divides_the_variance():
    for m in (2, 5, 9):
        result = agg.aggregate("poe", np.full(m, 1.5), np.full(m, 0.8), 4.0)
        assert result.mean == pytest.approx(1.5) and result.var == pytest.approx(0.8 / m)


def test_aggregations_by_hand():
    mean, var, prior = np.array([1.0, 3.0]), np.array([1.0, 0.5]), 4.0
    # PoE: precision 1 + 2 = 3; mean (1 * 1 + 2 * 3) / 3
    poe = agg.aggregate("poe", mean, var, prior)
    assert poe.var == pytest.approx(1 / 3) and poe.mean == pytest.approx(7 / 3)
    # BCM: precision 3 + (1 - 2) / 4 = 2.75
    bcm = agg.aggregate("bcm", mean, var, prior)
    assert bcm.var == pytest.approx(1 / 2.75) and bcm.mean == pytest.approx(7 / 2.75)
    # entropy weights, eq. (11): beta = 0.5 log(4 / 1) = log 2, 0.5 log(4 / 0.5) = 1.5 log 2
    beta = np.array([np.log(2), 1.5 * np.log(2)])
    np.testing.assert_allclose(agg.entropy_weights(var, prior), beta)
    weights = beta / var
    gpoe = agg.aggregate("gpoe", mean, var, prior)
    assert gpoe.var == pytest.approx(1 / weights.sum())
    assert gpoe.mean == pytest.approx(weights @ mean / weights.sum())
    np.testing.assert_allclose(gpoe.weights, weights)
    rbcm = agg.aggregate("rbcm", mean, var, prior)
    precision = weights.sum() + (1 - beta.sum()) / prior
    assert rbcm.var == pytest.approx(1 / precision) and rbcm.mean == pytest.approx(
        weights @ mean / precision
    )


@pytest.mark.parametrize("method", ["bcm", "rbcm"])
def test_committee_machines_return_to_the_prior_far_from_data(method):
    # far from all data every expert predicts the prior: mean 0, variance sigma_**^2
    result = agg.aggregate(method, np.zeros(6), np.full(6, 2.5), 2.5)
    assert result.mean == pytest.approx(0.0) and result.var == pytest.approx(2.5)
    # nearly so: close to the prior, unlike PoE which is over-confident by 1/M
    near = agg.aggregate(method, np.full(6, 0.01), np.full(6, 2.5 * (1 - 1e-6)), 2.5)
    assert near.var == pytest.approx(2.5, rel=1e-4)
    assert agg.aggregate("poe", np.zeros(6), np.full(6, 2.5), 2.5).var == pytest.approx(2.5 / 6)


@settings(max_examples=50, deadline=None)
@given(
    means=st.lists(st.floats(-100, 100), min_size=1, max_size=8),
    fractions=st.lists(st.floats(1e-6, 1.0), min_size=8, max_size=8),
    method=st.sampled_from(METHODS),
)
def test_aggregate_is_finite_and_positive(means, fractions, method):
    means = np.array(means)
    var = 3.0 * np.array(fractions[: len(means)])
    result = agg.aggregate(method, means, var, 3.0)
    assert np.isfinite(result.mean) and np.isfinite(result.var) and result.var > 0
    if method != "gpoe":  # GPoE's variance 1 / sum(beta_i / sigma_i^2) may exceed the prior
        assert result.var <= 3.0 * (1 + 1e-12)


def test_padding_experts_are_ignored():
    mean, var = np.array([1.0, 3.0, 99.0]), np.array([1.0, 0.5, 0.1])
    valid = np.array([True, True, False])
    for method in METHODS:
        padded = agg.aggregate(method, mean, var, 4.0, valid)
        plain = agg.aggregate(method, mean[:2], var[:2], 4.0)
        assert padded.mean == pytest.approx(plain.mean) and padded.var == pytest.approx(plain.var)


def test_gamma_splits_the_failure_probability():
    gamma = agg.gamma_one_step(4, 0.003)
    assert 4 * np.exp(-gamma / 2) == pytest.approx(0.003)
    steps = np.arange(1, 200_001)
    total = np.sum(3 * np.exp(-agg.gamma_anytime(steps, 3, 0.01) / 2))
    # sum over t of 6 delta / (pi^2 t^2) tends to delta; the tail beyond T is about 6 delta / (pi^2 T)
    assert total == pytest.approx(0.01 * (1 - 6 / (np.pi**2 * 200_000)), rel=1e-6)


def test_ucb_by_hand_and_single_expert_lemma():
    """RBCM with experts of variance 1 and 1/4 under a prior of 4: beta = 1/2 log 4 and
    log 4 sum to 3/2 log 4 > 1, so the prior's coefficient in the mean is negative, the
    failure probability is split over three events, and the bound is
    gamma^(1/2) (|a_1| 1 + |a_2| 1/2 + |a_0| 2). PoE has no prior term (two events)."""
    var, prior, delta = np.array([1.0, 0.25]), 4.0, 0.01
    beta = np.log(4.0) * np.array([0.5, 1.0])
    precision = beta[0] / 1.0 + beta[1] / 0.25 + (1.0 - 1.5 * np.log(4.0)) / 4.0
    a1, a2 = beta[0] / precision, beta[1] / 0.25 / precision
    a0 = (1.0 - 1.5 * np.log(4.0)) / 4.0 / precision
    assert a0 < 0 and a1 + a2 + a0 == pytest.approx(1.0)
    gamma = 2 * np.log(3 / delta)
    expected = np.sqrt(gamma) * (abs(a1) * 1.0 + abs(a2) * 0.5 + abs(a0) * 2.0)
    assert agg.ucb_half_width("rbcm", var, prior, delta) == pytest.approx(expected, rel=1e-12)
    gamma_poe = 2 * np.log(2 / delta)
    expected_poe = np.sqrt(gamma_poe) * (0.2 * 1.0 + 0.8 * 0.5)  # weights 1 and 4 of 5
    assert agg.ucb_half_width("poe", var, prior, delta) == pytest.approx(expected_poe, rel=1e-12)
    # one expert: Lemma 1, gamma^(1/2) sigma with gamma = 2 log(1 / delta)
    assert agg.ucb_half_width("gpoe", np.array([0.5]), prior, delta) == pytest.approx(
        np.sqrt(2 * np.log(1 / delta) * 0.5)
    )
    # a shared extra variance widens every term's standard deviation, not the weights
    widened = agg.ucb_half_width("rbcm", var, prior, delta, extra_var=3.0)
    assert widened == pytest.approx(
        np.sqrt(gamma) * (abs(a1) * 2.0 + abs(a2) * np.sqrt(3.25) + abs(a0) * np.sqrt(7.0)),
        rel=1e-12,
    )


@pytest.mark.parametrize("method", METHODS)
@given(
    means=st.lists(st.floats(-50, 50), min_size=1, max_size=5),
    fractions=st.lists(st.floats(0.01, 1.0), min_size=5, max_size=5),
)
@settings(max_examples=40, deadline=None)
def test_mean_coefficients_reproduce_the_aggregated_mean(method, means, fractions):
    """The coefficients the UCB is built on are those of the aggregate's mean: sum_i a_i mu_i
    (prior mean 0) equals :func:`aggregate`'s mean, and sum a_i + a_0 = 1."""
    mean = np.array(means)
    var = 4.0 * np.array(fractions[: mean.size])
    coefficients, prior_coefficient = agg.mean_coefficients(method, var, 4.0)
    combined = agg.aggregate(method, mean, var, 4.0)
    assert coefficients @ mean == pytest.approx(combined.mean, rel=1e-9, abs=1e-9)
    assert coefficients.sum() + prior_coefficient == pytest.approx(1.0, rel=1e-12)


def test_cumulative_bound_is_the_running_sum():
    np.testing.assert_allclose(agg.cumulative_bound(np.array([1.0, 2.0, 0.5])), [1.0, 3.0, 3.5])


@pytest.mark.parametrize("method", ["gpoe", "rbcm"])
def test_ucb_covers_functions_drawn_from_the_prior(method):
    """Theorems 1-2: on functions drawn from the GP prior with the true hyperparameters,
    |f(x*) - mu| <= UCB with probability at least 1 - delta. 4000 independent draws; the
    coverage must not fall below 1 - delta by more than 3 binomial standard errors."""
    rng = np.random.default_rng(2024)
    delta, draws, experts, points = 0.1, 4000, 3, 4
    log_params = np.log([1.0, 0.5, 0.05])
    X = rng.uniform(0, 3, size=(draws, experts, points, 1))
    x_test = rng.uniform(0, 3, size=(draws, 1, 1, 1))
    everything = np.concatenate([X.reshape(draws, experts * points, 1), x_test[:, 0]], axis=1)
    cov = np.exp(-0.5 * ((everything[:, :, None, 0] - everything[:, None, :, 0]) / 0.5) ** 2)
    f = np.einsum(
        "dab,db->da",
        np.linalg.cholesky(cov + 1e-10 * np.eye(cov.shape[-1])),
        rng.normal(size=everything.shape[:2]),
    )
    z = f[:, :-1].reshape(draws, experts, points) + np.sqrt(0.05) * rng.normal(
        size=(draws, experts, points)
    )
    params = np.broadcast_to(log_params, (draws, 3))
    mean, var = gp.predict(params, X, z, None, np.broadcast_to(x_test, (draws, experts, 1, 1)))
    combined = agg.aggregate(method, mean[..., 0], var[..., 0], np.ones(draws))
    bound = agg.ucb_half_width(method, var[..., 0], np.ones(draws), delta)
    coverage = np.mean(np.abs(f[:, -1] - combined.mean) <= bound)
    assert coverage >= (1 - delta) - 3 * np.sqrt(delta * (1 - delta) / draws)


def test_unknown_method():
    with pytest.raises(ValueError, match="aggregation must be one of"):
        agg.aggregate("moe", np.zeros(2), np.ones(2), 1.0)


def test_anytime_ucb_by_hand():
    """Lemma 2 at step t: gamma = 2 log(pi^2 t^2 M / (6 delta)); one expert of variance 0.5 at
    t = 7 with delta = 0.01 gives sqrt(2 log(49 pi^2 / 0.06) x 0.5), and the bound grows with t
    only through log t."""
    delta, var = 0.01, np.array([0.5])
    for step in (1, 7, 150):
        gamma = 2 * np.log(np.pi**2 * step**2 / (6 * delta))
        assert agg.ucb_half_width("rbcm", var, 4.0, delta, step=step) == pytest.approx(
            np.sqrt(gamma * 0.5), rel=1e-12
        )
    # two experts: delta is split, M = 2 enters the logarithm
    two = agg.ucb_half_width("poe", np.array([1.0, 1.0]), 4.0, delta, step=3)
    assert two == pytest.approx(np.sqrt(2 * np.log(np.pi**2 * 9 * 2 / (6 * delta))), rel=1e-12)


def test_mixture_half_width_by_hand():
    """Component k contributes |offset_k| + (2 log(K w_k / delta))^(1/2) std_k; one
    component of weight 1 is Lemma 1's bound; a component of weight at most delta / K
    contributes nothing (it may fail outright)."""
    delta = 0.01
    assert agg.mixture_half_width([1.0], [[2.0]], [[3.0]], delta) == pytest.approx(
        2.0 + 3.0 * np.sqrt(2 * np.log(1 / delta))
    )
    got = agg.mixture_half_width(
        [0.7, 0.3], np.array([[0.5, -4.0], [-1.0, 6.0]]), np.array([[1.0, 2.0], [8.0, 0.5]]), delta
    )
    first = np.array([0.5, 4.0]) + np.sqrt(2 * np.log(140.0)) * np.array([1.0, 2.0])
    second = np.array([1.0, 6.0]) + np.sqrt(2 * np.log(60.0)) * np.array([8.0, 0.5])
    np.testing.assert_allclose(got, np.maximum(first, second), rtol=1e-12)
    # weight 0.004 <= delta / 2: the wide component is left to its share of delta
    got = agg.mixture_half_width([0.996, 0.004], [[0.0], [50.0]], [[1.0], [100.0]], delta)
    assert got == pytest.approx(np.sqrt(2 * np.log(2 * 0.996 / delta)))


@given(
    weights=st.lists(st.floats(1e-4, 1.0), min_size=1, max_size=4),
    offsets=st.lists(st.floats(-30.0, 30.0), min_size=4, max_size=4),
    stds=st.lists(st.floats(0.05, 40.0), min_size=4, max_size=4),
    delta=st.floats(1e-4, 0.2),
)
@settings(max_examples=60, deadline=None)
def test_mixture_half_width_fails_with_probability_at_most_delta(weights, offsets, stds, delta):
    """The exact probability that a draw from the mixture falls outside +-u (Gaussian tails
    from scipy) is at most delta."""
    from scipy.stats import norm

    weights = np.asarray(weights) / np.sum(weights)
    k = len(weights)
    offsets, stds = np.asarray(offsets[:k]), np.asarray(stds[:k])
    u = agg.mixture_half_width(weights, offsets, stds, delta)
    miss = np.sum(weights * (norm.sf(u, offsets, stds) + norm.cdf(-u, offsets, stds)))
    assert miss <= delta * (1 + 1e-9)
