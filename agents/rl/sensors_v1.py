"""Sensor management that a learned agent can win: ``DGPTrackSensors-v1`` and ``-v2``."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from gymnasium import spaces

from agents.rl.base import TrackerInsideEnv
from agents.rl.registration import FixedTrackerOptions
from agents.rl.sensors_env import filter_reports
from dgpt_gym.registry import make_tracker, tracker_spec
from dgpt_gym.validation import check_integer, check_real

__all__ = [
    "DGPTrackSensorsV1Env",
    "WAKE_COUNTS",
    "OBSERVED_CANDIDATES",
    "TOP_SPEED",
    "SensorsObservation",
    "decode_observation",
]

WAKE_COUNTS: tuple[int | None, ...] = (0, 1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, None)
"""Action a wakes the ``WAKE_COUNTS[a]`` charged sensors nearest the tracker's prediction;
None wakes every charged sensor (the search that re-acquires a lost track)."""

OBSERVED_CANDIDATES = 16
"""The nearest charged sensors described in the observation."""

TOP_SPEED = 25.0
"""m/s: the scenarios' top speed, the scale of the predicted velocity in the observation."""

# the observation's other scales, shared by the environment and decode_observation
_STD_LOG_SCALE = 6.0  # log1p(standard deviation, m) / 6
_SILENT_SCALE = 10.0  # steps since a report / 10
_COUNT_LOG_SCALE = 6.0  # log1p(measurements) / 6
_REACH_COUNT_SCALE = 64.0  # charged sensors within range + 2 sigma / 64


class SensorsObservation(NamedTuple):
    """What the rules and the action tables read of a ``DGPTrackSensors-v1`` observation,
    in physical units."""

    distances: np.ndarray
    """(OBSERVED_CANDIDATES,) the nearest charged sensors' distances to the prediction, in
    sensing ranges (10 where there is no such sensor)."""
    sigma: float
    """The larger predictive standard deviation, m."""
    silent_steps: int
    """Steps since any woken sensor reported (the observation keeps at most 10)."""
    within_reach: float
    """Charged sensors within sensing range + 2 sigma of the prediction."""


def decode_observation(observation) -> SensorsObservation:
    """The inverse of the environment's scaling for the fields of :class:`SensorsObservation`."""
    observation = np.asarray(observation, dtype=float)
    tail = observation[3 * OBSERVED_CANDIDATES :]
    return SensorsObservation(
        distances=observation[0 : 3 * OBSERVED_CANDIDATES : 3],
        sigma=float(np.max(np.expm1(_STD_LOG_SCALE * tail[0:2]))),
        silent_steps=round(float(tail[5]) * _SILENT_SCALE),
        within_reach=float(tail[8]) * _REACH_COUNT_SCALE,
    )


