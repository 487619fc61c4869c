"""Tracker-tuning environments: an agent adapts the DGPT tracker as the target manoeuvres.

Both wrap a :class:`~dgpt_gym.env.DGPTrackEnv` with a :class:`~agents.dgpt.DGPT` tracker
inside: each step the agent sets one knob of the tracker, the tracker processes the step's
measurements with it, and the tracker's estimate is scored.
"""

from __future__ import annotations

import abc
import math

import numpy as np
from gymnasium import spaces

from agents.dgpt import DGPT
from agents.rl.base import TrackerInsideEnv
from agents.rl.features import FEATURE_HIGH, FEATURE_NAMES, tracker_features
from agents.rl.registration import TREND_TRACKER_OPTIONS
from dgpt_gym.validation import check_integer, check_real

__all__ = ["TrackerTuningEnv", "DGPTrackWindowEnv", "DGPTrackGatingEnv", "DEFAULT_WINDOWS"]

DEFAULT_WINDOWS = (2, 3, 4, 5, 6, 8, 10, 14, 20)
"""Candidate window lengths C of ``DGPTrackWindow-v0``: the paper's default 10 and the
windows tuned on training seeds, 2-3, among them."""

_REWARD_DOC = """
    Reward: ``-error / error_scale - compute_weight * n_experts * (C / C_max)^3``: the
    Euclidean error of the estimate normalised by ``error_scale`` (default: the sensing
    range), minus the cost of the step's GP training, which is cubic in the window length C
    per expert (the paper's complexity, Sec. IV-E: O(M C^3) for M experts of at most C
    points), scaled so that the largest window with one expert costs ``compute_weight``.
    ``info`` carries ``error``, ``compute_cost``, ``n_experts``, ``window``, the true
    ``position`` and the ``estimate``."""


class TrackerTuningEnv(TrackerInsideEnv, abc.ABC):
    """Shared machinery of the tuning environments (subclasses define the action)."""

    knob = "window"  # the info key of what the agent sets (for the evaluation tables)

    def __init__(
        self,
        aggregation: str = "rbcm",
        inputs: str = "tgp",
        window: int = 3,
        max_window: int = 20,
        gate_threshold: float | None = None,
        compute_weight: float = 0.1,
        error_scale: float | None = None,
        layout: str = "fixed",
        **env_kwargs,
    ) -> None:
        tracker = DGPT(
            aggregation=aggregation,
            inputs=inputs,
            window=window,
            gate_threshold=gate_threshold,
            **TREND_TRACKER_OPTIONS,
        )
        super().__init__(tracker, error_scale, env_kwargs, layout)
        self.max_window = check_integer("max_window", max_window, low=window)
        self.compute_weight = check_real("compute_weight", compute_weight, low=0.0)
        self.observation_space = spaces.Box(
            0.0, FEATURE_HIGH, shape=(len(FEATURE_NAMES),), dtype=np.float32
        )

    # -- the knob the subclass exposes ----------------------------------------------------

    @abc.abstractmethod
    def _apply_action(self, action) -> None:
        """Set the tracker's knob from the agent's action (validating it)."""

    def _reset_knob(self) -> None:
        """Return the knob to its value at the start of an episode."""

    def _window_position(self) -> float:
        return (self.tracker.window_.length - 2) / max(self.max_window - 2, 1)

    def _threshold_position(self) -> float:
        return 1.0

    # -- Gymnasium API --------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        info = self._reset_inner(seed, options)
        self._reset_knob()
        self._silent = 0
        return self._features(None), {"position": info["position"]}

    def begin_step(self, action) -> dict:
        self._check_started()
        self._apply_action(action)
        return self._pending

    def end_step(self, estimate):
        n_measurements = int(np.sum(self._pending["mask"]))
        self._silent = 0 if n_measurements else self._silent + 1
        observation, terminated, truncated, inner_info = self._score(estimate)
        error = inner_info["error"]
        n_experts = self.tracker.n_experts_
        window = self.tracker.window_.length
        compute_cost = self.compute_weight * n_experts * (window / self.max_window) ** 3
        reward = -error / self.error_scale - compute_cost
        info = {
            "error": error,
            "compute_cost": compute_cost,
            "n_experts": n_experts,
            "window": window,
            "gate_threshold": self.tracker.gate_threshold,
            "position": inner_info["position"],
            "estimate": estimate.mean.copy(),
        }
        return self._features(estimate, observation), float(reward), terminated, truncated, info

    def _features(self, estimate, observation=None) -> np.ndarray:
        upcoming = self._pending if observation is None else observation
        return tracker_features(
            self.tracker,
            estimate,
            int(np.sum(upcoming["mask"])),
            self._window_position(),
            self._threshold_position(),
            self._silent,
        )


