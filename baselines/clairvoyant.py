"""The clairvoyant filter: the accuracy floor of the benchmark.

A causal Kalman filter that is *told* which measurements are target-originated (the
environment's ``info["target_origin"]``) and uses the scenario's true motion model with its
true parameters and switching times. No tracker that must find the target among clutter,
and learn or guess its motion, can expect to beat it; every tracker's RMSE is reported
divided by its (docs/results.md). It is an oracle (``oracle = True``): the evaluation loop
hands it the environment's ``info`` (:func:`dgpt_gym.benchmark.episodes.run_episodes`), which no
other tracker ever sees.

Motion models, derived from how :mod:`dgpt_gym.scenarios` draws the paths (positions are
the trapezoidal integral of the velocities, so x_k = x_{k-1} + dt (v_{k-1} + v_k) / 2):

- **S1** (NCV legs): within a leg v_k = v_{k-1} + w_k, w_k ~ N(0, (sigma_a dt)^2 I): the
  discrete white-noise-acceleration model, Q per axis sigma_a^2 [[dt^4/4, dt^3/2],
  [dt^3/2, dt^2]]. At a waypoint (``info["new_leg"]``) the velocity is redrawn: speed
  uniform in the speed range, heading turned by +-U(heading_change_deg); the filter replaces
  v by the Gaussian with that distribution's mean and covariance about the current heading.
- **S2, S3** (coordinated turns): the CT transition F(omega) with the true turn rate of the
  interval (``info["turn_rate"]``, 0 on straight legs); the paths are exact arcs at
  constant speed, so the process noise is only a numerical floor.
- **S4** (Singer): per axis the state [p, v, a] with a_k = rho a_{k-1} + w_k,
  v_k = v_{k-1} + dt a_k, p_k = p_{k-1} + dt v_{k-1} + dt^2/2 a_k, rho = exp(-dt / tau),
  var(w) = sigma_m^2 (1 - rho^2). The scenario clips the acceleration norm to A_max and the
  speed to its range, which no Gaussian model holds; the clipped process's realised
  accelerations have a per-axis standard deviation of about 5.8 m/s^2 and a lag-one
  correlation of about 0.4, against the nominal sigma_m = 25.8 m/s^2 and rho = 0.90. With
  ``singer="realised"`` (default) sigma_m and rho are those realised moments, measured on
  paths drawn from training seeds (:func:`realised_singer_parameters`): the best Singer
  model of the true process. ``singer="nominal"`` uses the scenario's parameters as printed;
  it extrapolates the noisy acceleration estimate through coverage gaps and is no floor
  (docs/analysis.md gives both).

The update uses all target measurements of the step: with n of them, one Kalman update
with their mean and R = sigma_z^2 / n I, which carries exactly their information. The first
step with target measurements starts the track at their mean (variance sigma_z^2 / n) with
the velocity prior of the scenario's initial speed distribution; before it the estimate is
the area's centre.

Posterior Cramer-Rao bound. For the linear-Gaussian models (S1 within legs, S2, S3, S4
without clipping) with known measurement origin, the Kalman filter is the exact posterior,
so its covariance given the realised measurement counts *is* the conditional PCRLB; the
reported variance is that bound (``Estimate.var``), and its square root over an episode
is the floor's own predicted RMSE. The unconditional PCRLB would average it over the random
counts and coverage gaps; the waypoint redraws of S1 and the clipping of S4 make those
models non-Gaussian, where a bound would need Monte Carlo over the truth and is not given.
"""

from __future__ import annotations

import functools

import numpy as np

from baselines.cpf import turn_transition
from baselines.kalman import kalman_predict, kalman_update
from dgpt_gym.problem import ProblemSpec
from dgpt_gym.scenarios import (
    CoordinatedTurnScenario,
    NearlyConstantVelocityScenario,
    Scenario,
    SingerScenario,
)
from dgpt_gym.tracker import Estimate, TrackerBase
from dgpt_gym.validation import check_choice

__all__ = [
    "ClairvoyantFilter",
    "redrawn_velocity_moments",
    "singer_model",
    "realised_singer_parameters",
    "SINGER_PARAMETERS",
]

SINGER_PARAMETERS = ("realised", "nominal")
REALISED_MOMENT_PATHS = range(1000, 1100)
"""Training seeds of the paths whose accelerations give the realised Singer moments."""


