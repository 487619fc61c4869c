"""The NCV GP in state-space form (agents/state_space.py) against dense references: the
Kalman prediction of the Stone-Soup-checked baselines, the information-form aggregation of
eqs. (8)-(20) computed with explicit inverses and determinants, the dense Gaussian
likelihood, and the dense GP with the integrated Wiener-velocity kernel; then the tracker
built on it (agents/state_space_dgpt.py)."""

import copy
import importlib.util
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from conftest import (
    measurement_obs,
    median_in_band,
    mixture_moments,
    problem_spec,
    sensed_calibration,
    sensed_steps,
)
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import multivariate_normal

import dgpt_gym
from agents import gp
from agents.gating import gate_measurements, target_probabilities
from agents.state_space import (
    MIXTURE_SPREAD_SHARE,
    Manoeuvre,
    PooledSummaries,
    WindowStep,
    aggregate_error_cov,
    aggregate_error_var,
    bcm_window_log_likelihood,
    condition_on_position,
    expert_posteriors,
    filter_steps,
    filter_window,
    fused_update,
    mixture_summaries,
    ncv_predict,
    pool_summaries,
    step_log_likelihood,
)
from agents.state_space_dgpt import (
    LEARNING_GRID,
    LOG_STEP,
    PROCESS_NOISE_BOUNDS,
    TURN_MODES,
    StateSpaceDGPT,
    grid_maximum,
    newton_step,
)
from baselines.kalman import constant_velocity_model, kalman_predict
from dgpt_gym.benchmark.episodes import run_episode

seeds = st.integers(0, 2**32 - 1)


def random_state(rng, batch=()):
    """A random state mean (batch, 2) and positive-definite covariance (batch, 2, 2)."""
    mean = rng.normal(0.0, 10.0, batch + (2,))
    root = rng.normal(0.0, 3.0, batch + (2, 2))
    cov = root @ np.swapaxes(root, -1, -2) + 0.5 * np.eye(2)
    return mean, cov


