"""pda, imm-pda and the clairvoyant floor against independent references.

Kalman identities checked with a plain-numpy Kalman filter (explicit inverses, stacked
measurement updates), the multi-detection association against the exact posterior of the
scan likelihood expanded over all subsets of measurements, the IMM interaction by hand and
on an S3 episode, coasting, the clairvoyant floor against every registered tracker, oracle
isolation in the evaluation loop, the env's truth info and argument validation.
"""

import itertools

import gymnasium as gym
import numpy as np
import pytest
from conftest import mixture_moments, problem_spec, z_tolerance
from scipy.stats import multivariate_normal

from baselines import kalman
from baselines.centroid import GatedCentroidTracker
from baselines.clairvoyant import ClairvoyantFilter
from baselines.cpf import turn_transition
from baselines.kalman import (
    POSITION_MATRIX,
    constant_velocity_model,
    imm_mix,
    multi_detection_update,
    pda_update,
)
from baselines.pda import IMMPDAFilter, PDAFilter
from dgpt_gym import make_tracker, tracker_ids
from dgpt_gym.benchmark import metrics
from dgpt_gym.benchmark.episodes import run_episode, run_episodes, run_monte_carlo
from dgpt_gym.benchmark.windows import tuned_kwargs

H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
K_ROWS = 8  # padding size of the hand-built observations


def make_spec(clutter_rate=0.0, noise_std=2.0, dt=0.5, detection_rate=1.0):
    return problem_spec(
        [[150.0, 150.0], [400.0, 300.0], [700.0, 650.0]],
        noise_std=noise_std,
        clutter_rate=clutter_rate,
        detection_rate=detection_rate,
        dt=dt,
        n_steps=100,
    )


def padded_observation(points, t):
    """An observation dict as the env returns it: real rows first, zeros in padding."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    measurements = np.zeros((K_ROWS, 2))
    measurements[: len(points)] = points
    mask = (np.arange(K_ROWS) < len(points)).astype(np.int8)
    return {
        "measurements": measurements,
        "sensor": np.where(mask == 1, 0, -1).astype(np.int64),
        "mask": mask,
        "t": t,
    }


def cv_matrices(dt, q):
    """F and Q of the nearly-constant-velocity model for [x, vx, y, vy], written out."""
    axis_f = np.array([[1.0, dt], [0.0, 1.0]])
    axis_q = q * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    return np.kron(np.eye(2), axis_f), np.kron(np.eye(2), axis_q)


def gain_update(x, p, z, noise_std):
    """Kalman update with one 2-D point in gain form, explicit inverse of S = H P H^T + R."""
    s = H @ p @ H.T + noise_std**2 * np.eye(2)
    gain = p @ H.T @ np.linalg.inv(s)
    return x + gain @ (z - H @ x), (np.eye(4) - gain @ H) @ p


def information_update(x, p, points, noise_std):
    """Kalman update with all of ``points`` (n, 2) at once in information form:
    P+ = (P^-1 + H_S^T R_S^-1 H_S)^-1, x+ = P+ (P^-1 x + H_S^T R_S^-1 z_S), H_S stacking H n
    times and R_S = sigma^2 I_2n. (The gain form with the 2n x 2n innovation covariance of a
    flat prior loses a few 1e-8 relative to cancellation; this form does not.)"""
    n = len(points)
    h_s = np.vstack([H] * n)
    prior_information = np.linalg.inv(p)
    p = np.linalg.inv(prior_information + h_s.T @ h_s / noise_std**2)
    x = p @ (prior_information @ x + h_s.T @ np.ravel(points) / noise_std**2)
    return x, 0.5 * (p + p.T)


def reference_kalman_filter(scans, dt, noise_std, q, position_std, velocity_std):
    """The filter the PDA tracker must reduce to without clutter: started at the centroid of
    the first scan with zero velocity and the flat prior (``IMMPDAFilter._start``), no
    prediction before the first update; afterwards predict every step and update with the
    step's points (none: predict only). Returns the (x, P) after every step."""
    f, noise = cv_matrices(dt, q)
    first = np.asarray(scans[0], dtype=float).reshape(-1, 2)
    centre = first.mean(axis=0)
    x = np.array([centre[0], 0.0, centre[1], 0.0])
    p = np.diag([position_std, velocity_std, position_std, velocity_std]) ** 2.0
    states = []
    for index, points in enumerate(scans):
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        if index:
            x, p = f @ x, f @ p @ f.T + noise
        if len(points):
            x, p = information_update(x, p, points, noise_std)
        states.append((x.copy(), p.copy()))
    return states


def turning_path(n_steps, dt, start=(300.0, 400.0), speed=12.0, heading=0.4, rate=0.05):
    """Positions of a target turning slowly at constant speed (a manoeuvre the NCV model
    follows only through its process noise)."""
    headings = heading + rate * dt * np.arange(n_steps)
    steps = speed * dt * np.column_stack([np.cos(headings), np.sin(headings)])
    return np.asarray(start) + np.vstack([np.zeros(2), np.cumsum(steps[:-1], axis=0)])


# -- 1. without clutter the PDA filter is the Kalman filter ------------------------------


def test_the_hand_written_model_is_constant_velocity_model():
    f, noise = cv_matrices(0.5, 3.0)
    got_f, got_noise = constant_velocity_model(0.5, 3.0)
    np.testing.assert_array_equal(got_f, f)
    np.testing.assert_allclose(got_noise, noise, rtol=1e-15)
    np.testing.assert_array_equal(turn_transition(0.0, 0.5), f)  # the IMM's NCV transition
    np.testing.assert_array_equal(POSITION_MATRIX, H)


