"""The point-target tracking environment ``DGPTrack-v0``."""

from __future__ import annotations

import dataclasses
import logging
import math
from functools import partial

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded
from scipy import stats

from dgpt_gym.measurements import CLUTTER_SENSORS, Scans, simulate_scans
from dgpt_gym.network import SensorNetwork
from dgpt_gym.problem import ProblemSpec
from dgpt_gym.rendering import Renderer
from dgpt_gym.scenarios import Scenario, Trajectory, get_scenario
from dgpt_gym.validation import check_choice, check_integer, check_real

__all__ = [
    "DGPTrackEnv",
    "vector_env",
    "TRAJECTORY_MODES",
    "LAYOUT_MODES",
    "OVERFLOW_PROBABILITY",
]

logger = logging.getLogger(__name__)

TRAJECTORY_MODES = ("fixed", "random")
LAYOUT_MODES = ("fixed", "per_episode")
"""Where an episode's sensor layout comes from, for the tools that run many episodes (the
RL environments, :class:`dgpt_gym.benchmark.sweep.Grid`): ``"fixed"``, the env's
``layout_seed`` in every episode; ``"per_episode"``, the episode's seed, so that evaluation
seeds 1-99 meet layouts that training seeds (1000 and up) never showed (seed 0 meets layout
0, the default, in which the trackers' settings were chosen)."""
RESET_OPTIONS = ("layout_seed",)
"""The keys ``reset(options=...)`` accepts."""
OVERFLOW_PROBABILITY = 1e-9
"""Per-step probability bound on more measurements than the observation holds."""


