"""baselines/kalman.py against Stone Soup's Kalman and PDA components (equal to 1e-9), and the
Stone Soup tracker wrapper of baselines/stonesoup.py against a filter built from
baselines/kalman.py. Skipped where Stone Soup (the dev extra) is not installed."""

import datetime
import importlib
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("stonesoup")

from conftest import problem_spec  # noqa: E402
from scipy import stats  # noqa: E402
from stonesoup.hypothesiser.probability import PDAHypothesiser  # noqa: E402
from stonesoup.models.measurement.linear import LinearGaussian  # noqa: E402
from stonesoup.models.transition.linear import (  # noqa: E402
    CombinedLinearGaussianTransitionModel,
    ConstantVelocity,
)
from stonesoup.predictor.kalman import KalmanPredictor  # noqa: E402
from stonesoup.types.detection import Detection  # noqa: E402
from stonesoup.types.hypothesis import SingleHypothesis  # noqa: E402
from stonesoup.types.state import GaussianState  # noqa: E402
from stonesoup.types.track import Track  # noqa: E402
from stonesoup.updater.kalman import KalmanUpdater  # noqa: E402
from stonesoup.updater.probability import PDAUpdater  # noqa: E402

from baselines.kalman import (  # noqa: E402
    POSITION_MATRIX,
    constant_velocity_model,
    kalman_predict,
    kalman_update,
    pda_update,
)
from dgpt_gym.tracker import Estimate  # noqa: E402

START = datetime.datetime(2026, 1, 1)
TOLERANCE = {"rtol": 1e-9, "atol": 1e-9}


def spd(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    """A random symmetric positive-definite n x n matrix of magnitude about scale^2."""
    factor = scale * rng.normal(size=(n, n))
    return factor @ factor.T + 0.1 * scale**2 * np.eye(n)


def random_prior(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.normal(0.0, 50.0, 4), spd(rng, 4, rng.uniform(0.3, 10.0))


def gaussian(mean: np.ndarray, cov: np.ndarray, when=START) -> GaussianState:
    return GaussianState(mean.reshape(-1, 1), cov, timestamp=when)


def transition_model(q: float) -> CombinedLinearGaussianTransitionModel:
    return CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)])


def detections_at(measurements: np.ndarray, when, model) -> list[Detection]:
    return [
        Detection(z.reshape(-1, 1), timestamp=when, measurement_model=model) for z in measurements
    ]


# -- Kalman prediction and update --------------------------------------------------------------


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    q=st.floats(0.001, 200.0),
    # whole milliseconds: Stone Soup's timestamps have microsecond resolution
    dt=st.integers(1, 5000).map(lambda milliseconds: milliseconds / 1000),
)
def test_kalman_predict_equals_stonesoup_predictor(seed, q, dt):
    mean, cov = random_prior(seed)
    expected = KalmanPredictor(transition_model(q)).predict(
        gaussian(mean, cov), timestamp=START + datetime.timedelta(seconds=dt)
    )
    got_mean, got_cov = kalman_predict(mean, cov, *constant_velocity_model(dt, q))
    np.testing.assert_allclose(got_mean, expected.state_vector.ravel(), **TOLERANCE)
    np.testing.assert_allclose(got_cov, expected.covar, **TOLERANCE)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), noise_scale=st.floats(0.05, 5.0))
def test_kalman_update_equals_stonesoup_updater(seed, noise_scale):
    """Mean, covariance, predicted measurement and innovation covariance S, with a random
    (correlated) measurement covariance R."""
    mean, cov = random_prior(seed)
    rng = np.random.default_rng(seed + 1)
    noise = spd(rng, 2, noise_scale)
    model = LinearGaussian(4, [0, 2], noise)
    updater = KalmanUpdater(model)
    z = rng.normal(mean[[0, 2]], 5.0)
    prior = gaussian(mean, cov)
    (detection,) = detections_at(z[None], START, model)
    prediction = updater.predict_measurement(prior)
    expected = updater.update(SingleHypothesis(prior, detection))
    got_mean, got_cov, predicted, innovation_cov = kalman_update(
        mean, cov, z, POSITION_MATRIX, noise
    )
    np.testing.assert_allclose(got_mean, expected.state_vector.ravel(), **TOLERANCE)
    np.testing.assert_allclose(got_cov, expected.covar, **TOLERANCE)
    np.testing.assert_allclose(predicted, prediction.state_vector.ravel(), **TOLERANCE)
    np.testing.assert_allclose(innovation_cov, prediction.covar, **TOLERANCE)


