"""baselines/kalman.py against dense, loop-by-loop references of the same formulas."""

import itertools

import numpy as np
import pytest
from conftest import mixture_moments
from scipy.stats import multivariate_normal

from baselines import kalman
from baselines.kalman import (
    POSITION_MATRIX,
    imm_mix,
    inverse_2x2,
    multi_detection_update,
    reduce_mixture,
)

H = POSITION_MATRIX
NOISE_STD = 1.0
R = NOISE_STD**2 * np.eye(2)
DETECTION_RATE = 1.0
CLUTTER_DENSITY = 5.0 / (np.pi * 50.0**2)


def anchored_mixture_by_loops(mean, cov, measurements, miss_probability=0.0):
    """The anchored Gaussian mixture of the multi_detection_update docstring, one anchor and
    one measurement at a time, in information form, with explicit inverses; with a
    missed-detection component (the prior, weight ``miss_probability``) when positive. Also
    the scan's log-likelihood ratio, each anchor's weight divided by 1 + sum_i beta_i."""
    weights, means, covs, sizes = [], [], [], []
    if miss_probability > 0:
        sizes.append(1.0)
        weights.append(np.log(miss_probability))
        means.append(mean)
        covs.append(cov)
    for j, anchor in enumerate(measurements):
        innovation_cov = H @ cov @ H.T + R
        gain = cov @ H.T @ np.linalg.inv(innovation_cov)
        anchor_mean = mean + gain @ (anchor - H @ mean)
        anchor_cov = cov - gain @ H @ cov
        log_weight = (
            np.log(DETECTION_RATE)
            + multivariate_normal(H @ mean, innovation_cov).logpdf(anchor)
            - np.log(CLUTTER_DENSITY)
        )
        support_cov = H @ anchor_cov @ H.T + R
        beta = np.zeros(len(measurements))
        for i, other in enumerate(measurements):
            if i == j:
                continue
            rho = (
                DETECTION_RATE
                * multivariate_normal(H @ anchor_mean, support_cov).pdf(other)
                / CLUTTER_DENSITY
            )
            log_weight += np.log1p(rho)
            beta[i] = rho / (1.0 + rho)
        information = np.linalg.inv(anchor_cov) + beta.sum() * H.T @ np.linalg.inv(R) @ H
        refined_cov = np.linalg.inv(information)
        refined_mean = refined_cov @ (
            np.linalg.inv(anchor_cov) @ anchor_mean + H.T @ np.linalg.inv(R) @ (beta @ measurements)
        )
        weights.append(log_weight + np.log1p(-miss_probability))
        sizes.append(1.0 + beta.sum())
        means.append(refined_mean)
        covs.append(refined_cov)
    weights = np.array(weights)
    mixture_mean, mixture_cov = mixture_moments(weights, means, covs)
    # the scan likelihood counts each subset once: each anchor's weight over the expected
    # size of its subset
    return mixture_mean, mixture_cov, np.logaddexp.reduce(weights - np.log(sizes))


TIGHT_CORRELATED_COV = np.array(
    [[0.6, 0.2, 0.5, 0.0], [0.2, 4.0, 0.0, 1.0], [0.5, 0.0, 0.6, 0.1], [0.0, 1.0, 0.1, 4.0]]
)
"""A prior whose position block (correlation 0.83) makes the support covariance far from
the isotropic 2 R, so that a wrong whitening shows."""


def random_problem(rng, n_target=3, n_clutter=6, tight=False):
    mean = np.array([100.0, 5.0, 200.0, -3.0])
    factor = rng.normal(size=(4, 4))
    cov = TIGHT_CORRELATED_COV if tight else 4.0 * factor @ factor.T + np.eye(4)
    target = rng.normal([100.0, 200.0], NOISE_STD, (n_target, 2))
    clutter = rng.uniform([60.0, 160.0], [140.0, 240.0], (n_clutter, 2))
    return mean, cov, rng.permutation(np.vstack([target, clutter]))