@given(seeds, st.floats(0.1, 3.0), st.floats(1e-3, 100.0))
@settings(max_examples=30, deadline=None)
def test_prediction_is_the_kalman_prediction_of_the_ncv_model(seed, dt, q):
    mean, cov = random_state(np.random.default_rng(seed))
    transition, noise = constant_velocity_model(dt, q)
    expected_mean, expected_cov = kalman_predict(mean, cov, transition[:2, :2], noise[:2, :2])
    got_mean, got_cov = ncv_predict(mean, cov, dt, q)
    np.testing.assert_allclose(got_mean, expected_mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(got_cov, expected_cov, rtol=1e-12, atol=1e-10)


def dense_aggregate(method, prior_mean, prior_cov, summaries, noise_var):
    """Eqs. (8)-(20) on the state, expert by expert, with explicit inverses and
    determinants: each expert's posterior is the Kalman update of the prior with its
    summary; beta_i = 1/2 log(det P0 / det P_i) (GPoE, RBCM) or 1."""
    h = np.array([1.0, 0.0])
    prior_precision = np.linalg.inv(prior_cov)
    precisions, informations, betas = [], [], []
    for z, r in zip(summaries, noise_var):
        precision = prior_precision + np.outer(h, h) / r
        cov = np.linalg.inv(precision)
        mean = cov @ (prior_precision @ prior_mean + h * z / r)
        beta = 0.5 * np.log(np.linalg.det(prior_cov) / np.linalg.det(cov))
        betas.append(beta if method in ("gpoe", "rbcm") else 1.0)
        precisions.append(precision)
        informations.append(precision @ mean)
    if len(summaries) == 1:
        cov = np.linalg.inv(precisions[0])
        return cov @ informations[0], cov
    precision = sum(b * p for b, p in zip(betas, precisions))
    information = sum(b * i for b, i in zip(betas, informations))
    if method in ("bcm", "rbcm"):
        precision = precision + (1.0 - sum(betas)) * prior_precision
        information = information + (1.0 - sum(betas)) * prior_precision @ prior_mean
    cov = np.linalg.inv(precision)
    return cov @ information, cov


def dense_mixture_posterior(prior_mean, prior_cov, points, weights, noise_var):
    """The moments of the mixture over which of a sensor's ``points`` (k,) on one axis is
    the target's, with probabilities ``weights`` (k,): point j's component is the Kalman
    update of N(``prior_mean``, ``prior_cov``) with z_j of variance ``noise_var``, by
    explicit inverses. Points whose weighted spread about their weighted mean exceeds
    :data:`MIXTURE_SPREAD_SHARE` of the innovation variance are first drawn towards that
    mean until it does not (the cap of :func:`mixture_summaries`)."""
    summary = weights @ points
    spread = weights @ (points - summary) ** 2
    cap = MIXTURE_SPREAD_SHARE * (prior_cov[0, 0] + noise_var)
    if spread > cap:
        points = summary + (points - summary) * np.sqrt(cap / spread)
    h = np.array([1.0, 0.0])
    prior_precision = np.linalg.inv(prior_cov)
    covs = [np.linalg.inv(prior_precision + np.outer(h, h) / noise_var)] * len(points)
    means = [c @ (prior_precision @ prior_mean + h * z / noise_var) for c, z in zip(covs, points)]
    mean = np.sum([w * m for w, m in zip(weights, means)], axis=0)
    cov = sum(w * (c + np.outer(m - mean, m - mean)) for w, m, c in zip(weights, means, covs))
    return mean, cov


def equivalent_measurement(prior_mean, prior_cov, mean, cov):
    """The position measurement z of variance r whose Kalman update of N(``prior_mean``,
    ``prior_cov``) is N(``mean``, ``cov``), from the information form:
    cov^-1 - prior_cov^-1 = e1 e1^T / r and cov^-1 mean - prior_cov^-1 prior_mean = e1 z / r
    (the velocity entries must vanish: a position measurement's gain is rank one)."""
    precision_gain = np.linalg.inv(cov) - np.linalg.inv(prior_cov)
    information_gain = np.linalg.inv(cov) @ mean - np.linalg.inv(prior_cov) @ prior_mean
    scale = abs(precision_gain[0, 0])
    np.testing.assert_allclose(precision_gain[[0, 1, 1], [1, 0, 1]], 0.0, atol=1e-9 * scale)
    np.testing.assert_allclose(information_gain[1], 0.0, atol=1e-9 * np.abs(information_gain[0]))
    return information_gain[0] / precision_gain[0, 0], 1.0 / precision_gain[0, 0]


@given(seed=seeds, n_points=st.integers(1, 5))
@settings(max_examples=50, deadline=None)
def test_mixture_summaries_give_the_moments_of_the_mixture_posterior(seed, n_points):
    """The Kalman update with :func:`mixture_summaries`' pseudo-measurement is, for the
    whole state, the moment-matched mixture over which point is the target's (dense, by
    explicit inverses; weights the points' predictive likelihoods, as eq. (27) makes them;
    the points spread so widely that the cap acts in about a fifth of the examples). One
    point returns it unchanged."""
    rng = np.random.default_rng(seed)
    mean, cov = random_state(rng)
    noise_var = rng.uniform(0.3, 20.0)
    innovation_var = cov[0, 0] + noise_var
    points = mean[0] + rng.normal(0.0, 2.0 * np.sqrt(innovation_var), n_points)
    log_likelihood = -0.5 * (points - mean[0]) ** 2 / innovation_var
    weights = np.exp(log_likelihood - np.logaddexp.reduce(log_likelihood))
    summary = weights @ points
    spread = weights @ (points - summary) ** 2
    pseudo, pseudo_var = mixture_summaries(mean[0], cov[0, 0], summary, noise_var, spread)
    got_mean, got_cov = expert_posteriors(mean, cov, pseudo, pseudo_var)
    want_mean, want_cov = dense_mixture_posterior(mean, cov, points, weights, noise_var)
    np.testing.assert_allclose(got_mean[0], want_mean, rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(got_cov[0], want_cov, rtol=1e-8, atol=1e-8)
    if n_points == 1:
        np.testing.assert_allclose([pseudo[0], pseudo_var[0]], [points[0], noise_var])


def test_mixture_summaries_keep_the_mean_and_stay_within_the_prior_when_the_spread_is_wide():
    """Two points of equal weight at 13 and -7 m from a prediction at 0 of variance 4, noise
    variance 1: summary 3, spread 100. The mixture's variance, (1 - K) p + K^2 S =
    0.8 + 0.64 x 100 = 64.8, is wider than the prior (4), which no measurement gives. The
    spread is capped at 0.99 x a = 4.95: the mean moves by K (zbar - mu) as the mixture's
    does, and the variance is (1 - K) p + K^2 x 4.95 = 3.968, just under the prior's."""
    pseudo, pseudo_var = mixture_summaries(0.0, 4.0, np.array([3.0]), np.array([1.0]), 100.0)
    mean, cov = expert_posteriors(np.zeros(2), np.diag([4.0, 1.0]), pseudo, pseudo_var)
    assert MIXTURE_SPREAD_SHARE == 0.99
    np.testing.assert_allclose(mean[0, 0], 0.8 * 3.0)
    np.testing.assert_allclose(cov[0, 0, 0], 0.2 * 4.0 + 0.64 * 4.95)


@pytest.mark.parametrize("method", ["poe", "gpoe", "bcm", "rbcm"])
@given(seed=seeds, n_experts=st.integers(1, 5))
@settings(max_examples=25, deadline=None)
def test_fused_update_is_the_aggregation_of_the_experts_local_posteriors(method, seed, n_experts):
    rng = np.random.default_rng(seed)
    mean, cov = random_state(rng)
    summaries = mean[0] + rng.normal(0.0, 5.0, n_experts)
    noise_var = rng.uniform(0.5, 20.0, n_experts)
    expected_mean, expected_cov = dense_aggregate(method, mean, cov, summaries, noise_var)
    got_mean, got_cov = fused_update(method, mean, cov, summaries, noise_var)
    np.testing.assert_allclose(got_mean, expected_mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(got_cov, expected_cov, rtol=1e-9, atol=1e-9)
    # the experts' own posteriors, as the dense reference builds them
    means, covs = expert_posteriors(mean, cov, summaries, noise_var)
    for z, r, m, c in zip(summaries, noise_var, means, covs):
        one_mean, one_cov = dense_aggregate(method, mean, cov, [z], [r])
        np.testing.assert_allclose(m, one_mean, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(c, one_cov, rtol=1e-9, atol=1e-9)


def dense_error_var(method, prior_cov, noise_var, error_prior_var=None):
    """The variance of the dense aggregate's position error, from its linear map: the
    aggregated position is c . mu_0 + sum_i c_i z_i (coefficients read off
    :func:`dense_aggregate` with unit inputs), unbiased (c = (1 - sum_i c_i) e1); with
    x ~ N(mu_0, P0) and z_i = x_p + v_i its error is (1 - sum_i c_i) (x_p - mu_0p) -
    sum_i c_i v_i. ``error_prior_var``: the variance of x_p - mu_0p when it is not P0's."""
    n = len(noise_var)

    def position(prior_mean, summaries):
        return dense_aggregate(method, prior_mean, prior_cov, summaries, noise_var)[0][0]

    zero = position(np.zeros(2), np.zeros(n))
    assert abs(zero) < 1e-9  # linear, no offset
    c = np.array([position(np.eye(2)[k], np.zeros(n)) for k in range(2)])
    c_i = np.array([position(np.zeros(2), np.eye(n)[i]) for i in range(n)])
    np.testing.assert_allclose(c, [1.0 - c_i.sum(), 0.0], atol=1e-9)
    if error_prior_var is None:  # the prior mean's position error, by default the prior's
        error_prior_var = prior_cov[0, 0]
    return (1.0 - c_i.sum()) ** 2 * error_prior_var + np.sum(c_i**2 * np.asarray(noise_var))


@pytest.mark.parametrize("method", ["poe", "gpoe", "bcm", "rbcm"])
@given(seed=seeds, n_experts=st.integers(1, 5))
@settings(max_examples=25, deadline=None)
def test_aggregate_error_var_is_the_dense_aggregates_error_variance(method, seed, n_experts):
    rng = np.random.default_rng(seed)
    _, cov = random_state(rng)
    noise_var = rng.uniform(0.5, 20.0, n_experts)
    got = aggregate_error_var(method, cov[0, 0], noise_var)
    np.testing.assert_allclose(got, dense_error_var(method, cov, noise_var), rtol=1e-9)
    # BCM is the exact posterior: its error variance is the variance it reports, and no
    # other aggregation's mean has a smaller one
    exact_var = fused_update("bcm", np.zeros(2), cov, np.zeros(n_experts), noise_var)[1][0, 0]
    if method == "bcm" or n_experts == 1:
        np.testing.assert_allclose(got, exact_var, rtol=1e-9)
    assert got >= exact_var * (1 - 1e-9)


@pytest.mark.parametrize("method", ["poe", "gpoe", "bcm", "rbcm"])
@given(seed=seeds, n_experts=st.integers(1, 5))
@settings(max_examples=25, deadline=None)
def test_aggregate_error_cov_is_the_dense_aggregates_error_covariance(method, seed, n_experts):
    """The dense aggregate's state is C mu_0 + sum_i c_i z_i (C (2, 2), c_i (2,) read off
    :func:`dense_aggregate` with unit inputs); with the prior mean's error of covariance E
    (random, not the prior covariance P0 the aggregation uses) and z_i = x_p + v_i, its
    error covariance is C E C^T + sum_i c_i c_i^T s_i. With E = P0 the position entry is
    :func:`aggregate_error_var`, and for BCM the whole matrix is its posterior covariance."""
    rng = np.random.default_rng(seed)
    _, prior_cov = random_state(rng)
    _, error_cov = random_state(rng)
    noise_var = rng.uniform(0.5, 20.0, n_experts)

    def state(prior_mean, summaries):
        return dense_aggregate(method, prior_mean, prior_cov, summaries, noise_var)[0]

    columns = np.column_stack([state(np.eye(2)[k], np.zeros(n_experts)) for k in range(2)])
    c_i = [state(np.zeros(2), np.eye(n_experts)[i]) for i in range(n_experts)]
    expected = columns @ error_cov @ columns.T + sum(
        np.outer(c, c) * r for c, r in zip(c_i, noise_var)
    )
    got = aggregate_error_cov(method, prior_cov, error_cov, noise_var)
    np.testing.assert_allclose(got, expected, rtol=1e-8, atol=1e-9)
    own = aggregate_error_cov(method, prior_cov, prior_cov, noise_var)
    np.testing.assert_allclose(own[0, 0], aggregate_error_var(method, prior_cov[0, 0], noise_var))
    if method == "bcm":
        posterior_cov = fused_update("bcm", np.zeros(2), prior_cov, np.zeros(n_experts), noise_var)[
            1
        ]
        np.testing.assert_allclose(own, posterior_cov, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("aggregation", ["rbcm", "gpoe"])
def test_the_error_excess_is_carried_only_without_turn_modes(aggregation):
    """Without turn modes RBCM and GPoE carry their error's excess over the broadcast
    posterior (the test below shows its effect); with turn modes (the registered trackers)
    they do not: one pooled excess over-widens GPoE and PoE there
    (``StateSpaceDGPT._carries_error_excess``)."""
    spec = problem_spec(sensor_positions=((0.0, 0.0), (20.0, 0.0), (0.0, 20.0)))
    rng = np.random.default_rng(5)
    for turn_rates, carried in [((), True), ((0.35, -0.35), False)]:
        tracker = StateSpaceDGPT(aggregation=aggregation, turn_rates=turn_rates)
        tracker.reset(spec)
        for t in range(5):
            truth = np.array([5.0 + 2.0 * t, 3.0 - t])
            tracker.update(measurement_obs(t, truth + rng.normal(0.0, 1.0, (3, 2)), [0, 1, 2]))
        assert (tracker.error_excess_ is not None) == carried


def test_rbcm_error_variance_is_what_states_drawn_from_the_model_give():
    """Monte Carlo under the model (state from the prior, summaries = position + noise): the
    sample variance of RBCM's position error matches :func:`aggregate_error_var` within
    4 standard errors of a variance from n = 40000 Gaussian draws (sqrt(2 / n) = 0.7 %),
    and is visibly larger than the variance RBCM reports."""
    rng = np.random.default_rng(11)
    mean, cov = np.array([3.0, -1.0]), np.array([[40.0, 6.0], [6.0, 4.0]])
    noise_var = np.array([2.0, 5.0, 1.0, 30.0])
    n = 40000
    states = rng.multivariate_normal(mean, cov, n)
    summaries = states[:, :1] + rng.normal(0.0, np.sqrt(noise_var), (n, 4))
    aggregate, reported = fused_update(
        "rbcm",
        np.broadcast_to(mean, (n, 2)),
        np.broadcast_to(cov, (n, 2, 2)),
        summaries,
        np.broadcast_to(noise_var, (n, 4)),
    )
    errors = states[:, 0] - aggregate[:, 0]
    expected = aggregate_error_var("rbcm", cov[0, 0], noise_var)
    assert abs(errors.var() / expected - 1) < 4 * np.sqrt(2 / n)
    assert expected > 1.1 * reported[0, 0, 0]


@given(seed=seeds, noise_var=st.floats(0.01, 100.0))
@settings(max_examples=30, deadline=None)
def test_conditioning_on_a_kalman_updates_position_gives_back_the_kalman_update(seed, noise_var):
    """A position posterior from a Gaussian measurement, put in place of the prior's position
    marginal, gives the whole Kalman posterior: the velocity follows through the prior's
    correlation, as it does in the Kalman gain (three states at once, both orders of size)."""
    rng = np.random.default_rng(seed)
    mean, cov = random_state(rng, (3,))
    summary = mean[:, 0] + rng.normal(0.0, 5.0, 3)
    expected_mean, expected_cov = expert_posteriors(mean, cov, summary[:, None], noise_var)
    got_mean, got_cov = condition_on_position(
        mean, cov, expected_mean[:, 0, 0], expected_cov[:, 0, 0, 0]
    )
    np.testing.assert_allclose(got_mean, expected_mean[:, 0], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(got_cov, expected_cov[:, 0], rtol=1e-9, atol=1e-9)


@given(seed=seeds, n_experts=st.integers(1, 6))
@settings(max_examples=30, deadline=None)
def test_step_likelihood_is_the_dense_gaussian(seed, n_experts):
    rng = np.random.default_rng(seed)
    prior_mean, prior_var = rng.normal(0.0, 10.0), rng.uniform(0.1, 50.0)
    noise_var = rng.uniform(0.2, 30.0, n_experts)
    summaries = prior_mean + rng.normal(0.0, 6.0, n_experts)
    cov = prior_var * np.ones((n_experts, n_experts)) + np.diag(noise_var)
    expected = multivariate_normal(np.full(n_experts, prior_mean), cov).logpdf(summaries)
    got = step_log_likelihood(np.array(prior_mean), np.array(prior_var), summaries, noise_var)
    np.testing.assert_allclose(got, expected, rtol=1e-10)


@given(seed=seeds, q=st.floats(0.01, 50.0))
@settings(max_examples=20, deadline=None)
def test_bcm_window_likelihood_and_posterior_are_the_dense_ncv_gp(seed, q):
    """With BCM the filtered window is exact GP regression with the integrated Wiener-velocity
    kernel: the summed step likelihoods equal the dense marginal likelihood of every summary
    (prior state at the window start, kernel from agents.gp.NCVPrior, noise per summary), and
    the final posterior mean is the GP's predictive mean at the last time."""
    rng = np.random.default_rng(seed)
    start_mean, start_cov = random_state(rng)
    steps, times, values, noise = [], [], [], []
    time = 0.0
    for _ in range(int(rng.integers(1, 6))):
        dt = float(rng.integers(1, 3))
        time += dt
        m = int(rng.integers(1, 4))
        summary = start_mean[0] + start_mean[1] * time + rng.normal(0.0, 4.0, m)
        spread = rng.uniform(0.0, 3.0, m)
        steps.append(WindowStep(dt, summary[None], spread[None], start_mean[None], start_cov[None]))
        times += [time] * m
        values += list(summary)
        noise += list(1.0 + spread)
    times, values = np.array(times), np.array(values)
    basis = np.column_stack([np.ones_like(times), times])
    kernel = basis @ start_cov @ basis.T + q * gp.NCVPrior(0.0, 0.0).unit_kernel(times, times)
    expected = multivariate_normal(basis @ start_mean, kernel + np.diag(noise)).logpdf(values)
    log_likelihood, mean, cov = filter_window("bcm", steps, np.array([q]), np.array([1.0]))
    np.testing.assert_allclose(log_likelihood[0], expected, rtol=1e-9)
    last = (
        np.array([1.0, time]) @ start_cov @ basis.T
        + q * gp.NCVPrior(0.0, 0.0).unit_kernel(np.array([time]), times)[0]
    )
    gp_mean = (
        start_mean[0]
        + start_mean[1] * time
        + last @ np.linalg.solve(kernel + np.diag(noise), values - basis @ start_mean)
    )
    np.testing.assert_allclose(mean[0, 0], gp_mean, rtol=1e-9, atol=1e-9)


@given(seed=seeds, probability=st.floats(0.01, 0.99), intensity=st.floats(1.0, 1000.0))
@settings(max_examples=25, deadline=None)
def test_two_component_step_is_the_dense_mixture(seed, probability, intensity):
    """One step with a manoeuvre component: the log likelihood is that of the two-Gaussian
    mixture of the summaries (scipy, dense), and the posterior mean is the mixture of the two
    components' exact posterior means weighted by p_k N_k(z)."""
    rng = np.random.default_rng(seed)
    start_mean, start_cov = random_state(rng)
    m, q = int(rng.integers(1, 4)), rng.uniform(0.01, 10.0)
    summaries = start_mean[0] + start_mean[1] + rng.normal(0.0, 15.0, m)
    spread = rng.uniform(0.0, 2.0, m)
    step = WindowStep(1.0, summaries[None], spread[None], start_mean[None], start_cov[None])
    manoeuvre = Manoeuvre(intensity, probability)
    log_likelihood, mean, _ = filter_window(
        "bcm", [step], np.array([q]), np.array([1.0]), manoeuvre
    )
    log_densities, posterior_means = [], []  # logs: a far summary underflows the density
    for weight, intensity_k in ((1 - probability, q), (probability, q + intensity)):
        transition, noise = constant_velocity_model(1.0, intensity_k)
        prior_mean, prior_cov = kalman_predict(
            start_mean, start_cov, transition[:2, :2], noise[:2, :2]
        )
        cov = prior_cov[0, 0] * np.ones((m, m)) + np.diag(1.0 + spread)
        log_densities.append(
            np.log(weight) + multivariate_normal(np.full(m, prior_mean[0]), cov).logpdf(summaries)
        )
        gain = prior_cov[0, 0] * np.linalg.solve(cov, summaries - prior_mean[0]).sum()
        posterior_means.append(prior_mean[0] + gain)
    total = np.logaddexp(*log_densities)
    np.testing.assert_allclose(log_likelihood[0], total, rtol=1e-9)
    expected = np.dot(np.exp(np.array(log_densities) - total), posterior_means)
    np.testing.assert_allclose(mean[0, 0], expected, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("method", ["poe", "bcm"])
def test_windows_filtered_together_padded_at_the_front_equal_each_alone(method):
    """Two windows of 5 and 2 steps filtered in one batch (the short one padded with two
    invalid steps in front, whose data are NaN so that any use of them shows) give, bit for
    bit, what each gives alone: the padding neither moves the state nor adds likelihood."""
    rng = np.random.default_rng(7)
    manoeuvre = Manoeuvre(400.0, 0.5)
    windows = []
    for length in (5, 2):
        mean, cov = random_state(rng, (2,))
        steps = []
        for _ in range(length):
            m = int(rng.integers(1, 4))
            summaries = mean[:, :1] + rng.normal(0.0, 5.0, (2, m))
            steps.append((1.0, True, pool_summaries(summaries, rng.uniform(0.5, 3.0, (2, m)))))
        windows.append((steps, mean, cov))
    q = np.array([[0.5, 2.0], [3.0, 0.1]])  # (episode, axis)
    alone = [
        filter_steps(method, steps, mean, cov, q[i], manoeuvre)
        for i, (steps, mean, cov) in enumerate(windows)
    ]
    nan_step = (np.nan, False, PooledSummaries(*np.full((5, 2), np.nan)))
    long_steps, short_steps = windows[0][0], [nan_step] * 3 + windows[1][0]
    together_steps = [
        (
            np.array([a[0], b[0]])[:, None],
            np.array([a[1], b[1]])[:, None],
            PooledSummaries(*(np.stack(pair) for pair in zip(a[2], b[2]))),
        )
        for a, b in zip(long_steps, short_steps)
    ]
    together = filter_steps(
        method,
        together_steps,
        np.stack([windows[0][1], windows[1][1]]),
        np.stack([windows[0][2], windows[1][2]]),
        q,
        manoeuvre,
    )
    for i, single in enumerate(alone):
        for got, expected in zip(together, single):
            np.testing.assert_array_equal(got[i], expected)


@given(
    seeds,
    st.integers(1, 6),
    st.integers(1, 3),
    st.integers(1, 3),
    st.sampled_from([None, Manoeuvre(400.0, 0.5), Manoeuvre(20.0, 0.05)]),
)
@settings(max_examples=60, deadline=None)
def test_the_fast_window_likelihood_is_the_bcm_filters_bit_for_bit(
    seed, length, episodes, trials, manoeuvre
):
    """:func:`bcm_window_log_likelihood`, which the learning of q calls every step, gives
    :func:`filter_steps`'s BCM log likelihood to the last bit (it computes every entry by
    the same operations in the same order): windows of several episodes (up to 6 steps,
    each episode's window starting at a random step, the steps before it invalid and NaN
    so that any use of them shows), several trial points of q, steps of 0, 1 and several
    seconds, 1-3 summaries a step, with and without the manoeuvre component."""
    rng = np.random.default_rng(seed)
    starts = rng.integers(0, length, episodes)
    starts[0] = 0  # the longest window fills the batch
    dt = rng.choice([0.0, 1.0, 1.0, 3.0], (length, episodes, 1, 1))
    valid = np.arange(length)[:, None, None, None] >= starts[None, :, None, None]
    sums = np.full((length, episodes, 5, 2), np.nan)
    mean, cov = random_state(rng, (episodes, 1, 2))
    for step in range(length):
        for episode in np.flatnonzero(valid[step, :, 0, 0]):
            m = int(rng.integers(1, 4))
            summaries = mean[episode, 0, :, :1] + rng.normal(0.0, 20.0, (2, m))
            sums[step, episode] = pool_summaries(summaries, rng.uniform(0.5, 30.0, (2, m)))
    pooled = PooledSummaries(*np.moveaxis(sums, 2, 0)[:, :, :, None])
    q = np.exp(rng.uniform(np.log(1e-4), np.log(300.0), (episodes, trials, 2)))
    steps = [(dt[i], valid[i], PooledSummaries(*(f[i] for f in pooled))) for i in range(length)]
    expected, _, _ = filter_steps("bcm", steps, mean, cov, q, manoeuvre)
    got = bcm_window_log_likelihood(dt, valid, pooled, mean, cov, q, manoeuvre)
    assert got.shape == q.shape
    assert np.isfinite(got).all()
    np.testing.assert_array_equal(got, expected)


def test_the_fast_window_likelihood_broadcasts_as_the_filter_does():
    """Inputs with fewer axes than q, as :func:`filter_steps` takes them: one prior for
    every episode and trial point, a scalar dt and validity per step, sums per axis only;
    one step invalid; and the empty window (zeros). Arrays that would extend q's shape are
    refused with the shape in the message."""
    rng = np.random.default_rng(3)
    length, manoeuvre = 4, Manoeuvre(400.0, 0.5)
    mean, cov = random_state(rng, (2,))
    sums = np.stack(
        [
            pool_summaries(rng.normal(0.0, 20.0, (2, 3)), rng.uniform(0.5, 30.0, (2, 3)))
            for _ in range(length)
        ]
    )  # (L, field, axis)
    pooled = PooledSummaries(*np.moveaxis(sums, 1, 0))  # fields (L, 2)
    dt, valid = np.array([0.0, 1.0, 3.0, 1.0]), np.array([True, False, True, True])
    q = np.exp(rng.uniform(np.log(1e-4), np.log(300.0), (5, 3, 2)))
    steps = [(dt[i], valid[i], PooledSummaries(*(f[i] for f in pooled))) for i in range(length)]
    expected, _, _ = filter_steps("bcm", steps, mean, cov, q, manoeuvre)
    got = bcm_window_log_likelihood(dt, valid, pooled, mean, cov, q, manoeuvre)
    assert got.shape == (5, 3, 2)
    np.testing.assert_array_equal(got, expected)
    empty = PooledSummaries(*np.zeros((5, 0, 2)))
    np.testing.assert_array_equal(
        bcm_window_log_likelihood(dt[:0], valid[:0], empty, mean, cov, q), np.zeros(q.shape)
    )
    wider = PooledSummaries(*(np.repeat(field[:, None], 3, axis=1) for field in pooled))
    with pytest.raises(ValueError, match=r"q's shape \(2,\)"):
        bcm_window_log_likelihood(dt, valid, wider, mean, cov, q[0, 0], manoeuvre)


def test_newton_step_solves_a_quadratic_and_respects_its_limits():
    h = 0.05
    x = np.array([0.0, 0.0, 0.0])
    optimum = np.array([0.3, -0.7, 4.0])  # the last lies beyond the largest step

    def f(x):
        return -((x - optimum) ** 2)

    step = newton_step(np.stack([f(x), f(x + h), f(x - h)]), h, max_step=1.0)
    np.testing.assert_allclose(step, [0.3, -0.7, 1.0], rtol=1e-9)
    # convex (no maximum nearby): the largest step uphill; non-finite centre: no step
    convex = np.array([[0.0], [1.0], [0.5]])
    np.testing.assert_allclose(newton_step(convex, h, 1.0), [1.0])
    broken = np.array([[np.nan], [1.0], [0.5]])
    np.testing.assert_allclose(newton_step(broken, h, 1.0), [0.0])
    infinite_below = np.array([[0.0], [-1.0], [-np.inf]])
    np.testing.assert_allclose(newton_step(infinite_below, h, 1.0), [1.0])


@pytest.mark.parametrize("prior, shift", [("none", 0.0), ("boundary-avoiding", 0.25)])
def test_the_climb_lands_on_the_penalised_maximum(prior, shift):
    """A window likelihood -a (log q - u0)^2 per axis: without a prior the climb lands on
    u0; the boundary-avoiding prior adds (1/2) log q, whose maximum is u0 + 1 / (4 a) (by
    hand: -2 a (u - u0) + 1/2 = 0). One Newton step from anywhere within reach is exact for
    a quadratic. A flat likelihood moves q up by the largest step with the prior and not at
    all without."""
    a, u0 = np.array([1.0, 0.5]), np.array([-2.0, 1.0])
    tracker = StateSpaceDGPT(process_noise_prior=prior)
    tracker.reset(problem_spec())
    tracker.log_q_ = np.array([-1.5, 0.8])
    u = tracker.log_q_[None, :] + np.array([0.0, LOG_STEP, -LOG_STEP])[:, None]
    tracker._climb(-a * (u - u0) ** 2)
    np.testing.assert_allclose(tracker.log_q_, u0 + shift / a, rtol=1e-9)
    tracker.log_q_ = np.zeros(2)
    tracker._climb(np.zeros((3, 2)))
    np.testing.assert_allclose(tracker.log_q_, np.full(2, 1.0 if shift else 0.0))


@pytest.mark.parametrize("association", ["joint", "local"])
def test_a_step_is_the_likelihood_weighted_mixture_of_the_two_components(association):
    """One tracker step with data, then one without, recomputed densely: per component, the
    NCV prediction (the Stone-Soup-checked Kalman prediction), the gated summaries, their
    joint Gaussian likelihood (scipy) and the dense aggregate; the estimate is the mixture
    weighted by prior probability times likelihood (moments component by component), the UCB
    is the larger over the components of Lemma 1 on the component's error (its share of delta
    scaled by its weight; the prior's error has the prediction's covariance plus the excess
    the tracker carried, the transition times it times the transition's transpose) plus its
    distance to the estimate, and the next-step
    prediction carries q + p q_m with the q just learnt. Without data the components keep
    their prior weights. The summaries' weights are eq. (27)'s or, with the joint
    association, the target probabilities at the component's prediction."""
    spec = problem_spec(sensor_positions=((0.0, 0.0), (20.0, 0.0), (0.0, 20.0)))
    rng = np.random.default_rng(8)
    # probability 0.2: unequal prior weights, so that the test sees them
    tracker = StateSpaceDGPT(
        aggregation="rbcm",
        delta=0.01,
        manoeuvre_probability=0.2,
        association=association,
        turn_rates=(),
    )
    tracker.reset(spec)
    for t in range(8):
        truth = np.array([5.0 + 2.0 * t, 3.0 - t])
        tracker.update(measurement_obs(t, truth + rng.normal(0.0, 1.0, (3, 2)), [0, 1, 2]))
    before = (tracker.mean_.copy(), tracker.cov_.copy(), np.exp(tracker.log_q_))
    excess = tracker.error_excess_.copy()  # RBCM's error covariance minus its posterior's
    # a manoeuvre (the target is 4 m off the constant-velocity path) and a clutter point
    points = np.vstack([[25.0, -9.0] + rng.normal(0.0, 1.0, (3, 2)), [[18.0, -2.0]]])
    estimate = tracker.update(measurement_obs(8, points, [0, 1, 2, 1]))
    mean0, cov0, q = before
    manoeuvre = tracker.manoeuvre
    # learning: one Newton step on the window's likelihood under the two-component model
    trial = np.log(q) + np.array([0.0, LOG_STEP, -LOG_STEP])[:, None]
    window_likelihood, _, _ = filter_window(
        "rbcm", list(tracker.steps_), np.exp(trial), np.ones(2), manoeuvre
    )
    np.testing.assert_allclose(
        tracker.log_q_,
        np.clip(np.log(q) + newton_step(window_likelihood, LOG_STEP, 1.0), *np.log([1e-4, 1e6])),
        rtol=1e-12,
    )
    components = [
        (q, 1.0 - manoeuvre.probability),
        (q + manoeuvre.intensity, manoeuvre.probability),
    ]
    log_weights, means, covs, bounds = [], [], [], []
    for intensity, probability in components:
        prediction = []
        for axis in range(2):
            transition, noise = constant_velocity_model(1.0, intensity[axis])
            prediction.append(
                kalman_predict(mean0[axis], cov0[axis], transition[:2, :2], noise[:2, :2])
            )
        predicted_position = np.array([prediction[a][0][0] for a in range(2)])
        predicted_var = np.array([prediction[a][1][0, 0] for a in range(2)])
        log_target = None
        if association == "joint":
            log_target = np.log(
                target_probabilities(
                    points,
                    predicted_position,
                    predicted_var,
                    1.0,
                    spec.detection_rate,
                    spec.clutter_rate / spec.sensing_area,
                )
            )
        gated = gate_measurements(
            points,
            np.array([0, 1, 2, 1]),
            np.broadcast_to(predicted_position, points.shape),
            np.broadcast_to(predicted_var + 1.0, points.shape),
            log_target,
        )
        log_weight, axis_means, axis_covs, axis_bounds = np.log(probability), [], [], []
        # a summary's variance: sigma_n^2 = 1 times the sum of its squared weights (the
        # variance of a weighted mean of target points) plus the weighted spread
        order = np.argsort([0, 1, 2, 1], kind="stable")  # the order of gated.weights
        sorted_sensors, sorted_points = np.array([0, 1, 2, 1])[order], points[order]
        squares = np.array(
            [np.sum(gated.weights[sorted_sensors == sensor] ** 2) for sensor in gated.sensors]
        )
        for axis in range(2):
            z, r = gated.summaries[:, axis], squares + gated.spread[:, axis]
            p = predicted_var[axis]
            log_weight += multivariate_normal(
                np.full(z.size, predicted_position[axis]),
                p * np.ones((z.size, z.size)) + np.diag(r),
            ).logpdf(z)
            # each expert's posterior: the mixture over which of its sensor's points is the
            # target's, each of the summary's noise variance; aggregated as the measurement
            # that gives it
            experts = [
                equivalent_measurement(
                    *prediction[axis],
                    *dense_mixture_posterior(
                        *prediction[axis],
                        sorted_points[sorted_sensors == sensor, axis],
                        gated.weights[sorted_sensors == sensor],
                        square,
                    ),
                )
                for sensor, square in zip(gated.sensors, squares)
            ]
            pseudo, pseudo_var = np.array(experts).T
            m, c = dense_aggregate("rbcm", *prediction[axis], pseudo, pseudo_var)
            axis_means.append(m)
            axis_covs.append(c)
            # the prior's error: the prediction's covariance plus the excess carried by F
            carried = (transition[:2, :2] @ excess[axis] @ transition[:2, :2].T)[0, 0]
            axis_bounds.append(
                np.sqrt(dense_error_var("rbcm", prediction[axis][1], pseudo_var, p + carried))
            )
        log_weights.append(log_weight)
        means.append(axis_means)
        covs.append(axis_covs)
        bounds.append(axis_bounds)
    means, covs = np.array(means), np.array(covs)  # (component, axis, 2[, 2])
    for axis in range(2):
        mean, cov = mixture_moments(log_weights, means[:, axis], covs[:, axis])
        np.testing.assert_allclose(tracker.mean_[axis], mean, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(tracker.cov_[axis], cov, rtol=1e-9, atol=1e-9)
        # Lemma 1 on each component's error std, its share of delta scaled by its weight
        weights = np.exp(np.array(log_weights) - np.logaddexp(*log_weights))
        expected_ucb = max(
            abs(means[k, axis, 0] - mean[0])
            + np.sqrt(2 * np.log(2 * weights[k] / 0.01)) * bounds[k][axis]
            for k in range(2)
        )
        np.testing.assert_allclose(estimate.ucb[axis], expected_ucb, rtol=1e-9)
        # with the q learnt at this step, which the next step predicts with
        learnt = np.exp(tracker.log_q_[axis])
        transition, noise = constant_velocity_model(
            1.0, learnt + manoeuvre.probability * manoeuvre.intensity
        )
        next_mean, next_cov = kalman_predict(mean, cov, transition[:2, :2], noise[:2, :2])
        np.testing.assert_allclose(estimate.prior_next[0][axis], next_mean[0], rtol=1e-9)
        np.testing.assert_allclose(estimate.prior_next[1][axis], next_cov[0, 0], rtol=1e-9)
    manoeuvre_weight = np.exp(log_weights[1] - np.logaddexp(*log_weights))
    assert 0.05 < manoeuvre_weight < 0.95, manoeuvre_weight  # both components matter
    # a step without data: the prediction's mixture under the prior weights
    mean1, cov1, q1 = tracker.mean_.copy(), tracker.cov_.copy(), np.exp(tracker.log_q_)
    excess1 = tracker.error_excess_.copy()
    estimate = tracker.update(measurement_obs(9, np.empty((0, 2)), []))
    for axis in range(2):
        predictions = []
        for intensity in (q1[axis], q1[axis] + manoeuvre.intensity):
            transition, noise = constant_velocity_model(1.0, intensity)
            predictions.append(
                kalman_predict(mean1[axis], cov1[axis], transition[:2, :2], noise[:2, :2])
            )
        log_prior = np.log([1.0 - manoeuvre.probability, manoeuvre.probability])
        mean, cov = mixture_moments(
            log_prior, [m for m, _ in predictions], [c for _, c in predictions]
        )
        np.testing.assert_allclose(tracker.cov_[axis], cov, rtol=1e-9)
        np.testing.assert_allclose(estimate.mean[axis], mean[0], rtol=1e-12)
        # prior weights 0.8 and 0.2, equal means: the larger of the components' bounds, on
        # the prediction's variance plus the carried excess of RBCM's error
        carried = (transition[:2, :2] @ excess1[axis] @ transition[:2, :2].T)[0, 0]
        expected_ucb = max(
            np.sqrt(2 * np.log(2 * w / 0.01) * (c[0, 0] + carried))
            for w, (_, c) in zip((0.8, 0.2), predictions)
        )
        np.testing.assert_allclose(estimate.ucb[axis], expected_ucb, rtol=1e-12)
        np.testing.assert_allclose(estimate.var[axis], cov[0, 0] + carried, rtol=1e-12)


def test_without_gating_each_expert_updates_with_its_unweighted_mean_and_spread():
    """gating=False: a sensor's summary is the unweighted mean of its points, of variance
    sigma_n^2 / k plus their spread about it (the mean squared deviation), and its expert is
    the Kalman update of the broadcast prediction with that summary (dense_aggregate with one
    expert), not the mixture over its points, whose mean would move by the gain
    p / (p + r) instead of p / (p + r + spread); the estimate is RBCM over the experts. The mixture update needs the
    association's weights and is refused without them."""
    spec = problem_spec(sensor_positions=((0.0, 0.0), (20.0, 0.0)))
    tracker = StateSpaceDGPT(
        aggregation="rbcm",
        gating=False,
        manoeuvre_intensity=0.0,
        turn_rates=(),
        learn_process_noise=False,
    )
    assert tracker.expert_update == "summary"
    tracker.reset(spec)
    for t in range(3):
        tracker.update(measurement_obs(t, np.array([[2.0 * t, t], [2.0 * t + 1.0, t]]), [0, 1]))
    # sensor 0 reports two points 6 m apart on x, sensor 1 one point
    points = np.array([[3.0, 5.0], [9.0, 1.0], [7.0, 2.5]])
    tracker.update(measurement_obs(3, points, [0, 0, 1]))
    _, prior_means, prior_covs, _ = tracker.step_predictions_
    summaries = np.array([[6.0, 3.0], [7.0, 2.5]])  # (sensor, axis)
    spreads = np.array([[9.0, 4.0], [0.0, 0.0]])
    noise_var = np.array([[0.5], [1.0]])  # sigma_n^2 = 1 over k points
    for axis in range(2):
        prior_mean, prior_cov = prior_means[0, axis], prior_covs[0, axis]
        variances = noise_var[:, 0] + spreads[:, axis]
        for expert in range(2):
            mean, cov = dense_aggregate(
                "rbcm",
                prior_mean,
                prior_cov,
                summaries[expert, axis : axis + 1],
                variances[expert : expert + 1],
            )
            np.testing.assert_allclose(tracker.expert_means_[axis, expert], mean, rtol=1e-10)
            np.testing.assert_allclose(tracker.expert_covs_[axis, expert], cov, rtol=1e-10)
        mean, cov = dense_aggregate("rbcm", prior_mean, prior_cov, summaries[:, axis], variances)
        np.testing.assert_allclose(tracker.mean_[axis], mean, rtol=1e-10)
        np.testing.assert_allclose(tracker.cov_[axis], cov, rtol=1e-10)
    with pytest.raises(ValueError, match="expert_update='mixture' needs .*gating=True"):
        StateSpaceDGPT(gating=False, expert_update="mixture")


def test_an_experts_local_posterior_uses_only_its_own_data_and_the_broadcast_prior():
    spec = problem_spec(sensor_positions=((0.0, 0.0), (20.0, 0.0), (0.0, 20.0)))
    rng = np.random.default_rng(3)
    tracker = StateSpaceDGPT(aggregation="rbcm", manoeuvre_intensity=0.0)
    tracker.reset(spec)
    for t in range(6):
        truth = np.array([5.0 + 2.0 * t, 3.0 + t])
        points = truth + rng.normal(0.0, 1.0, (3, 2))
        tracker.update(measurement_obs(t, points, [0, 1, 2]))
    points = np.array([16.5, 9.2]) + rng.normal(0.0, 1.0, (3, 2))
    changed = points.copy()
    changed[1] += [7.0, -4.0]  # sensor 1 alone reports something else
    one, other = copy.deepcopy(tracker), copy.deepcopy(tracker)
    one.update(measurement_obs(6, points, [0, 1, 2]))
    other.update(measurement_obs(6, changed, [0, 1, 2]))
    np.testing.assert_array_equal(one.expert_sensors_, [0, 1, 2])
    for index in (0, 2):  # the other experts' local posteriors do not move
        np.testing.assert_array_equal(one.expert_means_[:, index], other.expert_means_[:, index])
    assert np.all(np.abs(one.expert_means_[:, 1, 0] - other.expert_means_[:, 1, 0]) > 1.0)
    assert np.all(one.mean_[:, 0] != other.mean_[:, 0])  # the aggregate does


LEARNERS = {
    "window": {"window": 160},
    # a memory far beyond the episode: every step's evidence counts fully
    "recursive": {"learning": "recursive", "learning_memory": 1e9},
}


@pytest.mark.parametrize("learning", sorted(LEARNERS))
@pytest.mark.parametrize("true_q", [(0.0, 0.0), (25.0, 25.0), (0.0, 25.0)])
def test_learns_q_on_the_nearly_constant_velocity_path_it_models(true_q, learning):
    """Three summaries per step of a target that moves by the NCV model itself (q per
    axis), 160 steps in the window (or, recursively, the whole track): q = 0 (constant
    velocity) drives q to its floor; q = 25 m^2/s^3 is recovered with |log(q_hat / q)| < 0.4,
    about 3.5 standard errors of the maximum-likelihood log q from 160 steps
    (sqrt(2 / 160) = 0.11; seeds 11-13 gave 0.01-0.12 with the window; seed 11 gives 0.13
    and 0.26 recursively, whose estimate uses each step once). A learning step counts as on a bound
    when either axis's q is: nearly all steps with q = 0 on an axis, nearly none
    otherwise."""
    spec = problem_spec(sensor_positions=((0.0, 0.0), (30.0, 0.0), (0.0, 30.0)), n_steps=160)
    rng = np.random.default_rng(11)
    tracker = StateSpaceDGPT(aggregation="bcm", manoeuvre_intensity=0.0, **LEARNERS[learning])
    tracker.reset(spec)
    state = np.array([[0.0, 3.0], [0.0, -2.0]])
    noises = [constant_velocity_model(1.0, q)[1][:2, :2] + 1e-12 * np.eye(2) for q in true_q]
    transition = constant_velocity_model(1.0, 0.0)[0][:2, :2]
    for t in range(160):
        if t:
            state = state @ transition.T + [rng.multivariate_normal(np.zeros(2), n) for n in noises]
        points = state[:, 0] + rng.normal(0.0, 1.0, (3, 2))
        tracker.update(measurement_obs(t, points, [0, 1, 2]))
    learnt = np.exp(tracker.log_q_)
    share = tracker.diagnostics()["share_at_bound"]
    for axis, q in enumerate(true_q):
        if q == 0.0:
            assert learnt[axis] < 1e-3, learnt
        else:
            assert abs(np.log(learnt[axis] / q)) < 0.4, learnt
    if 0.0 in true_q:
        assert share > 0.9, share  # measured 0.91-0.99
    else:
        assert share < 0.05, share  # measured 0 (window) and 0.038 (recursive: early steps)


def test_episode_is_finite_and_reports_its_fits():
    env = gym.make("DGPTrack-v0", scenario="S3", clutter_rate=5.0)
    obs, info = env.reset(seed=1000)
    tracker = StateSpaceDGPT()
    tracker.reset(info["problem_spec"])
    done = False
    while not done:
        estimate = tracker.update(obs)
        assert np.all(np.isfinite(estimate.mean)) and np.all(estimate.var > 0)
        assert np.all(np.isfinite(estimate.ucb)) and np.all(estimate.ucb > 0)
        obs, _, terminated, truncated, _ = env.step(estimate.mean)
        done = terminated or truncated
    diagnostics = tracker.diagnostics()
    assert 0.0 <= diagnostics["share_at_bound"] <= 1.0 and tracker.fits_ > 100


def test_lockstep_batch_equals_each_episode_alone():
    """Trackers of every kind (BCM and PoE, whose windows are filtered together, and RBCM,
    another window length, another manoeuvre component, turn modes) on different seeds, stepped together
    by ``run_episodes``, give bit for bit the estimates, variances and UCBs of each episode
    run alone; and the learning did run in the batch."""
    from dgpt_gym.benchmark.episodes import run_episodes

    settings = [
        ({}, 0),
        ({"aggregation": "poe"}, 1),
        ({"aggregation": "rbcm"}, 2),
        ({"window": 5}, 3),
        ({"manoeuvre_intensity": 100.0}, 4),
        ({}, 5),
        ({"turn_rates": (0.35, -0.35)}, 6),
    ]
    env = gym.make("DGPTrack-v0", scenario="S2", clutter_rate=5.0)
    alone = [run_episode(env, StateSpaceDGPT(**kwargs), seed) for kwargs, seed in settings]
    trackers = [StateSpaceDGPT(**kwargs) for kwargs, _ in settings]
    together = run_episodes(
        [gym.make("DGPTrack-v0", scenario="S2", clutter_rate=5.0) for _ in settings],
        trackers,
        [seed for _, seed in settings],
    )
    for single, batched in zip(alone, together):
        np.testing.assert_array_equal(single.mean, batched.mean)
        np.testing.assert_array_equal(single.var, batched.var)
        np.testing.assert_array_equal(single.ucb, batched.ucb)
    assert all(tracker.fits_ > 100 for tracker in trackers)


def test_windows_learnt_together_climb_as_each_window_filtered_alone():
    """The lockstep learning (pooled windows of different lengths, padded and filtered
    together) climbs, for each tracker, the likelihoods that :func:`filter_window` gives on
    that tracker's own window steps with the exact (BCM) filter, whatever the tracker's
    aggregation: the window's marginal likelihood is the model's."""
    from agents.state_space_dgpt import LEARNING_FILTER, _learn_pooled

    assert LEARNING_FILTER == "bcm"
    env = gym.make("DGPTrack-v0", scenario="S2", clutter_rate=5.0)
    trackers = []
    for window, seed, aggregation in ((20, 1000, "bcm"), (4, 1001, "rbcm"), (9, 1002, "gpoe")):
        obs, info = env.reset(seed=seed)
        tracker = StateSpaceDGPT(aggregation=aggregation, window=window)
        tracker.reset(info["problem_spec"])
        for _ in range(14):
            obs, *_ = env.step(tracker.update(obs).mean)
        trackers.append(tracker)
    # windows of three lengths, spanning the first step (dt 0) and a 4 s coverage gap
    assert len({len(tracker.steps_) for tracker in trackers}) == 3
    assert {step.dt for step in trackers[0].steps_} == {0.0, 1.0, 4.0}
    climbed = {}
    for tracker in trackers:
        tracker._climb = lambda values, tracker=tracker: climbed.setdefault(id(tracker), values)
    _learn_pooled(trackers)
    for tracker in trackers:
        trial = np.exp(tracker.log_q_ + np.array([0.0, LOG_STEP, -LOG_STEP])[:, None])
        expected, _, _ = filter_window(
            "bcm", list(tracker.steps_), trial, np.full(2, tracker.noise_var_), tracker.manoeuvre
        )
        np.testing.assert_allclose(climbed[id(tracker)], expected, rtol=1e-12)
    assert len({round(float(climbed[id(t)][0, 0]), 6) for t in trackers}) == 3


def test_set_estimate_with_the_trackers_own_posterior_changes_nothing():
    """Without the manoeuvre component a step's posterior is a Kalman update of the prior
    the tracker predicted for it, so feeding its own position posterior back through
    ``set_estimate`` (as the hybrid filter feeds its own) must leave the broadcast state and
    the next prediction as they were: the prior it conditions is the step's own."""
    env = gym.make("DGPTrack-v0", scenario="S1", clutter_rate=1.0)
    obs, info = env.reset(seed=1000)
    tracker = StateSpaceDGPT(manoeuvre_intensity=0.0, turn_rates=())
    tracker.reset(info["problem_spec"])
    checked = 0
    for step in range(40):
        estimate = tracker.update(obs)
        if tracker.prior_state_ is not None and tracker.data_step_ == step:
            mean, cov, prior_next = tracker.mean_, tracker.cov_, tracker.prior_next_
            returned = tracker.set_estimate(estimate.mean, estimate.var)
            np.testing.assert_allclose(tracker.mean_, mean, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(tracker.cov_, cov, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(returned, prior_next, rtol=1e-9, atol=1e-9)
            np.testing.assert_array_equal(tracker.data_mean_, tracker.mean_)
            checked += 1
        obs, *_ = env.step(estimate.mean)
    assert checked >= 20


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"aggregation": "mean"}, "aggregation"),
        ({"window": 0}, "window"),
        ({"delta": 1.0}, "delta"),
        ({"gating": "yes"}, "gating"),
        ({"manoeuvre_intensity": -1.0}, "manoeuvre_intensity"),
        ({"manoeuvre_probability": 1.0}, "manoeuvre_probability"),
        ({"process_noise": 0.0}, "process_noise"),
        ({"process_noise": 1e7}, "process_noise"),
        ({"learn_process_noise": "no"}, "learn_process_noise"),
        ({"learning": "online"}, "learning"),
        ({"learning_memory": 0.5}, "learning_memory"),
        ({"turn_rates": 0.35}, "turn_rates"),
        ({"turn_rates": (0.35, float("nan"))}, r"turn_rates\[1\]"),
        ({"turn_process_noise": -1.0}, "turn_process_noise"),
        ({"mode_stay_probability": 1.5}, "mode_stay_probability"),
        ({"process_noise_prior": "gamma"}, "process_noise_prior"),
        ({"expert_update": "pda"}, "expert_update"),
        ({"gap_end": "particles"}, "gap_end"),
        ({"gap_restart_probability": 1.0}, "gap_restart_probability"),
        ({"gap_restart_probability": -0.1}, "gap_restart_probability"),
        ({"gap_end_evidence": "points"}, "gap_end_evidence"),
        ({"gap_region_cell": -1.0}, "gap_region_cell"),
        ({"gap_region_cell": float("nan")}, "gap_region_cell"),
        ({"gap_region_cell": 0.5}, "gap_region_cell"),
        ({"gap_end_evidence": "summaries"}, "gap_region_cell"),  # cells need the scans
        ({"search_particles": 5}, "search_particles"),
        ({"search_settle_std": 0.0}, "search_settle_std"),
        ({"search_birth_probability": 1.0}, "search_birth_probability"),
        ({"gap_birth_probability": 1.0}, "gap_birth_probability"),
        ({"gap_birth_probability": -0.1}, "gap_birth_probability"),
    ],
)
def test_bad_arguments_name_themselves(kwargs, name):
    with pytest.raises(ValueError, match=name):
        StateSpaceDGPT(**kwargs)


def test_without_learning_q_stays_where_it_starts():
    """``learn_process_noise=False`` keeps q at ``process_noise`` through an episode and fits
    nothing (no share on a bound to report); the same tracker with learning starts q there
    and moves it."""
    env = gym.make("DGPTrack-v0", scenario="S2", clutter_rate=1.0)
    fixed = StateSpaceDGPT(process_noise=10.0, learn_process_noise=False)
    run_episode(env, fixed, 1001)
    assert fixed.fits_ == 0 and np.all(fixed.log_q_ == np.log(10.0))
    assert np.isnan(fixed.diagnostics()["share_at_bound"])
    learning = StateSpaceDGPT(process_noise=10.0)
    run_episode(env, learning, 1001)
    assert learning.fits_ > 100 and not np.allclose(learning.log_q_, np.log(10.0))


@pytest.mark.parametrize(
    "tracker, scenario",
    [
        ("dgpt-bcm", "S1"),
        ("dgpt-bcm", "S4"),
        *(("dgpt-rbcm", scenario) for scenario in ("S1", "S2", "S3", "S4")),
    ],
)
def test_is_calibrated_on_sensed_steps_at_clutter_1(tracker, scenario):
    """Issue 12's calibration goals for the default trackers on sensed steps, sigma_z 1,
    clutter 1, six training-seed episodes (670-770 sensed steps; as for the hybrid in
    test_hybrid_cpf.py): 3-sigma coverage per axis >= 99 % less three binomial standard
    errors (about 1.1 points), median 2-D NEES in [0.7, 2.8] within its sampling error (the
    sign test of ``median_in_band``: at most 1/2 + 3 sqrt(1 / 4n), about 56 %, of the steps
    below 0.7 or above 2.8). Measured in 0.11.0: coverage 98.8-99.7 %, median NEES
    0.68-1.40 (dgpt-rbcm on S1: 0.68, 51 % of the steps below 0.7; dgpt-bcm there 0.96:
    RBCM's variance is wider than its error)."""
    coverage, nees, n = sensed_calibration(tracker, scenario, range(1000, 1006))
    assert n > 600
    assert np.all(coverage >= 0.99 - 3.0 * np.sqrt(0.99 * 0.01 / n)), coverage
    assert median_in_band(nees, 0.7, 2.8), (np.median(nees), np.mean(nees < 0.7))


@pytest.mark.parametrize("scenario", ["S1", "S2", "S3", "S4"])
def test_the_ucb_covers_the_sensed_steps_without_being_wide(scenario):
    """Issue 12's UCB goals for DGPT-RBCM on sensed steps, sigma_z 1, clutter 1, six
    training-seed episodes (666-774 sensed steps): coverage per axis >= 99.7 % less three
    binomial standard errors (about 0.6 points), and on S1 and S2 a mean half-width at most 4
    times the RMSE. Measured in 0.23.1: coverage 100 % in every cell; half-width / RMSE
    1.3-3.0 on S1 and S2, 4.1-4.6 on S3 and S4, where the goal is not met (the grid's worst
    cell on detected steps: 4.35; docs/analysis.md), so their width is not asserted."""
    errors, _, ucbs = sensed_steps("dgpt-rbcm", scenario, range(1000, 1006))
    n = errors.shape[0]
    assert n > 600
    coverage = np.mean(np.abs(errors) <= ucbs, axis=0)
    assert np.all(coverage >= 0.997 - 3.0 * np.sqrt(0.997 * 0.003 / n)), coverage
    if scenario in ("S1", "S2"):
        width_over_rmse = np.mean(ucbs, axis=0) / np.sqrt(np.mean(errors**2, axis=0))
        assert np.all(width_over_rmse <= 4.0), width_over_rmse


def test_window_steps_span_the_gaps_between_steps_with_data():
    """A window step's dt runs from the previous step with data and its prior is the
    posterior after that step, so re-filtering the window crosses a gap in one prediction:
    with data at t = 0, 1, 2 and 5, the last window step has dt = 3 and the prior of t = 2."""
    spec = problem_spec(sensor_positions=((0.0, 0.0), (20.0, 0.0)))
    tracker = StateSpaceDGPT()
    tracker.reset(spec)
    rng = np.random.default_rng(5)
    empty = measurement_obs(0, np.empty((0, 2)), [])
    for t in (0, 1, 2, 3, 4, 5):
        if t in (3, 4):
            tracker.update({**empty, "t": t})
            continue
        tracker.update(
            measurement_obs(t, np.array([5.0 + t, 2.0]) + rng.normal(0, 1, (2, 2)), [0, 1])
        )
        if t == 2:
            after_two = (tracker.mean_.copy(), tracker.cov_.copy())
    assert [step.dt for step in tracker.steps_] == [0.0, 1.0, 1.0, 3.0]
    np.testing.assert_array_equal(tracker.steps_[-1].mean, after_two[0])
    np.testing.assert_array_equal(tracker.steps_[-1].cov, after_two[1])


def test_q_identification_records_without_changing_the_tracker():
    """scripts/q_identification.py's recording tracker gives the tracker's estimates, one
    record per learning step, on the floor exactly where the tracker counts a fit on a
    bound (q never reaches its upper bound here), and finite log likelihood ratios at every
    q of its grid, per axis."""
    path = Path(__file__).resolve().parents[2] / "scripts" / "q_identification.py"
    spec_ = importlib.util.spec_from_file_location("q_identification", path)
    module = importlib.util.module_from_spec(spec_)
    spec_.loader.exec_module(module)
    env = gym.make("DGPTrack-v0", scenario="S1", clutter_rate=5.0)
    plain, recording = StateSpaceDGPT(), module.RecordingStateSpaceDGPT()
    a, b = run_episode(env, plain, seed=1000), run_episode(env, recording, seed=1000)
    np.testing.assert_array_equal(a.mean, b.mean)
    assert len(recording.records_) == recording.fits_ > 50
    on_floor = np.array([record[0] for record in recording.records_])
    assert on_floor.any(axis=1).sum() == recording.fits_at_bound_
    ratios = np.array([record[1] for record in recording.records_])
    assert ratios.shape == (recording.fits_, len(module.Q_GRID), 2)
    assert np.all(np.isfinite(ratios))


def test_the_centralized_gp_is_the_bcm_aggregate_exactly():
    """The registration of ``gp``: it is the BCM tracker (the code computes BCM as one
    Kalman update on every summary's network-wide sums, so the two share their code), and
    gives bit for bit ``dgpt-bcm``'s episode, while RBCM, whose weights differ, does not.
    That this update is the exact posterior of every summary is checked against the dense
    GP in ``test_bcm_window_likelihood_and_posterior_are_the_dense_ncv_gp`` and
    ``test_fused_update_is_the_aggregation_of_the_experts_local_posteriors``."""
    env = gym.make("DGPTrack-v0", scenario="S3", clutter_rate=5.0)
    centralized = run_episode(env, dgpt_gym.make_tracker("gp"), 7)
    bcm = run_episode(env, dgpt_gym.make_tracker("dgpt-bcm"), 7)
    rbcm = run_episode(env, dgpt_gym.make_tracker("dgpt-rbcm"), 7)
    np.testing.assert_array_equal(centralized.mean, bcm.mean)
    np.testing.assert_array_equal(centralized.var, bcm.var)
    assert not np.array_equal(centralized.mean, rbcm.mean)
    with pytest.raises(ValueError, match="aggregation"):
        dgpt_gym.make_tracker("gp", aggregation="rbcm")


@pytest.mark.parametrize("aggregation", ["rbcm", "bcm", "gpoe", "poe"])
def test_the_reported_variance_is_the_estimates_error_variance_in_the_model(aggregation):
    """Targets drawn from the tracker's own NCV model (q = 2, no manoeuvres, no turns, q
    not learnt), four sensors each reporting the target with sigma_n = 1 and no clutter: the
    2-D NEES of the estimate at the 12th step is chi-square with 2 degrees of freedom, mean 2
    and standard deviation 2, so the mean over 400 independent episodes lies within
    5 x 2 / sqrt(400) = 0.5 of 2. RBCM's, GPoE's and PoE's own posterior variances are not
    their errors' (mean NEES 1.36, 2.9 and 8.5 here); the tracker reports the error's
    variance under the model, carrying the excess of the error's covariance over the
    broadcast posterior from step to step (:func:`agents.state_space.aggregate_error_cov`;
    measured 1.96, 1.96, 1.98 and 1.99 for RBCM, BCM, GPoE and PoE; without the carried
    excess GPoE and PoE gave 2.6 and 3.7)."""
    q, n_sensors, n_episodes, n_steps = 2.0, 4, 400, 12
    transition = np.array([[1.0, 1.0], [0.0, 1.0]])
    process_cov = q * np.array([[1.0 / 3.0, 1.0 / 2.0], [1.0 / 2.0, 1.0]])  # dt = 1
    spec = problem_spec(
        sensor_positions=[(0.0, 0.0), (30.0, 0.0), (0.0, 30.0), (30.0, 30.0)],
        clutter_rate=0.0,
        n_steps=n_steps,
    )
    rng = np.random.default_rng(4)
    nees = []
    for episode in range(n_episodes):
        tracker = StateSpaceDGPT(
            aggregation=aggregation,
            turn_rates=(),
            manoeuvre_intensity=0.0,
            learn_process_noise=False,
            process_noise=q,
        )
        tracker.reset(spec, seed=episode)
        state = np.array([[15.0, 2.0], [15.0, -1.0]])  # axes, (position, velocity)
        for t in range(n_steps):
            if t:
                noise = rng.multivariate_normal(np.zeros(2), process_cov, size=2)
                state = state @ transition.T + noise
            points = state[:, 0] + rng.normal(size=(n_sensors, 2))
            estimate = tracker.update(measurement_obs(t, points, np.arange(n_sensors)))
        nees.append(np.sum((estimate.mean - state[:, 0]) ** 2 / estimate.var))
    assert abs(np.mean(nees) - 2.0) < 5 * 2.0 / np.sqrt(n_episodes), np.mean(nees)


def test_the_learnt_q_stops_on_its_floor():
    """On S1's straight legs the window's likelihood climbs towards q = 0: log q reaches
    the lower bound of PROCESS_NOISE_BOUNDS and is held there, never below (a Newton step
    of up to 1 per step would carry it past the bound without the clip)."""
    env = gym.make("DGPTrack-v0", scenario="S1", clutter_rate=1.0)
    tracker = StateSpaceDGPT()
    observation, info = env.reset(seed=1000)
    tracker.reset(info["problem_spec"], seed=1000)
    log_q, truncated = [], False
    while not truncated:
        estimate = tracker.update(observation)
        log_q.append(tracker.log_q_.copy())
        observation, _, _, truncated, _ = env.step(estimate.mean)
    floor = np.log(PROCESS_NOISE_BOUNDS[0])
    assert np.min(log_q) == floor
    assert np.sum(np.array(log_q) == floor) > 10


@pytest.mark.parametrize("aggregation", ["bcm", "poe", "rbcm"])
def test_each_hypothesis_weighs_its_prediction_by_the_dense_likelihood(aggregation):
    """On every step with data of an S3 episode at clutter 5 (so several sensors and the
    manoeuvre's two process-noise components): each hypothesis's log weight is its log
    prior plus, per axis, the log density of its M summaries under its prediction,
    N(mu 1, p 1 1^T + diag(s)) by scipy; and its posterior is the aggregation, in
    information form from explicit inverses, of the experts' posteriors, each the PDA
    moments of its sensor's measurements (the mixture over which is the target's), and its
    error variance the dense one with each expert as the measurement that gives its
    posterior."""
    tracker = StateSpaceDGPT(aggregation=aggregation)
    recorded = {}
    own_hypotheses = tracker._hypotheses

    def recording(points, sensors, prior_means, prior_covs, log_priors, *rest):
        recorded["prior"] = (prior_means, prior_covs, log_priors)
        recorded["hypotheses"] = own_hypotheses(
            points, sensors, prior_means, prior_covs, log_priors, *rest
        )
        return recorded["hypotheses"]

    tracker._hypotheses = recording
    env = gym.make("DGPTrack-v0", scenario="S3", clutter_rate=5.0)
    obs, info = env.reset(seed=1001)
    tracker.reset(info["problem_spec"], seed=1001)
    checked = several = 0
    for _ in range(60):
        recorded.clear()
        estimate = tracker.update(obs)
        if "hypotheses" in recorded:
            prior_means, prior_covs, log_priors = recorded["prior"]
            own = recorded["hypotheses"]
            for h in range(len(log_priors)):
                expected = log_priors[h]
                for axis in range(2):
                    z = own["summaries"][h, axis]
                    s = own["summary_var"][h, axis]
                    p = prior_covs[h, axis, 0, 0]
                    expected += multivariate_normal.logpdf(
                        z, np.full(z.size, prior_means[h, axis, 0]), p + np.diag(s)
                    )
                    # expert i's posterior: the PDA moments of its sensor's mixture, gain
                    # K = P0 e1 / a, a = p + r_i (r_i its summary's noise variance), mean
                    # mu + K (z_i - mu_p), covariance P0 - K K^T (a - S_i), the spread S_i
                    # capped at 0.99 a; then eqs. (8)-(20) in information form with explicit
                    # inverses: precision sum_i beta_i P_i^-1 + (1 - sum_i beta_i) P0^-1 for
                    # BCM and RBCM (sum_i P_i^-1 for PoE), beta_i = 1/2 log(det P0 / det P_i)
                    # for RBCM with several experts, else 1
                    prior_mean, prior_cov = prior_means[h, axis], prior_covs[h, axis]
                    prior_precision = np.linalg.inv(prior_cov)
                    spread = own["spread"][h, axis]
                    innovation = p + s - spread
                    spread = np.minimum(spread, MIXTURE_SPREAD_SHARE * innovation)
                    precision, information, betas, pseudo_vars = 0.0, 0.0, [], []
                    for i, (z_i, a_i, spread_i) in enumerate(zip(z, innovation, spread)):
                        gain = prior_cov[:, 0] / a_i
                        expert_cov = prior_cov - np.outer(gain, gain) * (a_i - spread_i)
                        expert_mean = prior_mean + gain * (z_i - prior_mean[0])
                        np.testing.assert_allclose(
                            own["expert_means"][h, axis, i], expert_mean, rtol=1e-9
                        )
                        np.testing.assert_allclose(
                            own["expert_covs"][h, axis, i], expert_cov, rtol=1e-7, atol=1e-9
                        )
                        pseudo_vars.append(
                            equivalent_measurement(prior_mean, prior_cov, expert_mean, expert_cov)[
                                1
                            ]
                        )
                        beta = 1.0
                        if aggregation == "rbcm" and z.size > 1:
                            determinants = np.linalg.det(prior_cov) / np.linalg.det(expert_cov)
                            beta = 0.5 * np.log(determinants)
                        betas.append(beta)
                        precision = precision + beta * np.linalg.inv(expert_cov)
                        information = information + beta * np.linalg.solve(expert_cov, expert_mean)
                    if aggregation != "poe":
                        precision = precision + (1.0 - sum(betas)) * prior_precision
                        information = (
                            information + (1.0 - sum(betas)) * prior_precision @ prior_mean
                        )
                    cov = np.linalg.inv(precision)
                    np.testing.assert_allclose(own["mean"][h, axis], cov @ information, rtol=1e-9)
                    np.testing.assert_allclose(own["cov"][h, axis], cov, rtol=1e-7, atol=1e-9)
                    # the aggregate's error: each expert as the measurement that gives its
                    # posterior, with independent noise of that variance
                    np.testing.assert_allclose(
                        own["error_std"][h, axis] ** 2,
                        dense_error_var(aggregation, prior_cov, pseudo_vars),
                        rtol=1e-7,
                    )
                np.testing.assert_allclose(own["log_weight"][h], expected, rtol=1e-9)
            checked += 1
            several += own["summaries"].shape[-1] >= 2
        obs, *_ = env.step(estimate.mean)
    assert checked >= 40 and several >= 20


def test_grid_maximum_is_the_vertex_of_a_sampled_parabola():
    """Samples of -(x - u)^2 on a grid of spacing 0.5: the parabola through the best three
    is the function itself, so the maximum is u exactly, per column; a maximum beyond the
    grid lands on its end and is flagged; a flat column takes its first point."""
    grid = np.arange(-2.0, 2.01, 0.5)
    optimum = np.array([0.3, -1.1, 7.0, -9.0])
    values = -((grid[:, None] - optimum) ** 2)
    values = np.column_stack([values, np.zeros(len(grid))])
    maximum, on_edge = grid_maximum(values, grid)
    np.testing.assert_allclose(maximum, [0.3, -1.1, 2.0, -2.0, -2.0], atol=1e-12)
    np.testing.assert_array_equal(on_edge, [False, False, True, True, True])
    with pytest.raises(ValueError, match="at least 3 points"):
        grid_maximum(values[:2], grid[:2])
    with pytest.raises(ValueError, match=r"shape \(9, 5\)"):
        grid_maximum(values, grid[:-1])


def dense_step_evidence(tracker, ncv_base, dt, summaries, noise_var, q_axis, q_value):
    """log p(this step's summaries) (both axes, summed over the hypotheses of
    ``tracker.step_predictions_``) with the NCV mode's prediction on axis ``q_axis`` made
    again at q = ``q_value`` from ``ncv_base`` = (mean (2, 2), cov (2, 2, 2)), the state the
    NCV mode predicts from (with turn modes the IMM's mixed NCV posterior, else the last
    broadcast posterior), through ``ncv_predict`` under its two process-noise components,
    and every other prediction as the tracker made it: dense Gaussians
    p 1 1^T + diag(noise_var) per hypothesis and axis."""
    log_priors, means, covs, modes = tracker.step_predictions_
    modes = np.zeros(len(log_priors), dtype=int) if modes is None else modes
    intensities = [q_value, q_value + tracker.manoeuvre.intensity]
    terms = []
    for h, (log_prior, mode) in enumerate(zip(log_priors, modes)):
        total = log_prior
        for axis in range(2):
            mean, var = means[h, axis, 0], covs[h, axis, 0, 0]
            if mode == 0 and axis == q_axis:
                base_mean, base_cov = ncv_base[0][axis], ncv_base[1][axis]
                var = ncv_predict(base_mean, base_cov, dt, intensities[h])[1][0, 0]
            total += multivariate_normal.logpdf(
                summaries[:, axis], np.full(len(summaries), mean), var + np.diag(noise_var)
            )
        terms.append(total)
    return np.logaddexp.reduce(terms)


@pytest.mark.parametrize("turn_rates", [TURN_MODES["rates"], ()])
def test_the_recursive_learning_sums_the_dense_step_evidences(turn_rates):
    """Two sensors, one point each per step, the manoeuvre component, with and without the
    turn modes, no association: after the first step with a prediction the learning's sums
    are that step's evidence at every q of LEARNING_GRID (less its largest), computed
    densely with the NCV predictions made again at that q; after the next step (2 s later)
    they are the first step's times 1 - 1 / memory plus the second's; q is their maximum."""
    spec = problem_spec(sensor_positions=((0.0, 0.0), (20.0, 0.0)), n_steps=5)
    memory = 4.0
    tracker = StateSpaceDGPT(
        gating=False, turn_rates=turn_rates, learning="recursive", learning_memory=memory
    )
    tracker.reset(spec)
    rng = np.random.default_rng(3)
    sums = np.zeros((len(LEARNING_GRID), 2))
    for t, dt in ((0, None), (1, 1.0), (3, 2.0)):
        points = np.array([[3.0 * t, 2.0 * t]] * 2) + rng.normal(size=(2, 2))
        # what the NCV mode will predict from: the IMM's mixing for this step (made after
        # the last), or the last posterior
        ncv_base = (tracker.mean_, tracker.cov_)
        if turn_rates and tracker.mixed_ is not None:
            ncv_base = (tracker.mixed_[1][0], tracker.mixed_[2][0])
        tracker.update(measurement_obs(t, points, [0, 1]))
        if t == 0:  # a new track: no learning
            np.testing.assert_array_equal(tracker.evidence_sums_, 0.0)
            np.testing.assert_array_equal(tracker.log_q_, 0.0)
            assert tracker.fits_ == 0
            continue
        dense = np.array(
            [
                [
                    dense_step_evidence(tracker, ncv_base, dt, points, np.ones(2), axis, q)
                    for axis in range(2)
                ]
                for q in LEARNING_GRID
            ]
        )
        sums = (1.0 - 1.0 / memory) * sums + dense - dense.max(axis=0)
        np.testing.assert_allclose(tracker.evidence_sums_, sums, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(tracker.log_q_, grid_maximum(sums, np.log(LEARNING_GRID))[0])


def test_the_recursive_learning_needs_no_window_prior():
    with pytest.raises(ValueError, match="process_noise_prior"):
        StateSpaceDGPT(learning="recursive", process_noise_prior="boundary-avoiding")


def test_the_recursive_learning_skips_the_ends_of_gaps():
    """A gap's end (the silence's particles carried to the step and the reporting region's
    new track, ``gap_end="reports"``) predicts without q, so the recursive learning must
    not learn from it: with ``gap_end_evidence="summaries"`` the step's hypotheses are
    weighed as any step's, and S1's seed 1000 has such steps."""

    class Recording(StateSpaceDGPT):
        def _reporting_predictions(self, *args):
            self.gap_end_step_ = True
            return super()._reporting_predictions(*args)

        def _learn_recursive(self, *args):
            assert not self.gap_end_step_, "learnt from a gap's end"
            super()._learn_recursive(*args)

    env = gym.make("DGPTrack-v0", scenario="S1", clutter_rate=1.0)
    observation, info = env.reset(seed=1000)
    tracker = Recording(
        silence_particles=100,
        gap_end_evidence="summaries",
        gap_region_cell=0.0,
        learning="recursive",
    )
    tracker.reset(info["problem_spec"], seed=1000)
    gap_ends, truncated = 0, False
    while not truncated:
        tracker.gap_end_step_ = False
        estimate = tracker.update(observation)
        gap_ends += tracker.gap_end_step_
        observation, _, _, truncated, _ = env.step(estimate.mean)
    assert gap_ends >= 3 and tracker.fits_ > 100, (gap_ends, tracker.fits_)
