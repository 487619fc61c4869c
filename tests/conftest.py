"""Shared fixtures and helpers."""

import inspect
import itertools

import gymnasium as gym
import numpy as np
import pytest

import dgpt_gym  # noqa: F401  (registers DGPTrack-v0 and the trackers)
from agents.poisson_update import LOG_MASS_BEYOND_QUADRATURE
from agents.silence import region_truncation
from dgpt_gym import make_tracker
from dgpt_gym.benchmark.episodes import run_episode
from dgpt_gym.problem import ProblemSpec


def problem_spec(sensor_positions=((0.0, 0.0),), **changes) -> ProblemSpec:
    """A hand-built ProblemSpec for tests: 50 m range, sigma_z 1 m, unit rates and period,
    a 1000 m area, clutter at detecting sensors, 10 steps, unless ``changes`` say otherwise."""
    fields = dict(
        sensing_range=50.0,
        noise_std=1.0,
        clutter_rate=1.0,
        detection_rate=1.0,
        dt=1.0,
        area=1000.0,
        clutter_sensors="detecting",
        n_steps=10,
    )
    return ProblemSpec(np.asarray(sensor_positions, dtype=float), **{**fields, **changes})


def measurement_obs(t, points, sensors, size=8) -> dict:
    """A tracker observation of step ``t``: ``points`` (k, 2) reported by ``sensors`` (k,),
    padded to ``size`` rows with the mask off."""
    measurements = np.zeros((size, 2))
    mask = np.zeros(size, dtype=np.int8)
    sensor = np.zeros(size, dtype=np.int64)
    measurements[: len(points)] = points
    mask[: len(points)] = 1
    sensor[: len(points)] = sensors
    return {"t": t, "measurements": measurements, "mask": mask, "sensor": sensor}


def mixture_moments(log_weights, means, covs):
    """Mean and covariance of a Gaussian mixture, component by component (a reference for
    the vectorized reductions): weights normalised from their logs, covariance
    sum_j w_j (P_j + (m_j - mean)(m_j - mean)^T)."""
    log_weights = np.asarray(log_weights, dtype=float)
    weights = np.exp(log_weights - log_weights.max())
    weights /= weights.sum()
    means = np.asarray(means)
    mean = weights @ means
    cov = sum(w * (c + np.outer(m - mean, m - mean)) for w, m, c in zip(weights, means, covs))
    return mean, cov


def z_tolerance(standard_error: float, z: float = 5.0) -> float:
    """A test tolerance of ``z`` standard errors (5: a false alarm below 1e-6 per check)."""
    return z * standard_error


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def sensed_steps(tracker: str, scenario: str, seeds, clutter_rate: float = 1.0):
    """``(errors, variances, ucbs)``, each (n, 2): a registered tracker's estimate errors,
    reported variances and UCB half-widths on the steps where a sensor senses the target,
    pooled over one episode per seed (sigma_z 1)."""
    errors, variances, ucbs = [], [], []
    for seed in seeds:
        env = gym.make("DGPTrack-v0", scenario=scenario, clutter_rate=clutter_rate)
        result = run_episode(env, make_tracker(tracker), seed)
        sensed = result.n_detecting > 0
        errors.append((result.mean - result.truth)[sensed])
        variances.append(result.var[sensed])
        ucbs.append(result.ucb[sensed])
    return np.concatenate(errors), np.concatenate(variances), np.concatenate(ucbs)


def sensed_calibration(tracker: str, scenario: str, seeds, clutter_rate: float = 1.0):
    """``(coverage (2,), NEES (n,), n)`` of a registered tracker over the steps where a
    sensor senses the target (:func:`sensed_steps`): the share of those steps whose error
    is within 3 standard deviations, per axis, and the 2-D NEES of every step (median
    nominal 1.39)."""
    errors, variances, _ = sensed_steps(tracker, scenario, seeds, clutter_rate)
    coverage = np.mean(np.abs(errors) <= 3.0 * np.sqrt(variances), axis=0)
    return coverage, np.sum(errors**2 / variances, axis=1), errors.shape[0]


def median_in_band(values, low: float, high: float, z: float = 3.0) -> bool:
    """Whether a sample's median is consistent with the band [``low``, ``high``] by the sign
    test: the share of values below ``low`` (and the share above ``high``) exceeds 1/2 by at
    most ``z`` binomial standard errors, z sqrt(1 / (4 n)). A median below the band by more
    than its sampling error puts clearly more than half the values below it."""
    values = np.asarray(values, dtype=float)
    limit = 0.5 + z * np.sqrt(0.25 / values.size)
    return bool(np.mean(values < low) <= limit and np.mean(values > high) <= limit)