# -- PDA ------------------------------------------------------------------------------------

Q, NOISE_VARIANCE, CLUTTER_DENSITY = 2.0, 1.5, 1e-3
RADII = (0.2, 4.0)
"""Mahalanobis distances (under S) of the PDA tests' measurements from the predicted
position, spread evenly over this range: the farthest fall outside every gate P_G <= 0.99
(chi-square(2) radius 3.03) and the nearest inside."""


def scan_around(predicted_mean, predicted_cov, m: int, seed: int) -> np.ndarray:
    """m measurements at the Mahalanobis distances RADII[0] .. RADII[1] from H x, in random
    directions."""
    innovation_cov = predicted_cov[np.ix_([0, 2], [0, 2])] + NOISE_VARIANCE * np.eye(2)
    angles = np.random.default_rng(seed).uniform(0.0, 2.0 * np.pi, m)
    unit = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    radii = np.linspace(*RADII, m)[:, None]
    return predicted_mean[[0, 2]] + (radii * unit) @ np.linalg.cholesky(innovation_cov).T


def stonesoup_pda(mean, cov, measurements, dt, prob_detect, prob_gate, include_all, gm_method):
    """Stone Soup's PDA step from (mean, cov) at START to START + dt. Returns the update,
    the number of measurement hypotheses and the sum of the unnormalised hypothesis weights
    (the scan likelihood relative to all clutter)."""
    model = LinearGaussian(4, [0, 2], NOISE_VARIANCE * np.eye(2))
    predictor = KalmanPredictor(transition_model(Q))
    when = START + datetime.timedelta(seconds=dt)
    # the hypothesiser takes a set, in its own order: the PDA does not depend on it
    detections = set(detections_at(measurements, when, model))
    track = Track([gaussian(mean, cov)])

    def hypothesiser(normalise):
        return PDAHypothesiser(
            predictor,
            KalmanUpdater(model),
            clutter_spatial_density=CLUTTER_DENSITY,
            prob_detect=prob_detect,
            prob_gate=prob_gate,
            include_all=include_all,
            normalise=normalise,
        )

    hypotheses = hypothesiser(True).hypothesise(track, detections, when)
    unnormalised = hypothesiser(False).hypothesise(track, detections, when)
    total = sum(float(hypothesis.probability) for hypothesis in unnormalised)
    update = PDAUpdater(model).update(hypotheses, gm_method=gm_method)
    return update, len(hypotheses) - 1, total


def direct_log_likelihood(predicted_mean, predicted_cov, measurements, prob_detect, prob_gate):
    """log(1 - P_D P_G + sum_{i in gate} P_D N(z_i; H x, S) / lambda) with scipy, and the
    number of measurements in the gate."""
    position = predicted_mean[[0, 2]]
    innovation_cov = predicted_cov[np.ix_([0, 2], [0, 2])] + NOISE_VARIANCE * np.eye(2)
    offset = measurements - position
    distance = np.einsum("mi,ij,mj->m", offset, np.linalg.inv(innovation_cov), offset)
    threshold = stats.chi2.ppf(prob_gate, 2) if prob_gate < 1.0 else np.inf
    inside = distance <= threshold
    pdf = np.atleast_1d(
        stats.multivariate_normal(position, innovation_cov).pdf(measurements[inside])
    )
    total = 1.0 - prob_detect * prob_gate + np.sum(prob_detect * pdf / CLUTTER_DENSITY)
    return np.log(total), int(inside.sum())


PDA_CASES = [
    # (measurements, P_D, P_G, include_all, dt)
    (0, 0.9, 0.99, False, 1.0),
    (0, 0.9, 1.0, True, 1.0),
    (1, 0.9, 0.99, False, 1.0),
    (1, 1.0, 0.999, False, 2.0),
    (5, 0.9, 0.99, False, 1.0),
    (8, 0.7, 0.9, False, 0.5),
    (12, 0.99, 0.95, False, 1.0),
    # include_all=True keeps the measurements outside the gate but the missed-detection
    # weight stays 1 - P_D P_G: the textbook PDA (ours) only at P_G = 1, where Stone Soup
    # accepts it (its chi-square gate is then infinite)
    (6, 0.8, 1.0, True, 1.0),
    (6, 0.8, 1.0, False, 3.0),
]