class DGPTrackWindowEnv(TrackerTuningEnv):
    """Choose the DGPT tracker's sliding-window length C at every step.

    ## Description

    ``DGPTrack-v0`` with a DGPT tracker inside (:class:`agents.dgpt.DGPT`, RBCM aggregation
    and temporal inputs by default). Each step the agent picks C from ``windows``; the
    tracker trains its experts on the last C steps of gated summaries and its estimate is
    scored. Short windows follow manoeuvres, long ones average out noise and clutter and
    cost more to train: the agent learns when to use which. The tracker keeps
    ``max(windows)`` steps of history, so C can grow again after it shrank.

    ## Action Space

    ``Discrete(len(windows))``: action i sets C = ``windows[i]``.

    ## Observation Space

    ``Box(0, 10, (19,), float32)``, what the tracker knows after the previous step
    (:data:`agents.rl.features.FEATURE_NAMES`): active experts, measurements of the coming
    step, predictive standard deviations and UCB half-widths per axis, mean distance of the
    gated summaries from their predictions, measurements dropped by the hard gate, the
    current C and gate threshold, steps without measurements, and the learned
    hyperparameters of both axes, each scaled to about [0, 1].

    ## Rewards
    {reward}

    ## Starting State

    The inner environment's reset (its scenario, seed and layout; with
    ``layout="per_episode"`` the layout drawn from the reset seed); the tracker starts
    empty.

    ## Episode End

    Truncated at the end of the trajectory (100-200 steps); never terminated.

    ## Arguments

    | argument | default | meaning |
    |---|---|---|
    | ``windows`` | (2, 3, 4, 5, 6, 8, 10, 14, 20) | candidate window lengths, each >= 2 |
    | ``aggregation`` | ``"rbcm"`` | DGPT aggregation: poe, gpoe, bcm, rbcm |
    | ``inputs`` | ``"tgp"`` | ``"tgp"`` or ``"stgp"`` |
    | ``compute_weight`` | 0.1 | weight of the compute cost, >= 0 |
    | ``error_scale`` | sensing range | metres per unit of error penalty, > 0 |
    | ``layout`` | ``"fixed"`` | ``"fixed"`` (``layout_seed``) or ``"per_episode"`` (from the reset seed; :data:`agents.rl.base.LAYOUTS`) |
    | ``**env_kwargs`` | | ``DGPTrack-v0`` arguments (``scenario``, ``noise_std``, ``clutter_rate``, ...) |
    """

    def __init__(
        self,
        windows: tuple[int, ...] = DEFAULT_WINDOWS,
        aggregation: str = "rbcm",
        inputs: str = "tgp",
        compute_weight: float = 0.1,
        error_scale: float | None = None,
        layout: str = "fixed",
        **env_kwargs,
    ) -> None:
        windows = tuple(windows)
        if not windows:
            raise ValueError("windows must be a non-empty sequence of integers >= 2; got ()")
        self.windows = tuple(check_integer("windows", w, low=2) for w in windows)
        super().__init__(
            aggregation,
            inputs,
            window=self.windows[0],
            max_window=max(self.windows),
            compute_weight=compute_weight,
            error_scale=error_scale,
            layout=layout,
            **env_kwargs,
        )
        self.action_space = spaces.Discrete(len(self.windows))

    def fixed_actions(self) -> tuple[dict[str, object], str]:
        """Every candidate C; the default is C = 4, the DGPT tracker's default."""
        actions = {f"fixed C={w}": i for i, w in enumerate(self.windows)}
        return actions, "fixed C=4" if "fixed C=4" in actions else next(iter(actions))

    def _apply_action(self, action) -> None:
        index = int(action)
        if not 0 <= index < len(self.windows):
            raise ValueError(f"action must be in 0..{len(self.windows) - 1}; got {action!r}")
        self.tracker.set_window(self.windows[index], keep=self.max_window)