@pytest.fixture(params=["all pairs", "KD-tree pairs"])
def pairing(request, monkeypatch):
    """Runs a test with both ways of finding the pairs of measurements that support each
    other: every pair formed, or the KD-tree's sparse pairs (used for large scans)."""
    threshold = 10**9 if request.param == "all pairs" else 0
    monkeypatch.setattr(kalman, "SPARSE_SUPPORT_MIN_POINTS", threshold)


@pytest.mark.usefixtures("pairing")
@pytest.mark.parametrize("tight", [False, True], ids=["wide prior", "tight correlated prior"])
@pytest.mark.parametrize("miss_probability", [0.0, 0.14])
def test_multi_detection_update_equals_the_anchor_by_anchor_reference(miss_probability, tight):
    rng = np.random.default_rng(3)
    for _ in range(5):
        mean, cov, measurements = random_problem(rng, tight=tight)
        got = multi_detection_update(
            mean,
            cov,
            measurements,
            H,
            NOISE_STD,
            DETECTION_RATE,
            CLUTTER_DENSITY,
            miss_probability,
        )
        expected = anchored_mixture_by_loops(mean, cov, measurements, miss_probability)
        np.testing.assert_allclose(got[0], expected[0], rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(got[1], expected[1], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(got[2], expected[2], rtol=1e-10)


@pytest.mark.usefixtures("pairing")
def test_multi_detection_update_batches_over_modes_without_mixing_them():
    rng = np.random.default_rng(4)
    mean, cov, measurements = random_problem(rng)
    shifts = rng.normal(0.0, 2.0, (2, 3, 4))
    means = mean + shifts  # (episodes, modes, state)
    covs = np.stack([cov, 2.0 * cov, TIGHT_CORRELATED_COV])  # (modes, ...), broadcast
    batched = multi_detection_update(
        means, covs, measurements, H, NOISE_STD, DETECTION_RATE, CLUTTER_DENSITY
    )
    for e, k in np.ndindex(2, 3):
        alone = multi_detection_update(
            means[e, k], covs[k], measurements, H, NOISE_STD, DETECTION_RATE, CLUTTER_DENSITY
        )
        for a, b in zip(batched, alone):
            np.testing.assert_allclose(a[e, k], b, rtol=1e-12, atol=1e-12)
    # one mean under several covariances
    batched = multi_detection_update(
        mean, covs, measurements, H, NOISE_STD, DETECTION_RATE, CLUTTER_DENSITY
    )
    for k in range(3):
        alone = multi_detection_update(
            mean, covs[k], measurements, H, NOISE_STD, DETECTION_RATE, CLUTTER_DENSITY
        )
        for a, b in zip(batched, alone):
            np.testing.assert_allclose(a[k], b, rtol=1e-12, atol=1e-12)


def test_sparse_pairs_are_the_pairs_above_the_cutoff(monkeypatch):
    """With the cutoff raised to log rho = -1 many pairs fall below it: the KD-tree's sums
    equal sums over exactly the pairs at or above it, each found with an explicit inverse
    of an anisotropic support covariance."""
    monkeypatch.setattr(kalman, "SUPPORT_LOG_RHO_CUTOFF", -1.0)
    rng = np.random.default_rng(9)
    measurements = rng.uniform(0.0, 12.0, (40, 2))
    anchors = measurements + rng.normal(0.0, 0.3, (2, 40, 2))  # two batch elements
    support_covs = np.array([[[1.5, 0.6], [0.6, 1.1]], [[1.2, -0.3], [-0.3, 1.9]]])
    log_rho_scales = np.array([1.2, 0.4])
    got = kalman._pairwise_support_sparse(measurements, anchors, support_covs, log_rho_scales)
    for k in range(2):
        inverse = np.linalg.inv(support_covs[k])
        log_support, expected, weighted, n_kept = np.zeros(40), np.zeros(40), np.zeros((40, 2)), 0
        for j, i in itertools.permutations(range(40), 2):
            offset = measurements[i] - anchors[k, j]
            log_rho = log_rho_scales[k] - 0.5 * offset @ inverse @ offset
            if log_rho < -1.0:
                continue
            n_kept += 1
            rho = np.exp(log_rho)
            log_support[j] += np.log1p(rho)
            expected[j] += rho / (1.0 + rho)
            weighted[j] += rho / (1.0 + rho) * measurements[i]
        assert 0 < n_kept < 40 * 39 / 4  # the cutoff drops most pairs
        np.testing.assert_allclose(got[0][k], log_support, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(got[1][k], expected, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(got[2][k], weighted, rtol=1e-12, atol=1e-13)


def test_the_target_cluster_outweighs_isolated_clutter():
    """From a flat prior, three consistent target measurements among six clutter points put
    the posterior on their centroid with about the variance of their mean."""
    rng = np.random.default_rng(5)
    target_position = np.array([100.0, 200.0])
    target = target_position + rng.normal(0.0, NOISE_STD, (3, 2))
    clutter = rng.uniform(target_position - 40.0, target_position + 40.0, (6, 2))
    measurements = np.vstack([clutter[:3], target, clutter[3:]])
    mean = np.array([120.0, 0.0, 180.0, 0.0])
    cov = np.diag([1e6, 225.0, 1e6, 225.0])
    new_mean, new_cov, _ = multi_detection_update(
        mean, cov, measurements, H, NOISE_STD, DETECTION_RATE, CLUTTER_DENSITY
    )
    # Not exactly the centroid: each target point's beta is rho / (1 + rho) with rho of
    # 30-75 here (0.97-0.99). Picking any clutter point would move the mean by metres.
    np.testing.assert_allclose(new_mean[[0, 2]], target.mean(axis=0), atol=0.05 * NOISE_STD)
    # The variance keeps the residual chance (~1e-3 each) that an isolated clutter point
    # 20-40 m away is the target: the moment match adds ~1e-3 x 30^2 m^2. Without the
    # clutter only the three target points remain: about sigma_z^2 / 3, and each anchor
    # uses all three (a single point would leave sigma_z^2).
    _, target_only_cov, _ = multi_detection_update(
        mean, cov, target, H, NOISE_STD, DETECTION_RATE, CLUTTER_DENSITY
    )
    np.testing.assert_allclose(np.diag(target_only_cov)[[0, 2]], NOISE_STD**2 / 3, rtol=0.05)
    assert np.all(np.diag(new_cov)[[0, 2]] > np.diag(target_only_cov)[[0, 2]])


def test_sparse_pairs_equal_all_pairs_on_a_scan_of_clutter_at_every_sensor(monkeypatch):
    """A scan like clutter at every sensor of a large network: 600 points over 1 km^2 with
    a few target points, two modes. The KD-tree drops only pairs with rho below 2e-22, so
    the posterior and the likelihood agree with the all-pairs evaluation to rounding."""
    rng = np.random.default_rng(8)
    target = rng.normal([500.0, 500.0], NOISE_STD, (4, 2))
    clutter = rng.uniform(0.0, 1000.0, (596, 2))
    measurements = rng.permutation(np.vstack([target, clutter]))
    means = np.array([[490.0, 5.0, 505.0, -3.0], [520.0, 0.0, 480.0, 0.0]])
    covs = np.stack([np.diag([400.0, 25.0, 400.0, 25.0]), np.diag([1e4, 100.0, 1e4, 100.0])])
    results = {}
    for threshold in (10**9, 0):
        monkeypatch.setattr(kalman, "SPARSE_SUPPORT_MIN_POINTS", threshold)
        results[threshold] = multi_detection_update(
            means, covs, measurements, H, NOISE_STD, DETECTION_RATE, CLUTTER_DENSITY, 0.05
        )
    for dense, sparse in zip(results[10**9], results[0]):
        np.testing.assert_allclose(sparse, dense, rtol=1e-12, atol=1e-9)
    # and the target cluster carries the posterior of the tight mode
    np.testing.assert_allclose(results[0][0][0, [0, 2]], target.mean(axis=0), atol=0.1)


@pytest.mark.usefixtures("pairing")
def test_an_anchor_nothing_supports_keeps_its_own_kalman_update():
    """Two measurements 1 km apart, 10 km from the origin, support each other with
    rho ~ exp(-1e5): each anchor's component is its Kalman update, with no refinement (no
    pull towards the origin from a refinement by nothing)."""
    centre = np.array([1e4, 2e4])
    mean = np.array([centre[0], 0.0, centre[1], 0.0])
    cov = np.diag([1e6, 1.0, 1e6, 1.0])
    measurements = centre + np.array([[-500.0, 0.0], [500.0, 0.0]])
    new_mean, new_cov, _ = multi_detection_update(
        mean, cov, measurements, H, NOISE_STD, DETECTION_RATE, CLUTTER_DENSITY
    )
    # equal evidence by symmetry: the mixture of the two anchor updates, weights 1/2
    anchor_variance = 1e6 * NOISE_STD**2 / (1e6 + NOISE_STD**2)
    anchor_offset = 500.0 * 1e6 / (1e6 + NOISE_STD**2)
    np.testing.assert_allclose(new_mean[[0, 2]], centre, rtol=0, atol=1e-10)
    # P - P (P + R)^-1 P with P = 1e6 loses about six digits to cancellation
    np.testing.assert_allclose(new_cov[0, 0], anchor_variance + anchor_offset**2, rtol=1e-9)
    np.testing.assert_allclose(new_cov[2, 2], anchor_variance, rtol=1e-9)


def test_a_non_finite_prior_gives_the_same_answer_with_either_pairing(monkeypatch):
    """A state gone non-finite upstream reaches the sums as NaN with every pair formed; the
    KD-tree would raise on it, so the update falls back to the dense sums."""
    rng = np.random.default_rng(10)
    mean, cov, measurements = random_problem(rng)
    mean[0] = np.nan
    results = []
    for threshold in (10**9, 0):
        monkeypatch.setattr(kalman, "SPARSE_SUPPORT_MIN_POINTS", threshold)
        with np.errstate(invalid="ignore"):
            results.append(
                multi_detection_update(
                    mean, cov, measurements, H, NOISE_STD, DETECTION_RATE, CLUTTER_DENSITY
                )
            )
    for dense, sparse in zip(*results):
        np.testing.assert_array_equal(sparse, dense)


def test_inverse_2x2_and_mixture_reduction_by_hand():
    matrix = np.array([[4.0, 1.0], [1.0, 3.0]])  # det 11
    np.testing.assert_allclose(inverse_2x2(matrix), np.array([[3.0, -1.0], [-1.0, 4.0]]) / 11)
    # two 1-D components, weights 1/4 and 3/4, means 0 and 4, variances 1 and 2:
    # mean 3, variance 1/4 * (1 + 9) + 3/4 * (2 + 1) = 4.75
    mean, cov = reduce_mixture(
        np.log([1.0, 3.0]), np.array([[0.0], [4.0]]), np.array([[[1.0]], [[2.0]]])
    )
    np.testing.assert_allclose(mean, [3.0])
    np.testing.assert_allclose(cov, [[4.75]])


def test_imm_mix_by_hand():
    # mu = (0.8, 0.2), P = [[0.9, 0.1], [0.3, 0.7]]: c = (0.78, 0.22);
    # mu_{0|0} = 0.72 / 0.78, mu_{1|0} = 0.06 / 0.78, mu_{0|1} = 0.08 / 0.22, mu_{1|1} = 0.14 / 0.22
    means = np.array([[0.0], [10.0]])
    covs = np.array([[[1.0]], [[4.0]]])
    mixed_mean, mixed_cov, predicted = imm_mix(
        means, covs, np.array([0.8, 0.2]), np.array([[0.9, 0.1], [0.3, 0.7]])
    )
    np.testing.assert_allclose(predicted, [0.78, 0.22])
    w0, w1 = 0.06 / 0.78, 0.14 / 0.22
    np.testing.assert_allclose(mixed_mean[:, 0], [10 * w0, 10 * w1])
    for k, w in enumerate((w0, w1)):
        m = 10 * w
        expected = (1 - w) * (1 + m**2) + w * (4 + (10 - m) ** 2)
        np.testing.assert_allclose(mixed_cov[k, 0, 0], expected)