@pytest.mark.parametrize("gm_method", [False, True], ids=["innovation", "gm"])
@pytest.mark.parametrize(("m", "prob_detect", "prob_gate", "include_all", "dt"), PDA_CASES)
def test_pda_update_equals_stonesoup_pda(m, prob_detect, prob_gate, include_all, dt, gm_method):
    mean, cov = random_prior(100 + m)
    predicted_mean, predicted_cov = kalman_predict(mean, cov, *constant_velocity_model(dt, Q))
    measurements = scan_around(predicted_mean, predicted_cov, m, seed=m)
    expected, n_hypotheses, total = stonesoup_pda(
        mean, cov, measurements, dt, prob_detect, prob_gate, include_all, gm_method
    )
    got_mean, got_cov, log_likelihood = pda_update(
        predicted_mean,
        predicted_cov,
        measurements,
        POSITION_MATRIX,
        NOISE_VARIANCE * np.eye(2),
        prob_detect,
        CLUTTER_DENSITY,
        prob_gate,
    )
    np.testing.assert_allclose(got_mean, expected.state_vector.ravel(), **TOLERANCE)
    np.testing.assert_allclose(got_cov, expected.covar, **TOLERANCE)
    # the scan likelihood relative to all clutter: Stone Soup's unnormalised weights summed,
    # and scipy's densities directly
    np.testing.assert_allclose(np.exp(log_likelihood), total, rtol=1e-9)
    direct, n_inside = direct_log_likelihood(
        predicted_mean, predicted_cov, measurements, prob_detect, prob_gate
    )
    np.testing.assert_allclose(log_likelihood, direct, **TOLERANCE)
    assert n_hypotheses == n_inside
    if prob_gate < 1.0 and m > 1:  # the comparison exercises the gate
        assert 0 < n_inside < m
    if m == 0:  # Stone Soup returns only the missed detection: the posterior is the prediction
        np.testing.assert_allclose(got_mean, predicted_mean, **TOLERANCE)
        np.testing.assert_allclose(got_cov, predicted_cov, **TOLERANCE)
        np.testing.assert_allclose(log_likelihood, np.log(1.0 - prob_detect * prob_gate))


def test_batched_pda_update_equals_stonesoup_per_element():
    """pda_update over a batch of priors (the IMM modes) equals Stone Soup element by
    element."""
    priors = [random_prior(seed) for seed in (1, 2, 3)]
    model = constant_velocity_model(1.0, Q)
    predicted = [kalman_predict(mean, cov, *model) for mean, cov in priors]
    measurements = scan_around(*predicted[0], 7, seed=7)
    got_mean, got_cov, _ = pda_update(
        np.stack([mean for mean, _ in predicted]),
        np.stack([cov for _, cov in predicted]),
        measurements,
        POSITION_MATRIX,
        NOISE_VARIANCE * np.eye(2),
        0.9,
        CLUTTER_DENSITY,
        0.99,
    )
    for index, (mean, cov) in enumerate(priors):
        expected, _, _ = stonesoup_pda(mean, cov, measurements, 1.0, 0.9, 0.99, False, False)
        np.testing.assert_allclose(got_mean[index], expected.state_vector.ravel(), **TOLERANCE)
        np.testing.assert_allclose(got_cov[index], expected.covar, **TOLERANCE)


# -- the wrapper (baselines/stonesoup.py) -------------------------------------------------------

SPEC = problem_spec(
    [[100.0, 200.0], [150.0, 220.0], [400.0, 400.0]], noise_std=2.0, dt=2.0, n_steps=7
)
K = 6
SCANS = [
    [],
    [[100.0, 200.0], [102.0, 199.0], [140.0, 230.0]],
    [],
    [[112.0, 203.0], [400.0, 400.0]],  # the second one far outside the gate
    [[115.0, 204.0], [116.0, 206.0], [90.0, 210.0], [119.0, 199.0]],
    [[121.0, 206.0]],
    [],
]
"""A hand-built episode: nothing before the first scan, steps without measurements, clutter
inside and outside the gate."""


def observation(t: int, scan) -> dict:
    scan = np.asarray(scan, dtype=float).reshape(-1, 2)
    measurements = np.zeros((K, 2))
    measurements[: len(scan)] = scan
    mask = np.zeros(K, dtype=np.int8)
    mask[: len(scan)] = 1
    sensor = np.where(mask == 1, 0, -1)
    return {"measurements": measurements, "sensor": sensor, "mask": mask, "t": t}


