"""baselines/kalman.py against Stone Soup's Kalman and PDA components (equal to 1e-9), and
the Stone Soup tracker wrapper of baselines/stonesoup.py."""

import datetime

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("stonesoup")

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

START = datetime.datetime(2026, 1, 1)
TOLERANCE = {"rtol": 1e-9, "atol": 1e-9}
SPREAD = 10.0
"""Standard deviation (m) of the PDA test's measurements around the predicted position."""


def random_prior(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    factor = rng.normal(size=(4, 4))
    return rng.normal(0.0, 50.0, 4), factor @ factor.T + 0.5 * np.eye(4)


def stonesoup_prior(mean, cov) -> GaussianState:
    return GaussianState(mean.reshape(-1, 1), cov, timestamp=START)


def components(q: float, noise_variance: float):
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)])
    measurement = LinearGaussian(4, [0, 2], noise_variance * np.eye(2))
    return KalmanPredictor(transition), KalmanUpdater(measurement), measurement


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    q=st.floats(0.01, 200.0),
    # whole milliseconds: Stone Soup's timestamps have microsecond resolution
    dt=st.integers(100, 5000).map(lambda milliseconds: milliseconds / 1000),
)
def test_kalman_predict_equals_stonesoup(seed, q, dt):
    mean, cov = random_prior(seed)
    predictor, _, _ = components(q, 1.0)
    expected = predictor.predict(
        stonesoup_prior(mean, cov), timestamp=START + datetime.timedelta(seconds=dt)
    )
    got_mean, got_cov = kalman_predict(mean, cov, *constant_velocity_model(dt, q))
    np.testing.assert_allclose(got_mean, expected.state_vector.ravel(), **TOLERANCE)
    np.testing.assert_allclose(got_cov, expected.covar, **TOLERANCE)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), noise_variance=st.floats(0.01, 20.0))
def test_kalman_update_equals_stonesoup(seed, noise_variance):
    mean, cov = random_prior(seed)
    _, updater, measurement_model = components(1.0, noise_variance)
    z = np.random.default_rng(seed + 1).normal(mean[[0, 2]], 5.0)
    prior = stonesoup_prior(mean, cov)
    detection = Detection(z.reshape(-1, 1), timestamp=START, measurement_model=measurement_model)
    prediction = updater.predict_measurement(prior)
    expected = updater.update(SingleHypothesis(prior, detection))
    got_mean, got_cov, predicted, innovation_cov = kalman_update(
        mean, cov, z, POSITION_MATRIX, noise_variance * np.eye(2)
    )
    np.testing.assert_allclose(got_mean, expected.state_vector.ravel(), **TOLERANCE)
    np.testing.assert_allclose(got_cov, expected.covar, **TOLERANCE)
    np.testing.assert_allclose(predicted, prediction.state_vector.ravel(), **TOLERANCE)
    np.testing.assert_allclose(innovation_cov, prediction.covar, **TOLERANCE)


def stonesoup_pda(mean, cov, measurements, q, noise_variance, prob_detect, prob_gate,
                  clutter_density, gm_method, dt=1.0):
    """Stone Soup's PDA step from (mean, cov) at START to START + dt; also returns the
    measurements in the order Stone Soup saw them and its unnormalised hypothesis weights."""
    predictor, updater, measurement_model = components(q, noise_variance)
    when = START + datetime.timedelta(seconds=dt)
    detections = [
        Detection(z.reshape(-1, 1), timestamp=when, measurement_model=measurement_model)
        for z in measurements
    ]
    hypothesiser = PDAHypothesiser(
        predictor,
        updater,
        clutter_spatial_density=clutter_density,
        prob_detect=prob_detect,
        prob_gate=prob_gate,
        include_all=False,
    )
    track = Track([stonesoup_prior(mean, cov)])
    hypotheses = hypothesiser.hypothesise(track, set(detections), when)
    unnormalised = PDAHypothesiser(
        predictor,
        updater,
        clutter_spatial_density=clutter_density,
        prob_detect=prob_detect,
        prob_gate=prob_gate,
        normalise=False,
    ).hypothesise(track, set(detections), when)
    total = float(sum(float(h.probability) for h in unnormalised))
    update = PDAUpdater(measurement_model).update(hypotheses, gm_method=gm_method)
    return update, total


@pytest.mark.parametrize("gm_method", [False, True])
@pytest.mark.parametrize(
    ("n_measurements", "prob_detect", "prob_gate"),
    [(0, 0.9, 0.99), (1, 0.9, 0.99), (1, 1.0, 0.999), (5, 0.9, 0.99), (8, 0.7, 0.9),
     (12, 0.99, 0.95)],
)
def test_pda_update_equals_stonesoup(gm_method, n_measurements, prob_detect, prob_gate):
    rng = np.random.default_rng(n_measurements)
    mean, cov = random_prior(n_measurements + 100)
    q, noise_variance, clutter_density, dt = 2.0, 1.5, 1e-3, 1.0
    predicted_mean, predicted_cov = kalman_predict(mean, cov, *constant_velocity_model(dt, q))
    # measurements around the prediction, some outside the gate
    measurements = rng.normal(predicted_mean[[0, 2]], SPREAD, (n_measurements, 2))
    expected, total = stonesoup_pda(
        mean, cov, measurements, q, noise_variance, prob_detect, prob_gate, clutter_density,
        gm_method,
    )
    got_mean, got_cov, log_likelihood = pda_update(
        predicted_mean,
        predicted_cov,
        measurements,
        POSITION_MATRIX,
        noise_variance * np.eye(2),
        prob_detect,
        clutter_density,
        prob_gate,
    )
    np.testing.assert_allclose(got_mean, expected.state_vector.ravel(), **TOLERANCE)
    np.testing.assert_allclose(got_cov, expected.covar, **TOLERANCE)
    # the scan likelihood relative to all clutter: Stone Soup's unnormalised weights summed
    np.testing.assert_allclose(np.exp(log_likelihood), total, rtol=1e-9)


@pytest.mark.parametrize(("n_measurements", "prob_gate"), [(8, 0.9), (12, 0.95)])
def test_some_measurements_fall_outside_the_gate_in_the_comparison(n_measurements, prob_gate):
    """The comparison above exercises the gate: some of the points it draws around the
    prediction fall outside it and some inside (same draws as there)."""
    from scipy import stats

    rng = np.random.default_rng(n_measurements)
    mean, cov = random_prior(n_measurements + 100)
    predicted_mean, predicted_cov = kalman_predict(mean, cov, *constant_velocity_model(1.0, 2.0))
    measurements = rng.normal(predicted_mean[[0, 2]], SPREAD, (n_measurements, 2))
    innovation = predicted_cov[np.ix_([0, 2], [0, 2])] + 1.5 * np.eye(2)
    offset = measurements - predicted_mean[[0, 2]]
    distance = np.einsum("mi,ij,mj->m", offset, np.linalg.inv(innovation), offset)
    outside = distance > stats.chi2.ppf(prob_gate, 2)
    assert 0 < outside.sum() < n_measurements


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
    from dgpt_gym.evaluation import run_episode

    result = run_episode(
        gym.make("DGPTrack-v0", scenario="S1", clutter_rate=1.0), make_tracker("stonesoup-pda"), 0
    )
    values = result.metrics()
    assert all(np.isfinite(values[key]) for key in ("rmse_2d", "anees", "nrmse_x"))
    centre_rmse = np.sqrt(np.mean(np.sum((result.truth - 500.0) ** 2, axis=1)))
    assert values["rmse_2d"] < 0.2 * centre_rmse