@functools.lru_cache(maxsize=8)
def realised_singer_parameters(scenario: SingerScenario) -> tuple[float, float]:
    """(time constant tau, s; acceleration standard deviation sigma_m, m/s^2) of the Singer
    model whose per-axis acceleration variance and lag-one autocorrelation equal those of
    paths drawn from ``scenario`` (seeds :data:`REALISED_MOMENT_PATHS`): rho = lag-one
    correlation, tau = -dt / log rho."""
    accelerations = np.stack(
        [
            scenario.sample(np.random.default_rng(seed)).accelerations()
            for seed in REALISED_MOMENT_PATHS
        ]
    )  # (paths, steps, 2)
    centred = accelerations - accelerations.mean(axis=(0, 1))
    variance = float(np.mean(centred**2))
    lag_one = float(np.mean(centred[:, 1:] * centred[:, :-1])) / variance
    rho = min(max(lag_one, 1e-3), 1.0 - 1e-6)
    return -scenario.dt / np.log(rho), float(np.sqrt(variance))


NUMERICAL_PROCESS_NOISE = 1e-8
"""Process noise (m^2/s^3 per axis) added to the exact CT model: keeps P positive definite."""


def speed_moments(speed_range: tuple[float, float]) -> tuple[float, float]:
    """E[s] and E[s^2] of a speed uniform in ``speed_range``."""
    low, high = speed_range
    return 0.5 * (low + high), (low * low + low * high + high * high) / 3.0


def redrawn_velocity_moments(heading: float, speed_range, heading_change_deg):
    """Mean (2,) and covariance (2, 2) of S1's velocity after a waypoint: speed s ~
    U(speed_range), heading ``heading`` + d with |d| ~ U(heading_change_deg), sign random.

    Along the old heading the component is s cos d, across it s sin d (zero mean by the
    random sign): E[cos d] = (sin b - sin a) / (b - a), E[cos^2 d] = 1/2 + (sin 2b -
    sin 2a) / (4 (b - a)).
    """
    a, b = np.deg2rad(heading_change_deg)
    mean_speed, mean_square_speed = speed_moments(speed_range)
    mean_cos = (np.sin(b) - np.sin(a)) / (b - a)
    mean_cos2 = 0.5 + (np.sin(2 * b) - np.sin(2 * a)) / (4 * (b - a))
    along_mean = mean_speed * mean_cos
    along_var = mean_square_speed * mean_cos2 - along_mean**2
    across_var = mean_square_speed * (1.0 - mean_cos2)
    rotation = np.array([[np.cos(heading), -np.sin(heading)], [np.sin(heading), np.cos(heading)]])
    mean = rotation @ np.array([along_mean, 0.0])
    cov = rotation @ np.diag([along_var, across_var]) @ rotation.T
    return mean, cov


def singer_model(dt: float, time_constant: float, acceleration_std: float):
    """(F, Q) of the discrete Singer model for the state [x, vx, ax, y, vy, ay] (module
    docstring, S4)."""
    rho = np.exp(-dt / time_constant)
    axis_f = np.array([[1.0, dt, 0.5 * dt**2 * rho], [0.0, 1.0, dt * rho], [0.0, 0.0, rho]])
    gain = np.array([0.5 * dt**2, dt, 1.0])
    axis_q = acceleration_std**2 * (1.0 - rho**2) * np.outer(gain, gain)
    zero = np.zeros((3, 3))
    return np.block([[axis_f, zero], [zero, axis_f]]), np.block([[axis_q, zero], [zero, axis_q]])


def white_acceleration_noise(dt: float, acceleration_std: float) -> np.ndarray:
    """Q of the discrete white-noise-acceleration model for [x, vx, y, vy] (S1)."""
    axis = acceleration_std**2 * np.array([[dt**4 / 4, dt**3 / 2], [dt**3 / 2, dt**2]])
    zero = np.zeros((2, 2))
    return np.block([[axis, zero], [zero, axis]])