@pytest.fixture
def short_ppo(tmp_path):
    """``short_ppo(env_id, env_kwargs, timesteps)``: a PPO agent trained on 2 sub-environments
    with seed 0 and small rollouts (256 steps, batches of 64), saved under ``tmp_path``."""
    # imported here so that Stable-Baselines3 and torch load only for the tests that train
    from agents.rl.training import train_agent

    def train(env_id: str, env_kwargs: dict, timesteps: int):
        return train_agent(
            env_id,
            "ppo",
            timesteps=timesteps,
            seed=0,
            n_envs=2,
            out=tmp_path,
            env_kwargs=env_kwargs,
            algo_kwargs={"n_steps": 256, "batch_size": 64},
            progress=False,
        )

    return train


def step_vec_envs_alike(venv, reference, steps: int, rng) -> int:
    """Step two Stable-Baselines3 ``VecEnv`` s with the same random actions for ``steps``
    steps, asserting equal observations, rewards, dones, the tracker's error (a float64 the
    float32 observations and rewards would round away), time-limit flags and terminal
    observations; returns the number of episode ends."""
    dones = 0
    for _ in range(steps):
        actions = rng.integers(0, reference.action_space.n, reference.num_envs)
        got, want = venv.step(actions), reference.step(actions)
        for a, b in zip(got[:3], want[:3]):
            np.testing.assert_array_equal(a, b)
        assert len(got[3]) == len(want[3])
        for info_a, info_b in zip(got[3], want[3]):
            assert info_a["error"] == info_b["error"]
            assert info_a["TimeLimit.truncated"] == info_b["TimeLimit.truncated"]
            assert ("terminal_observation" in info_a) == ("terminal_observation" in info_b)
            if "terminal_observation" in info_b:
                np.testing.assert_array_equal(
                    info_a["terminal_observation"], info_b["terminal_observation"]
                )
        dones += int(got[2].sum())
    return dones


def assert_fixes_every_argument(tracker, options: dict, own: set) -> None:
    """An RL environment's ``tracker`` is built with ``options``, which name every argument
    of its class but the environment's ``own``; a ``manoeuvre_*`` option is read from the
    tracker's ``manoeuvre``. A new argument of the class fails the first assertion, an
    option the environment does not pass the second."""
    arguments = set(inspect.signature(type(tracker).__init__).parameters) - {"self"}
    assert set(options) == arguments - own
    for name, value in options.items():
        if name.startswith("manoeuvre_"):
            assert getattr(tracker.manoeuvre, name.removeprefix("manoeuvre_")) == value, name
        else:
            assert getattr(tracker, name) == value, name


def brute_force_posterior(prior_mean, prior_var, points, model, sensors=None, region=None):
    """The exact posterior by enumeration: every subset S of target points (with sensors,
    only the subsets with a point of every sensor), weight c^(n - |S|) lambda_T^|S| times
    the prior predictive density of z_S, its component the Kalman update with z_S; with
    ``region`` each component then cut to it by :func:`agents.silence.region_truncation`, its
    weight times its mass there (the prior's bound on every component when none reaches it);
    returns (mean, var, log evidence)."""
    c = model.clutter_rate / model.sensing_area
    noise = model.noise_std**2
    log_weights, means, variances = [], [], []
    for assignment in itertools.product([False, True], repeat=points.shape[0]):
        chosen = np.array(assignment, dtype=bool)
        if sensors is not None and not set(sensors) <= set(sensors[chosen]):
            continue
        n_clutter = points.shape[0] - chosen.sum()
        if n_clutter and c == 0:
            continue
        log_weight = n_clutter * np.log(c) if n_clutter else 0.0
        mean, var = prior_mean.copy(), prior_var.copy()
        for z in points[chosen]:  # sequential Kalman updates: the predictive chain rule
            predictive = var + noise
            log_weight += np.log(model.detection_rate) - 0.5 * np.sum(
                (z - mean) ** 2 / predictive + np.log(2 * np.pi * predictive)
            )
            gain = var / predictive
            mean, var = mean + gain * (z - mean), (1 - gain) * var
        log_weights.append(log_weight)
        means.append(mean)
        variances.append(var)
    log_weights = np.array(log_weights)
    means, variances = np.array(means), np.array(variances)
    if region is not None:
        log_mass, means, variances = region_truncation(means, variances, *region)
        if not np.isfinite(log_mass).any():
            log_mass = np.full(log_mass.shape, LOG_MASS_BEYOND_QUADRATURE)
        log_weights = log_weights + log_mass
    weights = np.exp(log_weights - log_weights.max())
    total = weights.sum()
    weights /= total
    mean = weights @ means
    return mean, weights @ (variances + (means - mean) ** 2), log_weights.max() + np.log(total)
