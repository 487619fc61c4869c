"""The clairvoyant floor's motion models against the scenarios that draw the paths, and the
standard trackers with noise-free measurements (tests/test_pda_clairvoyant.py has the rest)."""

import gymnasium as gym
import numpy as np
import pytest

from baselines.clairvoyant import ClairvoyantFilter, redrawn_velocity_moments, singer_model
from dgpt_gym import make_tracker
from dgpt_gym.evaluation import run_episode


def test_redrawn_velocity_moments_match_monte_carlo():
    rng = np.random.default_rng(1)
    n = 200_000
    speed = rng.uniform(10.0, 25.0, n)
    turn = rng.uniform(np.deg2rad(60), np.deg2rad(150), n) * rng.choice([-1, 1], n)
    heading = 0.7 + turn
    samples = speed[:, None] * np.column_stack([np.cos(heading), np.sin(heading)])
    mean, cov = redrawn_velocity_moments(0.7, (10.0, 25.0), (60.0, 150.0))
    standard_error = np.sqrt(np.diag(np.cov(samples.T)) / n)
    assert np.all(np.abs(samples.mean(axis=0) - mean) < 5 * standard_error)
    np.testing.assert_allclose(np.cov(samples.T), cov, rtol=0.02, atol=0.5)


def test_singer_model_reproduces_the_scenario_recursion():
    """One step of F on [p, v, a] equals a = rho a, v = v + dt a, p = p + dt (v_old + v) / 2
    of dgpt_gym.scenarios.SingerScenario (without clipping), and Q is var(w) G G^T."""
    dt, tau, sigma = 1.0, 10.0, 25.0
    f, q = singer_model(dt, tau, sigma)
    rho = np.exp(-dt / tau)
    state = np.array([1.0, 2.0, 3.0, -1.0, 0.5, -2.0])
    moved = f @ state
    for offset in (0, 3):
        p, v, a = state[offset : offset + 3]
        a_new = rho * a
        v_new = v + dt * a_new
        np.testing.assert_allclose(
            moved[offset : offset + 3], [p + dt * (v + v_new) / 2, v_new, a_new]
        )
    gain = np.array([dt**2 / 2, dt, 1.0])
    np.testing.assert_allclose(q[:3, :3], sigma**2 * (1 - rho**2) * np.outer(gain, gain))


@pytest.mark.parametrize("tracker_id", ["pda", "imm-pda", "clairvoyant"])
def test_noise_free_measurements_give_finite_estimates(tracker_id):
    """noise_std = 0 is a valid env setting; the Kalman updates floor sigma_z instead of
    dividing by zero (pytest turns the RuntimeWarning of a 0/0 into an error)."""
    env = gym.make("DGPTrack-v0", scenario="S1", noise_std=0.0, clutter_rate=1.0)
    result = run_episode(env, make_tracker(tracker_id), seed=0)
    assert np.all(np.isfinite(result.mean)) and np.all(np.isfinite(result.var))
    # with exact measurements a sensed step whose target point is associated is exact: the
    # typical (median) sensed step is within a millimetre (a few re-acquisitions among
    # clutter are not, so the RMSE is not)
    sensed = result.n_detecting > 0
    errors = np.linalg.norm(result.mean[sensed] - result.truth[sensed], axis=1)
    assert np.median(errors) < 1e-3


def test_the_clairvoyant_singer_parameters_are_checked():
    with pytest.raises(ValueError, match="singer"):
        ClairvoyantFilter(singer="exact")