class ClairvoyantFilter(TrackerBase):
    """The clairvoyant accuracy floor (module docstring). An oracle: it needs the truth in
    ``reset(spec, seed, truth=info)`` and ``update(obs, truth=info)``."""

    name = "clairvoyant"
    oracle = True

    def __init__(self, singer: str = "realised") -> None:
        self.singer = check_choice("singer", singer, SINGER_PARAMETERS)

    def reset(self, spec: ProblemSpec, seed: int | None = None, truth: dict | None = None):
        if truth is None or "scenario" not in truth:
            raise ValueError(
                "the clairvoyant filter is an oracle: reset it with truth=info, the env's reset "
                "info (dgpt_gym.benchmark.episodes.run_episode does)"
            )
        self.spec_ = spec
        scenario: Scenario = truth["scenario"]
        self.scenario_ = scenario
        dt = spec.dt
        if isinstance(scenario, SingerScenario):
            if self.singer == "realised":
                time_constant, acceleration_std = realised_singer_parameters(scenario)
            else:
                time_constant, acceleration_std = scenario.time_constant, scenario.acceleration_std
            self.acceleration_std_ = acceleration_std
            self.transition_, self.process_noise_ = singer_model(
                dt, time_constant, acceleration_std
            )
            self.position_index_ = np.array([0, 3])
            self.velocity_index_ = np.array([1, 4])
        else:
            self.position_index_ = np.array([0, 2])
            self.velocity_index_ = np.array([1, 3])
            if isinstance(scenario, NearlyConstantVelocityScenario):
                self.process_noise_ = white_acceleration_noise(dt, scenario.acceleration_noise_std)
            elif isinstance(scenario, CoordinatedTurnScenario):
                self.process_noise_ = white_acceleration_noise(dt, NUMERICAL_PROCESS_NOISE)
            else:
                raise ValueError(
                    f"no clairvoyant motion model for scenario type {type(scenario).__name__}"
                )
            self.transition_ = turn_transition(0.0, dt)
        n = self.transition_.shape[0]
        self.measurement_matrix_ = np.zeros((2, n))
        self.measurement_matrix_[[0, 1], self.position_index_] = 1.0
        self.mean_: np.ndarray | None = None
        self.cov_: np.ndarray | None = None

    def _start(self, measurements: np.ndarray) -> None:
        n = self.transition_.shape[0]
        self.mean_ = np.zeros(n)
        self.mean_[self.position_index_] = measurements.mean(axis=0)
        _, mean_square_speed = speed_moments(self.scenario_.speed_range)
        variances = np.zeros(n)
        variances[self.position_index_] = self.spec_.model_noise_std**2 / measurements.shape[0]
        variances[self.velocity_index_] = mean_square_speed / 2.0  # uniform heading
        if isinstance(self.scenario_, SingerScenario):
            variances[[2, 5]] = self.acceleration_std_**2
        self.cov_ = np.diag(variances)

    def _predict(self, truth: dict) -> None:
        scenario, dt = self.scenario_, self.spec_.dt
        if isinstance(scenario, CoordinatedTurnScenario):
            transition = turn_transition(truth.get("turn_rate") or 0.0, dt)
            self.mean_, self.cov_ = kalman_predict(
                self.mean_, self.cov_, transition, self.process_noise_
            )
        elif isinstance(scenario, NearlyConstantVelocityScenario) and truth.get("new_leg"):
            velocity = self.mean_[self.velocity_index_]
            heading = float(np.arctan2(velocity[1], velocity[0]))
            new_mean, new_cov = redrawn_velocity_moments(
                heading, scenario.speed_range, scenario.heading_change_deg
            )
            # x_k = x_{k-1} + dt (v_{k-1} + v_new) / 2, v_k = v_new: linear in (x, v_new)
            transition = np.eye(4)
            transition[[0, 2], [1, 3]] = 0.5 * dt
            transition[[1, 3], [1, 3]] = 0.0
            gain = np.zeros((4, 2))
            gain[[0, 2], [0, 1]] = 0.5 * dt
            gain[[1, 3], [0, 1]] = 1.0
            self.mean_ = transition @ self.mean_ + gain @ new_mean
            self.cov_ = transition @ self.cov_ @ transition.T + gain @ new_cov @ gain.T
        else:
            self.mean_, self.cov_ = kalman_predict(
                self.mean_, self.cov_, self.transition_, self.process_noise_
            )

    def update(self, obs: dict, truth: dict | None = None) -> Estimate:
        if self.spec_ is None:
            raise RuntimeError("call reset(spec, truth=info) before update(obs, truth=info)")
        if truth is None or "target_origin" not in truth:
            raise ValueError(
                "the clairvoyant filter is an oracle: pass truth=info, the env's info returned "
                "with obs (dgpt_gym.benchmark.episodes.run_episode does)"
            )
        rows = np.asarray(obs["mask"]).astype(bool) & np.asarray(truth["target_origin"])
        measurements = np.asarray(obs["measurements"], dtype=float)[rows]
        if self.mean_ is None:
            if measurements.shape[0] == 0:
                return Estimate.uninformed(self.spec_)
            self._start(measurements)
        else:
            self._predict(truth)
            if measurements.shape[0]:
                noise = self.spec_.model_noise_std**2 / measurements.shape[0] * np.eye(2)
                self.mean_, self.cov_, _, _ = kalman_update(
                    self.mean_,
                    self.cov_,
                    measurements.mean(axis=0),
                    self.measurement_matrix_,
                    noise,
                )
        position = self.mean_[self.position_index_].copy()
        variance = np.diag(self.cov_)[self.position_index_]
        return Estimate(position, np.maximum(variance, 1e-12))

    def predict(self, obs, state=None, episode_start=None, deterministic: bool = True):
        raise TypeError(
            "the clairvoyant filter is an oracle and needs the env's info each step; run it "
            "with dgpt_gym.benchmark.episodes.run_episode, not through predict()"
        )