class DGPTrackEnv(gym.Env):
    """Single point-target tracking in a wireless sensor network with Poisson clutter.

    ## Description

    The simulation setup of Sec. VII-B of "Gaussian Process Upper Confidence Bounds in
    Distributed Point Target Tracking over Wireless Sensor Networks": ``n_sensors`` sensors
    lie uniformly at random in ``[0, area]^2`` and each senses a disc of radius
    ``sensing_range``. A target moves along one of the scenarios S1-S4 (Sec. VII-D, see
    :mod:`dgpt_gym.scenarios`). Every step, each sensor that senses the target reports a
    zero-truncated Poisson(``detection_rate``) number of measurements ``z = p +
    N(0, noise_std^2 I)``, and each clutter-producing sensor reports Poisson(``clutter_rate``)
    clutter points uniform in its sensing disc. The agent (a tracker) sees the measurements
    and which sensor sent each one, never which are target-originated, and answers with an
    estimate of the target's current position.

    ## Action Space

    ``Box(-area, 2 * area, shape=(2,), float64)``: the estimate (x, y) of the target position
    at the step of the last observation, in metres. The bounds are generous; finite actions
    outside them are accepted and simply scored. An action that is not two finite real
    numbers (non-finite, bool, complex, strings, another shape) raises ``ValueError``.

    ## Observation Space

    ``Dict`` of fixed-size arrays padded to ``K = max_measurements`` rows:

    | key | space | meaning |
    |---|---|---|
    | ``measurements`` | ``Box(-inf, inf, (K, 2), float64)`` | measurement positions, m; 0 in padding |
    | ``sensor`` | ``Box(-1, n_sensors - 1, (K,), int64)`` | reporting sensor per row; -1 in padding |
    | ``mask`` | ``MultiBinary(K)`` (int8) | 1 for a real measurement, 0 for padding |
    | ``t`` | ``Discrete(n_steps + 1)`` | the step index of these measurements |

    Real rows come first, grouped by sensor in ascending order, in random order within a
    sensor. ``K`` is derived so that more measurements than ``K`` occur with probability
    below 1e-9 per step (:meth:`derive_max_measurements`); should it happen, the extra
    measurements are dropped from the observation, counted in ``info["overflow"]`` and a
    warning is logged once.

    ## Rewards

    Minus the Euclidean error of the estimate, in metres: ``-||action - p_t||``.

    ## Starting State

    The target starts at the first point of the scenario's trajectory: with
    ``trajectory="fixed"`` the scenario's one reference trajectory (the paper's Monte Carlo
    runs share it and differ in measurements and clutter), with ``"random"`` a fresh draw
    from the scenario's model. ``reset`` returns the measurements of step 0. The sensor
    layout comes from ``layout_seed`` and stays the same across episodes unless
    ``reset(options={"layout_seed": s})`` gives another (the one option; others raise
    ``ValueError``).

    ## Episode End

    The episode is truncated after the last step of the trajectory (100-200 steps); it never
    terminates. The observation returned with the truncation has no measurements and
    ``t = n_steps``. Stepping before ``reset`` or after the end raises
    ``gymnasium.error.ResetNeeded``.

    ## Info

    ``position`` and ``velocity`` (truth of the step just scored, or of step 0 at reset),
    ``n_target``, ``n_clutter``, ``active_sensors`` (indices of the sensors that sense the
    target), ``overflow``, and after a step ``error``. Reset info also has ``problem_spec``
    (:class:`~dgpt_gym.problem.ProblemSpec`) and ``scenario`` (the
    :class:`~dgpt_gym.scenarios.Scenario` and its parameters).

    About the observation returned with it (step ``t = obs["t"]``): ``target_origin``, a
    (K,) bool array marking its target-originated rows, and the manoeuvre over the interval
    ending at step t: ``turn_rate`` (rad/s; S2, S3, else None) and ``new_leg`` (the velocity
    was redrawn at a waypoint; S1, else None).

    Trackers must not read ``info``: it holds the truth. The evaluation loop hands it only
    to trackers that declare themselves oracles (``oracle = True``, e.g. the clairvoyant
    accuracy floor; :func:`dgpt_gym.benchmark.episodes.run_episodes`).

    ## Arguments

    | argument | default | meaning |
    |---|---|---|
    | ``scenario`` | ``"S1"`` | ``"S1"`` .. ``"S4"`` or a :class:`~dgpt_gym.scenarios.Scenario` |
    | ``noise_std`` | 1.0 | sigma_z of target measurements, m, >= 0 (the paper: 1, 2, 4; 0: exact target measurements) |
    | ``clutter_rate`` | 1.0 | lambda_c, clutter points per clutter-producing sensor per step (the paper: 1, 5) |
    | ``detection_rate`` | 1.0 | lambda_T, > 0 |
    | ``n_sensors`` | 250 | number of sensors |
    | ``area`` | 1000.0 | side of the square area, m |
    | ``sensing_range`` | 50.0 | sensing radius, m |
    | ``dt`` | 1.0 | sampling period, s |
    | ``clutter_sensors`` | ``"detecting"`` | ``"detecting"``: clutter only at sensors that sense the target (the paper); ``"all"``: at every sensor |
    | ``trajectory`` | ``"fixed"`` | ``"fixed"`` or ``"random"`` |
    | ``layout_seed`` | 0 | seed of the sensor layout |
    | ``max_measurements`` | derived | K, the padding size of the observation |
    | ``render_mode`` | None | ``"rgb_array"`` or ``"human"`` |

    Invalid values raise ``ValueError`` naming the argument, the value and what is allowed.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    def __init__(
        self,
        scenario: str | Scenario = "S1",
        noise_std: float = 1.0,
        clutter_rate: float = 1.0,
        detection_rate: float = 1.0,
        n_sensors: int = 250,
        area: float = 1000.0,
        sensing_range: float = 50.0,
        dt: float = 1.0,
        clutter_sensors: str = "detecting",
        trajectory: str = "fixed",
        layout_seed: int = 0,
        max_measurements: int | None = None,
        render_mode: str | None = None,
    ) -> None:
        base = scenario if isinstance(scenario, Scenario) else get_scenario(scenario)
        self.noise_std = check_real("noise_std", noise_std, low=0.0)
        self.clutter_rate = check_real("clutter_rate", clutter_rate, low=0.0)
        self.detection_rate = check_real(
            "detection_rate", detection_rate, low=0.0, low_inclusive=False
        )
        self.n_sensors = check_integer("n_sensors", n_sensors, low=1)
        self.area = check_real("area", area, low=0.0, low_inclusive=False)
        self.sensing_range = check_real(
            "sensing_range", sensing_range, low=0.0, low_inclusive=False
        )
        self.dt = check_real("dt", dt, low=0.0, low_inclusive=False)
        self.clutter_sensors = check_choice("clutter_sensors", clutter_sensors, CLUTTER_SENSORS)
        self.trajectory_mode = check_choice("trajectory", trajectory, TRAJECTORY_MODES)
        self.layout_seed = check_integer("layout_seed", layout_seed, low=0)
        self.render_mode = check_choice(
            "render_mode", render_mode, [None, *self.metadata["render_modes"]]
        )
        self.scenario = dataclasses.replace(base, area=self.area, dt=self.dt)
        try:
            self._reference = self.scenario.reference()
        except RuntimeError as error:
            raise ValueError(
                f"area={self.area!r} is too small for scenario {self.scenario.name}: {error}"
            ) from None
        self.network = SensorNetwork.uniform(
            self.n_sensors, self.area, self.sensing_range, self.layout_seed
        )
        if max_measurements is None:
            max_measurements = self.derive_max_measurements(self.network)
        self.max_measurements = check_integer("max_measurements", max_measurements, low=1)
        self.n_steps = self.scenario.n_steps

        k = self.max_measurements
        self.observation_space = spaces.Dict(
            {
                "measurements": spaces.Box(-np.inf, np.inf, (k, 2), np.float64),
                "sensor": spaces.Box(-1, self.n_sensors - 1, (k,), np.int64),
                "mask": spaces.MultiBinary(k),
                "t": spaces.Discrete(self.n_steps + 1),
            }
        )
        self.action_space = spaces.Box(-self.area, 2.0 * self.area, (2,), np.float64)

        self.trajectory_: Trajectory | None = None
        self.scans_: Scans | None = None
        self.step_: int | None = None
        self.estimates_: list[np.ndarray] = []
        self.uncertainties_: list[tuple[np.ndarray, np.ndarray | None] | None] = []
        self._annotation = None
        self._overflow_warned = False
        self._renderer = None

    # -- configuration -----------------------------------------------------------------

    def derive_max_measurements(self, network: SensorNetwork) -> int:
        """K such that a step has more than K measurements with probability < 1e-9.

        At most ``D = network.max_sensors_in_range()`` sensors sense the target. A
        zero-truncated Poisson(lambda_T) count is stochastically below 1 + Poisson(lambda_T),
        so the total is below ``D + Poisson(D lambda_T + S lambda_c)``, ``S`` being the number
        of clutter-producing sensors (``D`` or ``n_sensors``).
        """
        detecting = network.max_sensors_in_range()
        producing = detecting if self.clutter_sensors == "detecting" else network.n_sensors
        rate = detecting * self.detection_rate + producing * self.clutter_rate
        return int(detecting + stats.poisson.isf(OVERFLOW_PROBABILITY, rate) + 1)

    @property
    def problem_spec(self) -> ProblemSpec:
        """What trackers may know: layout, sensing range, rates and noise (docs/design.md)."""
        return ProblemSpec(
            sensor_positions=self.network.positions,
            sensing_range=self.sensing_range,
            noise_std=self.noise_std,
            clutter_rate=self.clutter_rate,
            detection_rate=self.detection_rate,
            dt=self.dt,
            area=self.area,
            clutter_sensors=self.clutter_sensors,
            n_steps=self.n_steps,
        )

    # -- Gymnasium API -------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if options is None:
            options = {}
        if not isinstance(options, dict):
            raise ValueError(f"options must be a dict or None; got {options!r}")
        unknown = sorted(set(options) - set(RESET_OPTIONS), key=str)
        if unknown:
            raise ValueError(f"options has unknown keys {unknown}; allowed: {list(RESET_OPTIONS)}")
        if "layout_seed" in options:
            layout_seed = check_integer("options['layout_seed']", options["layout_seed"], low=0)
            if layout_seed != self.layout_seed:
                self.layout_seed = layout_seed
                self.network = SensorNetwork.uniform(
                    self.n_sensors, self.area, self.sensing_range, layout_seed
                )
        if self.trajectory_mode == "fixed":
            self.trajectory_ = self._reference
        else:
            self.trajectory_ = self.scenario.sample(self.np_random)
        self.scans_ = simulate_scans(
            self.np_random,
            self.network,
            self.trajectory_.positions,
            self.noise_std,
            self.detection_rate,
            self.clutter_rate,
            self.clutter_sensors,
        )
        self._prepare_episode()
        self.step_ = 0
        info = self._step_info(0)
        info.update(self._observation_truth(0))
        info["problem_spec"] = self.problem_spec
        info["scenario"] = self.scenario
        self.estimates_ = []
        self.uncertainties_ = []
        self._annotation = None
        if self.render_mode == "human":
            self.render()
        return self._observation(0), info

    def annotate(self, var, ucb=None) -> None:
        """Attach the uncertainty of the estimate about to be passed to :meth:`step`: its
        per-axis variance (m^2) and, where the tracker has one, its UCB half-width (m).
        Only :meth:`render` uses it (a 3-sigma ellipse and the UCB box around the estimate);
        the action stays the position alone. Call it before each ``step``, e.g.
        ``env.unwrapped.annotate(estimate.var, estimate.ucb)``."""
        var = np.asarray(var, dtype=float)
        if var.shape != (2,) or not np.all(np.isfinite(var)) or np.any(var < 0):
            raise ValueError(f"var must be two finite variances >= 0; got {var!r}")
        if ucb is not None:
            ucb = np.asarray(ucb, dtype=float)
            if ucb.shape != (2,) or np.any(ucb < 0) or np.any(np.isnan(ucb)):
                raise ValueError(f"ucb must be two half-widths >= 0 or None; got {ucb!r}")
        self._annotation = (var, ucb)

    def step(self, action):
        if self.step_ is None:
            raise ResetNeeded("Cannot call env.step() before calling env.reset()")
        if self.step_ >= self.n_steps:
            raise ResetNeeded(
                "The episode has ended (truncated); call env.reset() before env.step()"
            )
        raw = np.asarray(action)
        if raw.dtype.kind not in "iuf":  # bool, complex, strings and objects would cast silently
            raise ValueError(
                f"action must be a finite real position estimate of shape (2,); got {action!r}"
            )
        estimate = raw.astype(np.float64)
        if estimate.shape != (2,) or not (
            math.isfinite(estimate[0]) and math.isfinite(estimate[1])
        ):
            raise ValueError(
                f"action must be a finite position estimate of shape (2,); got {action!r}"
            )
        step = self.step_
        truth = self.trajectory_.positions[step]
        error = math.hypot(estimate[0] - truth[0], estimate[1] - truth[1])
        info = self._step_info(step)
        info["error"] = error
        self.estimates_.append(estimate)
        self.uncertainties_.append(self._annotation)
        self._annotation = None
        self.step_ = step + 1
        truncated = self.step_ == self.n_steps
        info.update(self._observation_truth(self.step_))
        observation = self._observation(self.step_)
        if self.render_mode == "human":
            self.render()
        return observation, -error, False, truncated, info

    def render(self):
        if self.render_mode is None:
            gym.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human'"
            )
            return None
        if self.step_ is None:
            raise ResetNeeded("Cannot call env.render() before calling env.reset()")
        if self._renderer is None:
            self._renderer = Renderer(self)
        return self._renderer.render(self.render_mode)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # -- helpers -------------------------------------------------------------------------

    def _prepare_episode(self) -> None:
        """Pad every step's measurements into read-only (n_steps + 1, K, ...) arrays once per
        episode, so that a step returns views; the last row is the empty final observation."""
        scans, k = self.scans_, self.max_measurements
        per_step = np.diff(scans.offsets)
        kept = np.minimum(per_step, k)
        step_of_row = np.repeat(np.arange(self.n_steps), per_step)
        slot = np.arange(scans.sensor.size) - np.repeat(scans.offsets[:-1], per_step)
        keep = slot < k
        measurements = np.zeros((self.n_steps + 1, k, 2))
        sensor = np.full((self.n_steps + 1, k), -1, dtype=np.int64)
        measurements[step_of_row[keep], slot[keep]] = scans.measurements[keep]
        sensor[step_of_row[keep], slot[keep]] = scans.sensor[keep]
        target_origin = np.zeros((self.n_steps + 1, k), dtype=bool)
        target_origin[step_of_row[keep], slot[keep]] = scans.is_target[keep]
        mask = (np.arange(k) < np.r_[kept, 0][:, None]).astype(np.int8)
        for array in (measurements, sensor, mask, target_origin):
            array.setflags(write=False)
        self._padded = (measurements, sensor, mask)
        self._target_origin = target_origin
        n_target, n_clutter = scans.counts()
        self._n_target, self._n_clutter = n_target.tolist(), n_clutter.tolist()
        self._overflow = (per_step - kept).tolist()
        detect_step, detect_sensor = np.nonzero(scans.detecting)
        self._active = np.split(
            detect_sensor, np.searchsorted(detect_step, np.arange(1, self.n_steps))
        )

    def _observation(self, step: int) -> dict:
        measurements, sensor, mask = self._padded
        return {
            "measurements": measurements[step],
            "sensor": sensor[step],
            "mask": mask[step],
            "t": step,
        }

    def _observation_truth(self, step: int) -> dict:
        """The truth about the observation of ``step`` that only oracle trackers may read:
        which rows are target-originated and the manoeuvre over the interval ending at it."""
        trajectory = self.trajectory_
        inside = step < self.n_steps
        return {
            "target_origin": self._target_origin[step],
            "turn_rate": (
                float(trajectory.turn_rate[step])
                if inside and trajectory.turn_rate is not None
                else None
            ),
            "new_leg": (
                bool(trajectory.new_leg[step])
                if inside and trajectory.new_leg is not None
                else None
            ),
        }

    def _step_info(self, step: int) -> dict:
        overflow = self._overflow[step]
        if overflow and not self._overflow_warned:
            self._overflow_warned = True
            logger.warning(
                "step %d has %d more measurements than max_measurements=%d; they are dropped "
                "from the observation and counted in info['overflow']",
                step,
                overflow,
                self.max_measurements,
            )
        return {
            "position": self.trajectory_.positions[step].copy(),
            "velocity": self.trajectory_.velocities[step].copy(),
            "n_target": self._n_target[step],
            "n_clutter": self._n_clutter[step],
            "active_sensors": self._active[step].copy(),
            "overflow": overflow,
        }


def vector_env(num_envs: int = 1, copy: bool = True, **env_kwargs) -> gym.vector.SyncVectorEnv:
    """``gymnasium.make_vec("DGPTrack-v0", num_envs, vectorization_mode="vector_entry_point")``:
    ``num_envs`` :class:`DGPTrackEnv` with ``env_kwargs`` in Gymnasium's sync vector env. A
    step of this environment is a table lookup (the scans are drawn at reset), so there is
    nothing to batch; the RL environments, which run a tracker inside, batch it
    (``agents.rl.vector``)."""
    return gym.vector.SyncVectorEnv([partial(DGPTrackEnv, **env_kwargs)] * num_envs, copy=copy)