class DGPTrackGatingEnv(TrackerTuningEnv):
    """Set the DGPT tracker's hard gating threshold at every step (continuous).

    ## Description

    ``DGPTrack-v0`` with a DGPT tracker inside, window fixed. Before the weighted mean of
    eqs. (27)-(28), measurements whose Mahalanobis distance from their sensor's prediction
    exceeds the threshold are dropped (:class:`agents.dgpt.DGPT` ``gate_threshold``). A
    tight gate rejects clutter but can lose the target at a manoeuvre; a loose one lets
    clutter into the summaries.

    ## Action Space

    ``Box(-1, 1, (1,), float32)``, mapped log-linearly onto the threshold:
    ``threshold = min_threshold * (max_threshold / min_threshold) ** ((a + 1) / 2)``.
    Actions outside [-1, 1] are clipped.

    ## Observation Space

    As ``DGPTrackWindow-v0`` (:class:`DGPTrackWindowEnv`): 19 features.

    ## Rewards
    {reward}

    With a fixed window the compute cost is a constant offset.

    ## Starting State

    The inner environment's reset; the tracker starts empty.

    ## Episode End

    Truncated at the end of the trajectory; never terminated.

    ## Arguments

    | argument | default | meaning |
    |---|---|---|
    | ``min_threshold``, ``max_threshold`` | 1.0, 30.0 | range of the threshold (Mahalanobis distance) |
    | ``window`` | 3 | the tracker's window length C (the tuned one for S1-S3) |
    | ``aggregation``, ``inputs`` | ``"rbcm"``, ``"tgp"`` | the DGPT tracker |
    | ``compute_weight`` | 0.1 | weight of the compute cost, >= 0 |
    | ``error_scale`` | sensing range | metres per unit of error penalty, > 0 |
    | ``layout`` | ``"fixed"`` | ``"fixed"`` (``layout_seed``) or ``"per_episode"`` (from the reset seed; :data:`agents.rl.base.LAYOUTS`) |
    | ``**env_kwargs`` | | ``DGPTrack-v0`` arguments |
    """

    knob = "gate_threshold"

    def __init__(
        self,
        min_threshold: float = 1.0,
        max_threshold: float = 30.0,
        window: int = 3,
        aggregation: str = "rbcm",
        inputs: str = "tgp",
        compute_weight: float = 0.1,
        error_scale: float | None = None,
        layout: str = "fixed",
        **env_kwargs,
    ) -> None:
        self.min_threshold = check_real(
            "min_threshold", min_threshold, low=0.0, low_inclusive=False
        )
        self.max_threshold = check_real(
            "max_threshold", max_threshold, low=self.min_threshold, low_inclusive=False
        )
        window = check_integer("window", window, low=2)
        super().__init__(
            aggregation,
            inputs,
            window=window,
            max_window=window,
            gate_threshold=self.max_threshold,
            compute_weight=compute_weight,
            error_scale=error_scale,
            layout=layout,
            **env_kwargs,
        )
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)

    def threshold(self, action) -> float:
        """The gate threshold of an action in [-1, 1] (clipped)."""
        value = np.asarray(action, dtype=float).reshape(-1)
        if value.size != 1 or not math.isfinite(value[0]):
            raise ValueError(f"action must be one finite number; got {action!r}")
        fraction = (np.clip(value[0], -1.0, 1.0) + 1.0) / 2.0
        return float(self.min_threshold * (self.max_threshold / self.min_threshold) ** fraction)

    def fixed_actions(self) -> tuple[dict[str, object], str]:
        """Thresholds at actions -1, -0.75, ..., 1; the default is no hard gate (the paper's
        soft gating only, reached at the largest threshold, action 1)."""
        actions = {
            f"fixed threshold {self.threshold([a]):.3g}": np.array([a], dtype=np.float32)
            for a in np.linspace(-1.0, 1.0, 9)
        }
        return actions, list(actions)[-1]

    def _apply_action(self, action) -> None:
        self.tracker.gate_threshold = self.threshold(action)

    def _reset_knob(self) -> None:
        self.tracker.gate_threshold = self.max_threshold

    def _threshold_position(self) -> float:
        ratio = math.log(self.tracker.gate_threshold / self.min_threshold)
        return ratio / math.log(self.max_threshold / self.min_threshold)


for _env in (DGPTrackWindowEnv, DGPTrackGatingEnv):
    _env.__doc__ = _env.__doc__.replace("{reward}", _REWARD_DOC)