class DGPTrackSensorsV1Env(TrackerInsideEnv):
    """Decide how many sensors to wake around the predicted target, with batteries.

    ## Description

    ``DGPTrack-v0`` with a GP tracker inside (v1: the SE DGPT-RBCM; ``DGPTrackSensors-v2``:
    ``dgpt-bcm``, the distributed NCV GP, whose predictive standard deviation, which the
    observation carries, is calibrated), on a random path through a random sensor
    layout each episode (the layout is drawn from the episode's seed, so evaluation seeds
    0-99 meet layouts that training seeds 1000 and up never showed). Before each step the
    agent chooses how many of the charged sensors nearest the tracker's predicted position
    to wake; only woken sensors report, and the tracker's estimate is scored. Every sensor
    has a battery: a step awake costs ``wake_energy``, waking a sleeping sensor costs
    ``startup_energy`` more, and an empty sensor cannot be woken again, so waking many
    sensors now leaves fewer for when the target comes back. Until the tracker has a
    prediction the wake order is by distance to the target's first position (a detection
    stage handed the track over).

    Choices, and why (the issue that asked for this task has the measurements):

    - a structured action: one number, "the nearest n" (``MultiBinary`` bits of v0 had no
      order, and PPO learnt to wake the ninth-nearest sensor more often than the second);
    - a search action (every charged sensor) so that a lost track can be re-acquired: in v0
      the 16 candidates near a wrong prediction could never see the target again;
    - a bounded reward (the error is capped at ``error_cap``), so that a lost track does not
      decide every comparison;
    - batteries and wake-up costs, so that the trade-off is not myopic;
    - time-to-go and the predicted velocity in the observation.

    ## Action Space

    ``Discrete(len(WAKE_COUNTS))``: action a wakes the ``WAKE_COUNTS[a]`` nearest charged
    sensors (0, 1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, or all).

    ## Observation Space

    ``Box(-10, 10, (3 * OBSERVED_CANDIDATES + 9,), float32)``: for the 16 nearest charged
    sensors, nearest first, the distance to the prediction / sensing range, the battery
    left, and 1 if awake at the last step; then the predictive standard deviations
    (log1p(m) / 6, per axis), the predicted velocity / 25 m/s (per axis), the fraction of
    the episode still to go, the steps since any woken sensor reported / 10 (at most 1),
    log1p of the measurements of the last step / 6, the mean battery of the network, and the
    number of charged sensors within sensing range + 2 standard deviations of the
    prediction / 64.

    ## Rewards

    ``-min(error, error_cap) / error_scale - energy_weight * energy``: ``error`` the
    Euclidean error of the estimate (m), ``energy`` the battery spent at this step summed
    over sensors. ``info`` carries ``error``, ``energy``, ``n_woken``, ``woken`` (boolean per
    sensor), ``battery`` (a copy), ``reports``, ``position`` and ``estimate``.

    ## Starting State

    A random path (``trajectory="random"``) in a layout drawn from the reset seed, every
    battery full, every sensor asleep, the tracker empty.

    ## Episode End

    Truncated at the end of the trajectory; never terminated.

    ## Arguments

    | argument | default | meaning |
    |---|---|---|
    | ``wake_energy`` | 0.01 | battery per step awake (a sensor lasts 100 awake steps) |
    | ``startup_energy`` | 0.01 | battery to wake a sleeping sensor |
    | ``energy_weight`` | 2.0 | reward per unit of battery spent |
    | ``error_cap`` | 4 x sensing range | m, the largest error the reward counts |
    | ``error_scale`` | sensing range | metres per unit of error penalty |
    | ``tracker`` | ``"dgpt-rbcm-trend"`` | the tracker inside: a registered id (``dgpt_gym.tracker_ids()``) or ``"package.module:ClassName"``, as ``dgpt_gym.make_tracker`` takes it; ``DGPTrackSensors-v2`` is this task with ``"dgpt-bcm"`` |
    | ``window`` | 3 | the tracker's ``window`` argument (None: the tracker's own default) |
    | ``tracker_options`` | None | further keyword arguments of the tracker, over its id's registered ones; ``DGPTrackSensors-v1`` fixes every argument of ``dgpt-rbcm-trend`` but ``window`` (``agents.rl.registration.SENSORS_V1_TRACKER_OPTIONS``), ``DGPTrackSensors-v2`` fixes every argument of ``dgpt-bcm`` (``agents.rl.registration.SENSORS_V2_TRACKER_OPTIONS``): the model as 0.9.0 built it (``association="local"``, manoeuvre probability 0.5, no turn modes, ``summary_variance="point"``, ``expert_update="summary"``, no silence particles) and the rest as its agents were trained. Gymnasium passes an id's fixed arguments with the user's, so another ``tracker`` with -v1 or -v2 needs its own ``tracker_options`` (None: its registered ones), or is refused |
    | ``layout`` | ``"per_episode"`` | ``"per_episode"`` (from the reset seed) or ``"fixed"`` (``layout_seed``) |
    | ``**env_kwargs`` | | ``DGPTrack-v0`` arguments; ``trajectory`` defaults to ``"random"`` |
    """

    knob = "n_woken"  # the info key of what the agent sets (for the evaluation tables)

    def __init__(
        self,
        wake_energy: float = 0.01,
        startup_energy: float = 0.01,
        energy_weight: float = 2.0,
        error_cap: float | None = None,
        error_scale: float | None = None,
        tracker: str = "dgpt-rbcm-trend",
        window: int | None = 3,
        layout: str = "per_episode",
        tracker_options: dict | None = None,
        **env_kwargs,
    ) -> None:
        env_kwargs.setdefault("trajectory", "random")
        tracker_spec(tracker)  # an unknown id is named before the options
        fixed_for = (
            tracker_options.tracker if isinstance(tracker_options, FixedTrackerOptions) else None
        )
        if fixed_for not in (None, tracker):
            raise ValueError(
                f"this environment id fixes tracker_options for tracker {fixed_for!r}; with "
                f"tracker={tracker!r} pass tracker_options too (None: its registered arguments)"
            )
        options = {} if window is None else {"window": check_integer("window", window, low=1)}
        options.update(tracker_options or {})
        try:
            inner_tracker = make_tracker(tracker, **options)
        except TypeError as error:
            raise ValueError(
                f"tracker {tracker!r} does not take the arguments {sorted(options)} ({error}): "
                "pass window=None if it takes no window, and tracker_options that it takes"
            ) from None
        super().__init__(inner_tracker, error_scale, env_kwargs, layout)
        self.wake_energy = check_real("wake_energy", wake_energy, low=0.0)
        self.startup_energy = check_real("startup_energy", startup_energy, low=0.0)
        self.energy_weight = check_real("energy_weight", energy_weight, low=0.0)
        self.error_cap = (
            4.0 * self.inner.sensing_range
            if error_cap is None
            else check_real("error_cap", error_cap, low=0.0, low_inclusive=False)
        )
        self.action_space = spaces.Discrete(len(WAKE_COUNTS))
        self.observation_space = spaces.Box(
            -10.0, 10.0, shape=(3 * OBSERVED_CANDIDATES + 9,), dtype=np.float32
        )

    def fixed_actions(self) -> tuple[dict[str, object], str]:
        """Waking the nearest n for every n of :data:`WAKE_COUNTS`; the default wakes 8."""
        actions = {
            ("all" if count is None else f"nearest {count}"): index
            for index, count in enumerate(WAKE_COUNTS)
        }
        return actions, "nearest 8"

    # -- Gymnasium API ----------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        info = self._reset_inner(seed, options)
        n = self.inner.n_sensors
        self.battery_ = np.ones(n)
        self._awake = np.zeros(n, dtype=bool)
        self._predicted = info["position"].copy()  # the hand-over cue (see Description)
        self._predicted_std = np.full(2, self.inner.sensing_range)
        self._velocity = np.zeros(2)
        self._silent = 0
        self._last_count = 0
        self._step = 0
        return self._observation(), {"position": info["position"]}

    def begin_step(self, action) -> dict:
        self._check_started()
        value = np.asarray(action)
        if (
            value.size != 1
            or value.dtype.kind not in "iu"
            or not 0 <= int(value.reshape(-1)[0]) < self.action_space.n
        ):
            raise ValueError(
                f"action must be an integer in [0, {self.action_space.n - 1}] (an index of "
                f"WAKE_COUNTS); got {action!r}"
            )
        action = int(value.reshape(-1)[0])
        count = WAKE_COUNTS[action]
        order = self._order  # the wake order the observation described
        woken = np.zeros(self.inner.n_sensors, dtype=bool)
        woken[order if count is None else order[:count]] = True
        energy = woken * self.wake_energy + (woken & ~self._awake) * self.startup_energy
        self._energy = float(np.sum(energy))
        self.battery_ = np.maximum(self.battery_ - energy, 0.0)
        self._awake = woken
        self._reports = filter_reports(self._pending, woken)
        return self._reports

    def end_step(self, estimate):
        reports = self._reports
        n_reports = int(reports["mask"].sum())
        self._silent = 0 if n_reports else self._silent + 1
        self._last_count = n_reports
        _, terminated, truncated, inner_info = self._score(estimate)
        self._step += 1
        if estimate.prior_next is not None:
            predicted = np.asarray(estimate.prior_next[0], dtype=float)
            self._velocity = (predicted - estimate.mean) / self.inner.dt
            self._predicted = predicted.copy()
            self._predicted_std = np.sqrt(np.maximum(estimate.prior_next[1], 0.0))
        error = inner_info["error"]
        reward = -min(error, self.error_cap) / self.error_scale - self.energy_weight * self._energy
        info = {
            "error": error,
            "energy": self._energy,
            "n_woken": int(self._awake.sum()),
            "woken": self._awake.copy(),
            "battery": self.battery_.copy(),
            "reports": reports,
            "position": inner_info["position"],
            "estimate": estimate.mean.copy(),
        }
        return self._observation(), float(reward), terminated, truncated, info

    # -- helpers ----------------------------------------------------------------------------

    def _charged(self) -> np.ndarray:
        """Sensors that can pay for a step awake (and the wake-up if asleep)."""
        cost = self.wake_energy + np.where(self._awake, 0.0, self.startup_energy)
        return np.flatnonzero(self.battery_ >= cost - 1e-12)

    def _wake_order(self) -> tuple[np.ndarray, np.ndarray]:
        """The charged sensors, nearest to the prediction first, and their distances (m)."""
        charged = self._charged()
        offset = self.inner.network.positions - self._predicted
        # np.linalg.norm(offset, axis=1) to the last bit (the same two squares, one sum), in
        # a fraction of its time: this runs at every step of every sub-environment
        distance = np.sqrt(offset[:, 0] ** 2 + offset[:, 1] ** 2)[charged]
        nearest_first = np.argsort(distance, kind="stable")
        return charged[nearest_first], distance[nearest_first]

    def _observation(self) -> np.ndarray:
        """The observation of the coming step; keeps its wake order for ``begin_step``."""
        self._order, distance = self._wake_order()
        nearest = self._order[:OBSERVED_CANDIDATES]
        per_candidate = np.zeros((OBSERVED_CANDIDATES, 3))
        per_candidate[:, 0] = 10.0  # no such sensor: far away, empty, asleep
        per_candidate[: nearest.size, 0] = distance[:OBSERVED_CANDIDATES] / self.inner.sensing_range
        per_candidate[: nearest.size, 1] = self.battery_[nearest]
        per_candidate[: nearest.size, 2] = self._awake[nearest]
        reach = self.inner.sensing_range + 2.0 * float(np.max(self._predicted_std))
        tail = np.empty(9)
        tail[0:2] = np.log1p(self._predicted_std) / _STD_LOG_SCALE
        tail[2:4] = self._velocity / TOP_SPEED
        tail[4] = 1.0 - self._step / self.inner.n_steps
        tail[5] = min(self._silent / _SILENT_SCALE, 1.0)
        tail[6] = np.log1p(self._last_count) / _COUNT_LOG_SCALE
        tail[7] = np.mean(self.battery_)
        tail[8] = np.count_nonzero(distance <= reach) / _REACH_COUNT_SCALE
        vector = np.concatenate((per_candidate.ravel(), tail))
        # np.clip's numbers (NaN included), without its overhead
        return np.minimum(np.maximum(vector, -10.0), 10.0).astype(np.float32)