@pytest.mark.parametrize("association", ["multi", "single"])
def test_pda_without_clutter_one_measurement_per_step_is_the_kalman_filter(association):
    dt, noise_std, q, position_std, velocity_std = 0.5, 2.0, 3.0, 50.0, 8.0
    rng = np.random.default_rng(11)
    truth = turning_path(40, dt)
    points = truth + rng.normal(0.0, noise_std, truth.shape)
    tracker = PDAFilter(
        noise_diff_coeff=q,
        association=association,
        detection_probability=1.0,
        gate_probability=1.0,
        initial_position_std=position_std,
        initial_velocity_std=velocity_std,
    )
    tracker.reset(make_spec(clutter_rate=0.0, noise_std=noise_std, dt=dt))
    expected = reference_kalman_filter(points, dt, noise_std, q, position_std, velocity_std)
    for t, (z, (x, p)) in enumerate(zip(points, expected)):
        estimate = tracker.update(padded_observation(z, t))
        np.testing.assert_allclose(estimate.mean, x[[0, 2]], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(estimate.var, np.diag(p)[[0, 2]], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(tracker.means_[0], x, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(tracker.covs_[0], p, rtol=1e-9, atol=1e-9)
    assert tracker.restarts_ == 0


def test_multi_association_without_clutter_uses_every_measurement_of_a_step():
    """1 to 3 target measurements per step and a few empty steps: the tracker equals the
    Kalman filter updating with all of them stacked (not only with their mean)."""
    dt, noise_std, q, position_std, velocity_std = 1.0, 1.5, 0.7, 200.0, 15.0
    rng = np.random.default_rng(12)
    truth = turning_path(30, dt, speed=15.0, rate=-0.03)
    counts = rng.integers(1, 4, len(truth))
    counts[[7, 8, 19]] = 0
    scans = [rng.normal(p, noise_std, (n, 2)) for p, n in zip(truth, counts)]
    tracker = PDAFilter(
        noise_diff_coeff=q, initial_position_std=position_std, initial_velocity_std=velocity_std
    )
    tracker.reset(make_spec(clutter_rate=0.0, noise_std=noise_std, dt=dt))
    expected = reference_kalman_filter(scans, dt, noise_std, q, position_std, velocity_std)
    for t, (points, (x, p)) in enumerate(zip(scans, expected)):
        estimate = tracker.update(padded_observation(points, t))
        np.testing.assert_allclose(estimate.mean, x[[0, 2]], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(tracker.covs_[0], p, rtol=1e-9, atol=1e-9)


def random_prior(rng):
    mean = np.array([100.0, 4.0, 200.0, -2.0])
    factor = rng.normal(size=(4, 4))
    return mean, 3.0 * factor @ factor.T + 0.5 * np.eye(4)


def test_multi_detection_update_without_clutter_is_one_update_with_the_mean():
    """m target measurements, no clutter: one Kalman update with their mean and R / m equals
    m sequential updates, one per measurement, and the information form
    P+^-1 = P^-1 + m H^T R^-1 H, x+ = P+ (P^-1 x + H^T R^-1 sum_i z_i)."""
    rng = np.random.default_rng(21)
    noise_std = 1.5
    r = noise_std**2 * np.eye(2)
    for m in (1, 2, 3, 5):
        mean, cov = random_prior(rng)
        points = rng.normal([101.0, 199.0], noise_std, (m, 2))
        got_mean, got_cov, got_log = multi_detection_update(
            mean, cov, points, POSITION_MATRIX, noise_std, 1.0, 0.0
        )
        centroid = points.mean(axis=0)
        s = H @ cov @ H.T + r / m
        gain = cov @ H.T @ np.linalg.inv(s)
        one_mean, one_cov = mean + gain @ (centroid - H @ mean), cov - gain @ H @ cov
        sequential_mean, sequential_cov = mean, cov
        for z in points:
            sequential_mean, sequential_cov = gain_update(
                sequential_mean, sequential_cov, z, noise_std
            )
        information = np.linalg.inv(cov) + m * H.T @ np.linalg.inv(r) @ H
        info_cov = np.linalg.inv(information)
        info_mean = info_cov @ (
            np.linalg.inv(cov) @ mean + H.T @ np.linalg.inv(r) @ points.sum(axis=0)
        )
        for reference_mean, reference_cov in (
            (one_mean, one_cov),
            (sequential_mean, sequential_cov),
            (info_mean, info_cov),
        ):
            np.testing.assert_allclose(got_mean, reference_mean, rtol=1e-10, atol=1e-9)
            np.testing.assert_allclose(got_cov, reference_cov, rtol=1e-9, atol=1e-9)
        assert got_log == pytest.approx(multivariate_normal(H @ mean, s).logpdf(centroid), 1e-10)
        # batched over two modes: each equals its own update
        means, covs = np.stack([mean, mean + 1.0]), np.stack([cov, 2.0 * cov])
        batched = multi_detection_update(means, covs, points, POSITION_MATRIX, noise_std, 1.0, 0.0)
        alone = multi_detection_update(
            means[1], covs[1], points, POSITION_MATRIX, noise_std, 1.0, 0.0
        )
        np.testing.assert_allclose(batched[0][1], alone[0], rtol=1e-12)
        np.testing.assert_allclose(batched[1][1], alone[1], rtol=1e-12)


def test_vanishing_clutter_density_joins_the_no_clutter_branch():
    """The anchored mixture with clutter density c -> 0 tends to the no-clutter update: every
    beta_ji = rho / (1 + rho) -> 1 with rho ~ lambda_T N / c, so the difference is O(c):
    at c = 1e-10 measured 1.8e-10 m in the mean and 5.6e-10 in the covariance; tolerances
    about 10 times that."""
    rng = np.random.default_rng(22)
    mean, cov = random_prior(rng)
    points = rng.normal(H @ mean, 1.0, (4, 2))
    no_clutter = multi_detection_update(mean, cov, points, POSITION_MATRIX, 1.0, 1.0, 0.0)
    tiny = multi_detection_update(mean, cov, points, POSITION_MATRIX, 1.0, 1.0, 1e-10)
    np.testing.assert_allclose(tiny[0], no_clutter[0], rtol=0, atol=2e-9)
    np.testing.assert_allclose(tiny[1], no_clutter[1], rtol=0, atol=5e-9)


# -- 2. the multi-detection association against the exact posterior ---------------------

NOISE_STD = 1.0
DETECTION_RATE = 1.0
CLUTTER_DENSITY = 1.0 / (np.pi * 50.0**2)  # lambda_c = 1 in a 50 m disc
PRIOR_MEAN = np.array([100.0, 5.0, 200.0, -3.0])
PRIOR_COV = np.array(
    [[9.0, 3.0, 2.0, 0.5], [3.0, 4.0, 0.5, 0.0], [2.0, 0.5, 9.0, 3.0], [0.5, 0.0, 3.0, 4.0]]
)


def exact_scan_posterior(mean, cov, points, noise_std, detection_rate, clutter_density):
    """Moment-matched posterior of N(x; mean, cov) prod_i (c + lambda_T N(z_i; H x, R)),
    expanded over every non-empty subset S of the points (S: the target's measurements):
    weight c^(m - |S|) lambda_T^|S| N(z_S; H_S mean, H_S P H_S^T + R_S), component the Kalman
    update with z_S. Also returns log sum_S weight_S / c^m, the scan's likelihood relative
    to the all-clutter hypothesis."""
    m = len(points)
    log_weights, means, covs = [], [], []
    for size in range(1, m + 1):
        for subset in itertools.combinations(range(m), size):
            h_s = np.vstack([H] * size)
            s = h_s @ cov @ h_s.T + noise_std**2 * np.eye(2 * size)
            z_s = points[list(subset)].ravel()
            gain = cov @ h_s.T @ np.linalg.inv(s)
            means.append(mean + gain @ (z_s - h_s @ mean))
            covs.append(cov - gain @ h_s @ cov)
            log_weights.append(
                (m - size) * np.log(clutter_density)
                + size * np.log(detection_rate)
                + multivariate_normal(h_s @ mean, s).logpdf(z_s)
            )
    log_weights = np.array(log_weights)
    posterior_mean, posterior_cov = mixture_moments(log_weights, means, covs)
    log_ratio = np.logaddexp.reduce(log_weights) - m * np.log(clutter_density)
    return posterior_mean, posterior_cov, log_ratio


def association_errors(points):
    """(multi mean error, multi covariance error, pda mean error) against the exact
    posterior: position-mean errors in units of sigma_z (max over axes), the covariance
    error as max_kl |P_kl - P*_kl| / sqrt(P*_kk P*_ll)."""
    exact_mean, exact_cov, _ = exact_scan_posterior(
        PRIOR_MEAN, PRIOR_COV, points, NOISE_STD, DETECTION_RATE, CLUTTER_DENSITY
    )
    multi_mean, multi_cov, _ = multi_detection_update(
        PRIOR_MEAN,
        PRIOR_COV,
        points,
        POSITION_MATRIX,
        NOISE_STD,
        DETECTION_RATE,
        CLUTTER_DENSITY,
    )
    pda_mean, _, _ = pda_update(
        PRIOR_MEAN,
        PRIOR_COV,
        points,
        POSITION_MATRIX,
        NOISE_STD**2 * np.eye(2),
        0.99,
        CLUTTER_DENSITY,
    )
    std = np.sqrt(np.diag(exact_cov))
    multi_error = np.max(np.abs(multi_mean - exact_mean)[[0, 2]]) / NOISE_STD
    cov_error = np.max(np.abs(multi_cov - exact_cov) / np.outer(std, std))
    pda_error = np.max(np.abs(pda_mean - exact_mean)[[0, 2]]) / NOISE_STD
    return multi_error, cov_error, pda_error


def test_multi_detection_update_against_the_exact_subset_expansion():
    """A hand-built scan: two target measurements 1.3 m apart near the prediction and two
    clutter points 7-8 m from the prediction and 7-9 m from the target's, plausible alone
    (their exact single-measurement weights are 5-12 % of a target measurement's) but
    isolated. The exact posterior puts 0.995 on the
    pair {0, 2}.

    The anchored mixture is an approximation (beta-weighted refinement instead of a mixture
    over the other measurements; a subset of size k counted once per anchor). Measured:
    mean error 0.0010 sigma_z, covariance error 1.7 %; tolerances 0.005 sigma_z and 5 %.
    Dropping the support term prod (1 + rho) gives 0.38 sigma_z and 410 %, dropping the
    refinement (beta = 0) 0.096 sigma_z and 130 %: both far outside. The textbook PDA (at
    most one target measurement) is off by 0.55 sigma_z and 510 % (its covariance keeps
    the spread between the two single-measurement updates); the test requires 0.25 sigma_z
    and a mean error 100 times the multi-detection update's (measured 570)."""
    points = np.array([[101.2, 199.1], [94.0, 204.0], [102.3, 198.4], [97.0, 193.0]])
    multi_error, cov_error, pda_error = association_errors(points)
    assert multi_error < 0.005, multi_error
    assert cov_error < 0.05, cov_error
    assert pda_error > 0.25 and pda_error > 100 * multi_error, (pda_error, multi_error)


def test_multi_detection_update_on_random_well_separated_scans():
    """200 scans (fixed seed): two target measurements N(p, sigma_z^2 I) around a point
    1.9 m from the prediction, two clutter points 6-20 m from the prediction and at least
    8 sigma_z from either target measurement, in random order.

    The anchored approximation is good when the two target measurements agree: with them
    within 2.5 sigma_z of each other (160 of the 200 scans; chance 79 %) the worst mean
    error measured is 0.0050 sigma_z and the worst covariance error 7.1 % (tolerances 0.01
    and 10 %), and the PDA's mean error at least 106 times larger (required: 50). Farther
    apart the exact posterior keeps 5-10 % on each single-measurement subset, a spread the
    beta-weighted anchors under-represent: over the other 40 scans up to 0.077 sigma_z and
    48 % (covariance errors above 20 % only with the pair 3.4-4.1 sigma_z apart); there the
    requirement is a mean error below 0.1 sigma_z and 5 times below the PDA's (measured 8.3),
    and the covariance is not checked."""
    rng = np.random.default_rng(2024)
    target_point = np.array([101.5, 198.8])
    prediction = PRIOR_MEAN[[0, 2]]
    consistent = 0
    for _ in range(200):
        while True:
            target = rng.normal(target_point, NOISE_STD, (2, 2))
            angle, radius = rng.uniform(0, 2 * np.pi, 2), rng.uniform(6.0, 20.0, 2)
            clutter = prediction + radius[:, None] * np.column_stack([np.cos(angle), np.sin(angle)])
            separation = np.linalg.norm(clutter[:, None] - target[None], axis=-1)
            if separation.min() >= 8.0 * NOISE_STD:
                break
        points = rng.permutation(np.vstack([target, clutter]))
        multi_error, cov_error, pda_error = association_errors(points)
        if np.linalg.norm(target[0] - target[1]) <= 2.5 * NOISE_STD:
            consistent += 1
            assert multi_error < 0.01 and cov_error < 0.1, (multi_error, cov_error)
            assert pda_error > 50 * multi_error, (pda_error, multi_error)
        else:
            assert multi_error < 0.1 and pda_error > 5 * multi_error, (multi_error, pda_error)
    assert consistent == 160


def test_multi_detection_log_likelihood_is_the_scan_likelihood_ratio():
    """The docstring: 'the log-likelihood of the scan relative to the all-clutter
    hypothesis', log sum_{S != {}} (lambda_T / c)^|S| N(z_S; H_S x, H_S P H_S^T + R_S), the
    exact expansion's. The plain sum over anchors meets a subset of k target measurements k
    times (it returned log(e_1 + e_2 + 2 w_12) for a target pair: +0.691 here, log 2 in the
    limit). Measured now: exact for one measurement, -0.0012 for the target pair alone,
    -0.0010 with the two clutter points; tolerance 0.005. (With three target measurements
    the product over the others given the anchor is itself approximate: -0.18 to +0.37 on
    three random scans, not checked.)"""
    points = np.array([[101.2, 199.1], [94.0, 204.0], [102.3, 198.4], [97.0, 193.0]])
    for rows, tolerance in (([0], 1e-12), ([0, 2], 0.005), ([0, 1, 2, 3], 0.005)):
        _, _, exact = exact_scan_posterior(
            PRIOR_MEAN, PRIOR_COV, points[rows], NOISE_STD, DETECTION_RATE, CLUTTER_DENSITY
        )
        _, _, got = multi_detection_update(
            PRIOR_MEAN,
            PRIOR_COV,
            points[rows],
            POSITION_MATRIX,
            NOISE_STD,
            DETECTION_RATE,
            CLUTTER_DENSITY,
        )
        assert got == pytest.approx(exact, abs=tolerance), rows


# -- 3. IMM ---------------------------------------------------------------------------------


def test_imm_mix_by_hand_two_modes():
    # mu = (0.6, 0.4), P = [[0.8, 0.2], [0.1, 0.9]]: c = (0.52, 0.48);
    # mu_{i|0} = (0.48, 0.04) / 0.52 = (12/13, 1/13), mu_{i|1} = (0.12, 0.36) / 0.48 = (1/4, 3/4)
    # means m_0 = (0, 0), m_1 = (13, 26); P_0 = [[2, 1], [1, 3]], P_1 = [[4, 0], [0, 1]]
    # mode 0: mean (1, 2); cov 12/13 [[3, 3], [3, 7]] + 1/13 [[148, 288], [288, 577]]
    # mode 1: mean (9.75, 19.5); cov 1/4 P_0 + 3/4 P_1 + 3/16 (13, 26)(13, 26)^T
    means = np.array([[0.0, 0.0], [13.0, 26.0]])
    covs = np.array([[[2.0, 1.0], [1.0, 3.0]], [[4.0, 0.0], [0.0, 1.0]]])
    probabilities = np.array([0.6, 0.4])
    transition = np.array([[0.8, 0.2], [0.1, 0.9]])
    mixed_mean, mixed_cov, predicted = imm_mix(means, covs, probabilities, transition)
    np.testing.assert_allclose(predicted, [0.52, 0.48], rtol=1e-14)
    np.testing.assert_allclose(mixed_mean, [[1.0, 2.0], [9.75, 19.5]], rtol=1e-14)
    np.testing.assert_allclose(
        mixed_cov[0], np.array([[184.0, 324.0], [324.0, 661.0]]) / 13.0, rtol=1e-13
    )
    np.testing.assert_allclose(mixed_cov[1], [[35.1875, 63.625], [63.625, 128.25]], rtol=1e-13)
    # a leading batch axis (lockstep episodes) mixes each element alone
    batched = imm_mix(
        np.stack([means, means[::-1]]),
        np.stack([covs, covs[::-1]]),
        np.stack([probabilities, probabilities[::-1]]),
        transition[::-1, ::-1],
    )
    np.testing.assert_allclose(batched[0][1], mixed_mean[::-1], rtol=1e-14)
    np.testing.assert_allclose(batched[1][1], mixed_cov[::-1], rtol=1e-13)
    np.testing.assert_allclose(batched[2][1], predicted[::-1], rtol=1e-14)


def runs_of(flags):
    """Boundaries of the maximal runs of equal values of a boolean sequence."""
    edges = np.flatnonzero(np.diff(flags.astype(int))) + 1
    return np.split(np.arange(flags.size), edges)


def test_imm_pda_mode_probabilities_on_an_s3_episode():
    """S3 (turns at +-30 deg/s), clutter 1, seed 1000, default imm-pda (CT modes at +-20 and
    +-30 deg/s): the mode probabilities are a distribution at every step, and the CT modes'
    total probability is higher on steps whose interval is a turn (the env's
    info["turn_rate"] != 0, the truth) than on straight steps.

    The steps are strongly autocorrelated (the probabilities follow the manoeuvre with a lag
    of a step or two), so the test treats each run of turning or straight steps as one unit:
    Welch's difference of the run means must exceed 5 standard errors (conftest.z_tolerance).
    Measured: 0.89 over 7 turn runs against 0.10 over 7 straight runs, 13.2 standard
    errors."""
    env = gym.make("DGPTrack-v0", scenario="S3", clutter_rate=1.0)
    tracker = IMMPDAFilter()
    turn_modes = tracker.turn_rates != 0.0
    obs, info = env.reset(seed=1000)
    tracker.reset(info["problem_spec"], seed=1000)
    turning, turn_probability = [], []
    while True:
        estimate = tracker.update(obs)
        probabilities = tracker.mode_probabilities_
        assert probabilities is not None  # step 0 has measurements
        assert np.all(probabilities >= 0.0)
        assert abs(probabilities.sum() - 1.0) < 1e-12
        turning.append(info["turn_rate"] != 0.0)
        turn_probability.append(probabilities[turn_modes].sum())
        obs, _, _, truncated, info = env.step(estimate.mean)
        if truncated:
            break
    turning, turn_probability = np.array(turning), np.array(turn_probability)
    assert turning.size == 150 and tracker.restarts_ == 0
    runs = runs_of(turning)
    turn_runs = np.array([turn_probability[r].mean() for r in runs if turning[r[0]]])
    straight_runs = np.array([turn_probability[r].mean() for r in runs if not turning[r[0]]])
    assert turn_runs.size >= 5 and straight_runs.size >= 5
    difference = turn_runs.mean() - straight_runs.mean()
    standard_error = np.sqrt(
        turn_runs.var(ddof=1) / turn_runs.size + straight_runs.var(ddof=1) / straight_runs.size
    )
    assert difference > z_tolerance(standard_error), (turn_runs, straight_runs)


# -- 4. coasting ----------------------------------------------------------------------------


def test_imm_pda_with_clutter_at_every_sensor_is_the_same_with_sparse_pairs(monkeypatch):
    """Clutter at every sensor gives scans of about 250 points, where the association
    finds the supporting pairs with a KD-tree: an S2 episode's estimates equal those with
    every pair formed, to far below a millimetre."""
    env = gym.make("DGPTrack-v0", scenario="S2", clutter_rate=1.0, clutter_sensors="all")
    observation, _ = env.reset(seed=1000)
    assert np.asarray(observation["mask"]).sum() > kalman.SPARSE_SUPPORT_MIN_POINTS
    sparse = run_episode(env, make_tracker("imm-pda"), 1000)
    monkeypatch.setattr(kalman, "SPARSE_SUPPORT_MIN_POINTS", 10**9)
    dense = run_episode(env, make_tracker("imm-pda"), 1000)
    np.testing.assert_allclose(sparse.mean, dense.mean, rtol=0, atol=1e-6)
    np.testing.assert_allclose(sparse.var, dense.var, rtol=1e-6)


def test_empty_steps_coast_along_the_motion_model():
    spec = make_spec(clutter_rate=1.0, noise_std=1.0, dt=1.0)
    tracker = PDAFilter(noise_diff_coeff=2.0)
    tracker.reset(spec)
    before = tracker.update(padded_observation([], 0))  # no track yet: the uninformed answer
    np.testing.assert_array_equal(before.mean, [500.0, 500.0])
    np.testing.assert_allclose(before.var, 1000.0**2 / 12.0)
    assert tracker.means_ is None
    for t in range(1, 7):
        tracker.update(padded_observation([[200.0 + 9.0 * t, 300.0 - 4.0 * t]], t))
    f, noise = cv_matrices(1.0, 2.0)
    mean, cov = tracker.means_[0].copy(), tracker.covs_[0].copy()
    previous = np.diag(cov)[[0, 2]]
    for t in range(7, 17):
        estimate = tracker.update(padded_observation([], t))
        mean, cov = f @ mean, f @ cov @ f.T + noise
        np.testing.assert_allclose(tracker.means_[0], mean, rtol=1e-13)
        np.testing.assert_allclose(tracker.covs_[0], cov, rtol=1e-12)
        np.testing.assert_array_equal(estimate.mean, tracker.means_[0][[0, 2]])
        assert np.all(estimate.var > previous), (estimate.var, previous)
        previous = estimate.var


def test_empty_steps_move_imm_mode_probabilities_along_the_markov_chain():
    spec = make_spec(clutter_rate=1.0, noise_std=1.0, dt=1.0)
    tracker = IMMPDAFilter()
    tracker.reset(spec)
    for t in range(6):
        tracker.update(padded_observation([[200.0 + 10.0 * t, 300.0 + 2.0 * t * t]], t))
    probabilities = tracker.mode_probabilities_.copy()
    for t in range(6, 12):
        tracker.update(padded_observation([], t))
        probabilities = probabilities @ tracker.mode_transition
        np.testing.assert_allclose(tracker.mode_probabilities_, probabilities, rtol=1e-12)


# -- 5. the clairvoyant floor ---------------------------------------------------------------

FLOOR_SEEDS = (1000, 1001)


@pytest.mark.parametrize("scenario", ["S1", "S2", "S3", "S4"])
def test_the_clairvoyant_floor_is_below_every_registered_tracker(scenario):
    """Paired on training seeds 1000-1001 (clutter 1, sigma_z 1, tuned windows), every
    registered tracker including centroid.

    RMSE over the episode (sqrt of the mean squared 2-D error): the clairvoyant's mean over
    the seeds must be below every other tracker's, with no slack. Not per seed: the RMSE of
    S1 and S4 is dominated by the few coverage-gap steps (S1 clairvoyant: 6.3 m over the
    episode, 0.7 m on detected steps), where the floor only coasts; on S4 seed 1001 the
    constant-velocity coasts of pda (6.6 m) and imm-pda (7.1 m) through a gap beat the
    clairvoyant's Singer extrapolation (7.5 m). Measured smallest ratio of the mean RMSEs:
    1.26 (imm-pda, S4); S1 1.44 (dgpt-poe-stgp), S2 14, S3 20 (imm-pda).

    On the steps where some sensor senses the target, the floor holds per seed: the
    clairvoyant's RMSE is below every other tracker's. There the estimate is dominated by the
    measurements and good trackers come near the floor: measured smallest ratios in 0.11.0
    1.06 on S4 (the state-space trackers with the silence; without it 1.14), 1.36 on S1
    (with the silence), 2.95 on S3 and 9.42 on S2 (imm-pda); up to 0.10.0 every ratio was
    above 1.5, which the test then asked for.

    The floor does not use the silence of the sensors in coverage gaps (the target is in no
    awake sensor's disc), nor which sensors report (the target is in each of their discs
    and in no other awake one's), so a tracker that does (``silence_particles``: every
    registered ``dgpt-*``, ``gp`` and ``hybrid``, which use it in gaps and at their ends;
    ``reporting_region``: the exact hybrids, on every step) is held to the detected-step
    floor on the mean over the seeds only: over the episode it beats the floor on S4 (5.99
    against 6.51 m on these seeds; ``hybrid`` 6.09), and ``hybrid`` with the region but
    without the silence beats it on S4 seed 1001's detected steps (0.747 against 0.770 m in
    0.23.0). The same tracker without either is held to both, per seed."""

    def run(tracker_id, **options):
        envs = [gym.make("DGPTrack-v0", scenario=scenario, clutter_rate=1.0) for _ in FLOOR_SEEDS]
        kwargs = {**tuned_kwargs(tracker_id, scenario), **options}
        trackers = [make_tracker(tracker_id, **kwargs) for _ in FLOOR_SEEDS]
        results = run_episodes(envs, trackers, list(FLOOR_SEEDS))
        episode = np.array([metrics.rmse_2d(r.mean, r.truth) for r in results])
        detected = np.array(
            [
                metrics.rmse_2d(r.mean[r.n_detecting > 0], r.truth[r.n_detecting > 0])
                for r in results
            ]
        )
        return episode, detected

    floor_episode, floor_detected = run("clairvoyant")
    others = [t for t in tracker_ids() if t != "clairvoyant"]
    assert "centroid" in others and "pda" in others and "imm-pda" in others
    for tracker_id in others:
        episode, detected = run(tracker_id)
        tracker = make_tracker(tracker_id)
        if getattr(tracker, "silence_particles", 0) or getattr(tracker, "reporting_region", 0):
            assert floor_detected.mean() < detected.mean(), (tracker_id, floor_detected, detected)
            blind = {"silence_particles": 0} if getattr(tracker, "silence_particles", 0) else {}
            if getattr(tracker, "reporting_region", False):
                blind["reporting_region"] = False
            episode, detected = run(tracker_id, **blind)
        assert np.all(floor_detected < detected), (tracker_id, floor_detected, detected)
        assert floor_episode.mean() < episode.mean(), (tracker_id, floor_episode, episode)


# -- 6. only oracles see the truth --------------------------------------------------------


class TruthRefusingTracker(GatedCentroidTracker):
    """The reference tracker, recording every call: any argument beyond (spec, seed) for
    reset or obs for update (such as ``truth``) is recorded and fails the call."""

    def __init__(self):
        super().__init__()
        self.extras = []
        self.resets = 0
        self.updates = 0

    def reset(self, spec, seed=None, *args, **kwargs):
        self.resets += 1
        if args or kwargs:
            self.extras.append(("reset", args, sorted(kwargs)))
            raise AssertionError(f"reset received {args} {sorted(kwargs)}")
        super().reset(spec, seed)

    def update(self, obs, *args, **kwargs):
        self.updates += 1
        if args or kwargs:
            self.extras.append(("update", args, sorted(kwargs)))
            raise AssertionError(f"update received {args} {sorted(kwargs)}")
        return super().update(obs)


class RecordingClairvoyant(ClairvoyantFilter):
    """The clairvoyant filter, keeping the truth it is handed with each observation."""

    def reset(self, spec, seed=None, truth=None):
        self.reset_truth = truth
        self.seen = []
        super().reset(spec, seed=seed, truth=truth)

    def update(self, obs, truth=None):
        self.seen.append((dict(obs), truth))
        return super().update(obs, truth=truth)


def s2_env(clutter_rate=1.0):
    return gym.make("DGPTrack-v0", scenario="S2", clutter_rate=clutter_rate)


def test_non_oracle_trackers_never_receive_the_truth():
    n_steps = 150
    single = TruthRefusingTracker()
    run_episode(s2_env(), single, seed=0)
    batched = [TruthRefusingTracker() for _ in range(3)]  # lockstep through update_batch
    run_episodes([s2_env() for _ in batched], batched, [0, 1, 2])
    # mixed lockstep: an oracle between two non-oracles (one update each, truth to the oracle)
    mixed = [TruthRefusingTracker(), RecordingClairvoyant(), TruthRefusingTracker()]
    run_episodes([s2_env() for _ in mixed], mixed, [3, 4, 5])
    refusing = [single, *batched, mixed[0], mixed[2]]
    for tracker in refusing:
        assert tracker.extras == [] and tracker.resets == 1 and tracker.updates == n_steps
    assert len(mixed[1].seen) == n_steps and all(truth is not None for _, truth in mixed[1].seen)
    monte_carlo = TruthRefusingTracker()
    run_monte_carlo(s2_env, lambda: monte_carlo, seeds=[6, 7], progress=False)
    assert monte_carlo.extras == [] and monte_carlo.resets == 2
    assert monte_carlo.updates == 2 * n_steps


def test_the_oracle_receives_the_truth_of_its_own_observation():
    env = s2_env(clutter_rate=5.0)
    tracker = RecordingClairvoyant()
    run_episode(env, tracker, seed=8)
    trajectory = env.unwrapped.trajectory_
    assert tracker.reset_truth["scenario"] is env.unwrapped.scenario
    assert len(tracker.seen) == 150
    target_rows = 0
    for t, (obs, truth) in enumerate(tracker.seen):
        assert obs["t"] == t
        origin, mask = np.asarray(truth["target_origin"]), obs["mask"]
        assert origin.dtype == bool and origin.shape == mask.shape
        assert not np.any(origin & (mask == 0))
        # the marked rows are the target's at this very step: within the chi-square(2)
        # 1e-9 quantile (6.4 sigma_z) of the true position at t (a neighbouring step's
        # position is 10-25 m away)
        offsets = obs["measurements"][origin] - trajectory.positions[t]
        assert np.all(np.linalg.norm(offsets, axis=1) < 6.5 * env.unwrapped.noise_std)
        target_rows += origin.sum()
        assert truth["turn_rate"] == trajectory.turn_rate[t] and truth["new_leg"] is None
    assert target_rows > 100


def test_the_clairvoyant_filter_refuses_to_run_without_the_truth():
    spec = make_spec()
    with pytest.raises(ValueError, match="oracle"):
        ClairvoyantFilter().reset(spec)
    with pytest.raises(TypeError, match="oracle"):
        ClairvoyantFilter().predict(padded_observation([[1.0, 2.0]], 0))
    env = s2_env()
    obs, info = env.reset(seed=0)
    tracker = ClairvoyantFilter()
    tracker.reset(info["problem_spec"], seed=0, truth=info)
    with pytest.raises(ValueError, match="oracle"):
        tracker.update(obs)


# -- 7. the env's truth info --------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_target_origin_marks_the_target_rows_of_the_returned_observation(seed):
    """At reset target_origin (of obs 0) marks exactly info["n_target"] rows (of step 0).
    After a step, n_target counts the step just scored while target_origin describes the
    returned observation: the sum of one step's target_origin is the n_target of the next
    step's info. Never on padding rows; nothing in the final, empty observation."""
    env = gym.make("DGPTrack-v0", scenario="S3", clutter_rate=5.0)
    obs, info = env.reset(seed=seed)
    assert info["target_origin"].sum() == info["n_target"]
    assert info["target_origin"].shape == obs["mask"].shape
    assert not np.any(info["target_origin"] & (obs["mask"] == 0))
    marked = info["target_origin"].sum()
    while True:
        obs, _, _, truncated, info = env.step(np.zeros(2))
        assert info["n_target"] == marked
        assert not np.any(info["target_origin"] & (obs["mask"] == 0))
        marked = info["target_origin"].sum()
        if truncated:
            break
    assert obs["mask"].sum() == 0 and marked == 0


def infos_of_an_episode(scenario, seed=0):
    env = gym.make("DGPTrack-v0", scenario=scenario, clutter_rate=1.0)
    _, info = env.reset(seed=seed)
    infos = [info]
    while True:
        _, _, _, truncated, info = env.step(np.zeros(2))
        if truncated:
            return env.unwrapped.trajectory_, infos, info
        infos.append(info)


def test_turn_rate_and_new_leg_describe_the_interval_ending_at_the_observation():
    omega = np.deg2rad(20.0)
    trajectory, infos, final = infos_of_an_episode("S2")
    rates = np.array([info["turn_rate"] for info in infos])
    assert all(info["new_leg"] is None for info in infos) and final["turn_rate"] is None
    assert np.all(np.isclose(rates, 0.0, atol=0) | np.isclose(np.abs(rates), omega, rtol=1e-12))
    assert np.any(rates > 0) and np.any(rates < 0) and rates[0] == 0.0
    # the heading change from step t - 1 to t of the true velocities is turn_rate[t] dt
    np.testing.assert_allclose(trajectory.turn_rates(), rates[1:], atol=1e-9)

    trajectory, infos, final = infos_of_an_episode("S1")
    new_leg = np.array([info["new_leg"] for info in infos])
    assert all(info["turn_rate"] is None for info in infos) and final["new_leg"] is None
    assert new_leg.dtype == bool and not new_leg[0]
    # 150 steps of 15-30 s legs: 4 to 9 waypoints; at each the heading jumps by 60-150 deg,
    # within a leg it drifts by the 0.2 m/s^2 noise on >= 10 m/s (measured at most 2.7
    # deg per step; smallest jump 64 deg)
    assert 4 <= new_leg.sum() <= 9
    jumps = np.abs(trajectory.turn_rates() * trajectory.dt) > np.deg2rad(30.0)
    np.testing.assert_array_equal(new_leg[1:], jumps)

    _, infos, _ = infos_of_an_episode("S4")
    assert all(info["turn_rate"] is None and info["new_leg"] is None for info in infos)


# -- 8. argument validation -----------------------------------------------------------------

TWO_MODES = {"turn_rates": (0.0, 0.3), "noise_diff_coeffs": (1.0, 1.0)}


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"association": "foo"}, "association"),
        ({"turn_rates": (0.0, 0.3), "noise_diff_coeffs": (1.0,)}, "turn_rates"),
        ({"turn_rates": [[0.0]], "noise_diff_coeffs": [[1.0]]}, "turn_rates"),
        ({"turn_rates": (0.0, np.nan), "noise_diff_coeffs": (1.0, 1.0)}, "turn_rates"),
        ({"turn_rates": (0.0,), "noise_diff_coeffs": (-1.0,)}, "noise_diff_coeffs"),
        ({"turn_rates": (0.0, 0.3), "noise_diff_coeffs": (1.0, np.nan)}, "noise_diff_coeffs"),
        ({"mode_stay_probability": 1.5}, "mode_stay_probability"),
        ({"mode_stay_probability": -0.1}, "mode_stay_probability"),
        ({**TWO_MODES, "mode_transition": [[0.5, 0.6], [0.5, 0.5]]}, "mode_transition"),
        ({**TWO_MODES, "mode_transition": [[1.2, -0.2], [0.5, 0.5]]}, "mode_transition"),
        ({**TWO_MODES, "mode_transition": [[1.0, 0.0]]}, "mode_transition"),
        ({**TWO_MODES, "mode_transition": np.eye(3)}, "mode_transition"),
        ({"detection_probability": 0.0}, "detection_probability"),
        ({"gate_probability": 1.5}, "gate_probability"),
        ({"initial_position_std": 0.0}, "initial_position_std"),
    ],
)
def test_bad_imm_pda_arguments_name_themselves(kwargs, name):
    with pytest.raises(ValueError, match=name):
        IMMPDAFilter(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"association": "foo"}, "association"),
        ({"noise_diff_coeff": -1.0}, "noise_diff_coeff"),
        ({"noise_diff_coeff": np.inf}, "noise_diff_coeff"),
        ({"detection_probability": 1.5}, "detection_probability"),
    ],
)
def test_bad_pda_arguments_name_themselves(kwargs, name):
    with pytest.raises(ValueError, match=name):
        PDAFilter(**kwargs)


def test_an_infinite_imm_noise_diff_coeff_is_rejected():
    with pytest.raises(ValueError, match="noise_diff_coeffs"):
        IMMPDAFilter(turn_rates=(0.0, 0.3), noise_diff_coeffs=(1.0, np.inf))


def test_an_imm_without_modes_is_rejected():
    with pytest.raises(ValueError, match="turn_rates"):
        IMMPDAFilter(turn_rates=(), noise_diff_coeffs=())