def reference_pda_filter(start, q, prob_detect, prob_gate):
    """The wrapper's procedure with baselines/kalman.py: (mean, var, measurements in the
    gate) per step of SCANS."""
    density = SPEC.clutter_rate / SPEC.sensing_area
    noise = SPEC.noise_std**2 * np.eye(2)
    state, last, out = None, None, []
    for t, scan in enumerate(SCANS):
        z = np.asarray(scan, dtype=float).reshape(-1, 2)
        if state is None:
            if len(z) == 0:
                uninformed = Estimate.uninformed(SPEC)
                out.append((uninformed.mean, uninformed.var, 0))
                continue
            state = start(z)
        else:
            state = kalman_predict(*state, *constant_velocity_model((t - last) * SPEC.dt, q))
        last = t
        inside = 0
        if len(z):
            predicted_mean, predicted_cov = state
            offset = z - predicted_mean[[0, 2]]
            s = predicted_cov[np.ix_([0, 2], [0, 2])] + noise
            distance = np.einsum("mi,ij,mj->m", offset, np.linalg.inv(s), offset)
            inside = int(np.sum(distance <= stats.chi2.ppf(prob_gate, 2)))
            mean, cov, _ = pda_update(
                *state, z, POSITION_MATRIX, noise, prob_detect, density, prob_gate
            )
            state = mean, cov
        mean, cov = state
        out.append((mean[[0, 2]], np.diag(cov)[[0, 2]], inside))
    return out


def one_point_start(z):
    """The wrapper's default start (initial_velocity_std = 15)."""
    centroid = z.mean(axis=0)
    mean = np.array([centroid[0], 0.0, centroid[1], 0.0])
    return mean, np.diag([SPEC.sensing_range**2, 15.0**2] * 2)


def first_point_start(z):
    """A custom start: the first measurement, position std 10 m, velocity (3, -1) m/s with
    std 5 m/s."""
    return np.array([z[0, 0], 3.0, z[0, 1], -1.0]), np.diag([100.0, 25.0] * 2)


@pytest.mark.parametrize("gm_method", [False, True], ids=["innovation", "gm"])
@pytest.mark.parametrize("construction", ["factory", "components"])
def test_wrapper_equals_kalman_py_pda_filter_step_by_step(construction, gm_method):
    from baselines.stonesoup import EPOCH, StoneSoupTracker, stonesoup_pda_tracker

    if construction == "factory":
        q, prob_detect, prob_gate, start = 20.0, 0.99, 0.9999, one_point_start
        tracker = stonesoup_pda_tracker(noise_diff_coeff=q, gm_method=gm_method)
    else:  # ready-made components and a custom initial state
        q, prob_detect, prob_gate, start = 5.0, 0.8, 0.99, first_point_start
        model = LinearGaussian(4, [0, 2], SPEC.noise_std**2 * np.eye(2))
        predictor = KalmanPredictor(transition_model(q))
        hypothesiser = PDAHypothesiser(
            predictor,
            KalmanUpdater(model),
            clutter_spatial_density=SPEC.clutter_rate / SPEC.sensing_area,
            prob_detect=prob_detect,
            prob_gate=prob_gate,
        )

        def initial_state(z, spec, when):
            assert spec is SPEC
            return gaussian(*first_point_start(z), when=when)

        tracker = StoneSoupTracker.from_components(
            predictor, PDAUpdater(model), hypothesiser, initial_state=initial_state
        )
    tracker.reset(SPEC, seed=0)
    expected = reference_pda_filter(start, q, prob_detect, prob_gate)
    for t, (scan, (mean, var, _)) in enumerate(zip(SCANS, expected)):
        estimate = tracker.update(observation(t, scan))
        np.testing.assert_allclose(estimate.mean, mean, **TOLERANCE)
        np.testing.assert_allclose(estimate.var, var, **TOLERANCE)
    assert [inside for *_, inside in expected][3] == 1  # the gate excluded one measurement
    # step t is at EPOCH + t * dt
    last = EPOCH + datetime.timedelta(seconds=(len(SCANS) - 1) * SPEC.dt)
    assert tracker.track_.state.timestamp == last


def test_wrapper_follows_stable_baselines3_predict_contract():
    from baselines.stonesoup import stonesoup_pda_tracker

    tracker = stonesoup_pda_tracker()
    tracker.reset(SPEC)
    fresh = stonesoup_pda_tracker()
    fresh.reset(SPEC)
    for t, scan in enumerate(SCANS[:4]):
        actions, _ = tracker.predict(observation(t, scan))
        np.testing.assert_allclose(actions, fresh.update(observation(t, scan)).mean, **TOLERANCE)


def test_stonesoup_pda_tracker_tracks_an_s1_episode():
    """The wrapped Stone Soup KF-PDA on one S1 episode at clutter rate 1: finite metrics and
    an RMSE far below answering the area's centre."""
    import gymnasium as gym

    from baselines.stonesoup import stonesoup_pda_tracker
    from dgpt_gym.benchmark.episodes import run_episode

    env = gym.make("DGPTrack-v0", scenario="S1", clutter_rate=1.0)
    result = run_episode(env, stonesoup_pda_tracker(), seed=0)
    values = result.metrics()
    assert all(np.isfinite(values[key]) for key in ("rmse_2d", "anees", "nrmse_x"))
    centre_rmse = np.sqrt(np.mean(np.sum((result.truth - 500.0) ** 2, axis=1)))
    assert values["rmse_2d"] < 0.1 * centre_rmse


def test_wrapper_rejects_bad_arguments():
    from baselines.stonesoup import StoneSoupTracker, stonesoup_pda_tracker

    with pytest.raises(ValueError, match="build must be callable"):
        StoneSoupTracker(build=3)
    with pytest.raises(ValueError, match="initial_state"):
        StoneSoupTracker(initial_state="centroid")
    with pytest.raises(ValueError, match="initial_velocity_std"):
        StoneSoupTracker(initial_velocity_std=0.0)
    with pytest.raises(ValueError, match="prob_gate"):
        stonesoup_pda_tracker(prob_gate=1.5).reset(SPEC)
    with pytest.raises(RuntimeError, match="reset"):
        StoneSoupTracker().update(observation(0, []))


def test_missing_stonesoup_names_the_extra(monkeypatch):
    """Without Stone Soup the import fails with the pip command of the extra."""
    monkeypatch.delitem(sys.modules, "baselines.stonesoup", raising=False)
    monkeypatch.setitem(sys.modules, "stonesoup.hypothesiser.probability", None)
    with pytest.raises(ImportError, match=r"pip install 'dgpt-gym\[stonesoup\]'"):
        importlib.import_module("baselines.stonesoup")


def test_wrapped_stonesoup_pda_equals_our_textbook_pda_step_by_step():
    """The Stone Soup KF-PDA in the wrapper and PDAFilter(association="single") with the
    same model, prior and gate give the same estimates to 1e-9 over an S1 episode."""
    import gymnasium as gym

    from baselines.pda import PDAFilter
    from baselines.stonesoup import StoneSoupTracker, pda_components

    env = gym.make("DGPTrack-v0", scenario="S1", clutter_rate=1.0)
    observation, info = env.reset(seed=3)
    spec = info["problem_spec"]
    wrapped = StoneSoupTracker(pda_components, noise_diff_coeff=20.0, prob_gate=0.9999)
    ours = PDAFilter(
        noise_diff_coeff=20.0,
        association="single",
        detection_probability=0.99,
        gate_probability=0.9999,
        initial_position_std=spec.sensing_range,
    )
    wrapped.reset(spec)
    ours.reset(spec)
    for _ in range(60):
        a, b = wrapped.update(observation), ours.update(observation)
        np.testing.assert_allclose(a.mean, b.mean, **TOLERANCE)
        np.testing.assert_allclose(a.var, b.var, **TOLERANCE)
        observation, *_ = env.step(a.mean)
    assert ours.restarts_ == 0  # the wrapper has no restart: the comparison needs none


def test_wrapped_stonesoup_tracker_runs_an_episode():
    import gymnasium as gym

    from dgpt_gym import make_tracker
    from dgpt_gym.benchmark.episodes import run_episode

    result = run_episode(
        gym.make("DGPTrack-v0", scenario="S1", clutter_rate=1.0), make_tracker("stonesoup-pda"), 0
    )
    values = result.metrics()
    assert all(np.isfinite(values[key]) for key in ("rmse_2d", "anees", "nrmse_x"))
    centre_rmse = np.sqrt(np.mean(np.sum((result.truth - 500.0) ** 2, axis=1)))
    assert values["rmse_2d"] < 0.2 * centre_rmse
