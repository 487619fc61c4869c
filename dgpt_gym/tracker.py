"""The tracker interface: :class:`Estimate`, the :class:`Tracker` protocol and
:class:`TrackerBase`, which gives every tracker Stable-Baselines3's ``predict`` contract."""

from __future__ import annotations

import abc
import copy
import inspect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from dgpt_gym.problem import ProblemSpec

__all__ = ["Estimate", "Tracker", "TrackerBase", "check_estimate", "check_reset_signature"]


@dataclass(frozen=True)
class Estimate:
    """A tracker's answer for one step.

    Attributes:
        mean: (2,) estimate of the target position p_t, m.
        var: (2,) latent predictive variance per axis, m^2.
        ucb: (2,) upper-confidence-bound half-width per axis (Theorems 1-3), or None.
        prior_next: (mean, var) of the predicted position at step t + 1, where the tracker
            has one (the hybrid filter's prior, eq. (48)), else None.
    """

    mean: np.ndarray
    var: np.ndarray
    ucb: np.ndarray | None = None
    prior_next: tuple[np.ndarray, np.ndarray] | None = None

    @classmethod
    def uninformed(cls, spec: ProblemSpec) -> Estimate:
        """The answer before any measurement: the area's centre, with the per-axis variance
        of a position uniform over the area (area^2 / 12)."""
        return cls(np.full(2, spec.area / 2.0), np.full(2, spec.area**2 / 12.0))


def check_estimate(estimate, tracker) -> None:
    """Raise a ``TypeError`` or ``ValueError`` that names ``tracker``'s ``update`` unless
    ``estimate`` is what the evaluation can score: an :class:`Estimate` whose ``mean`` is a
    finite (2,) position, whose ``var`` is a (2,) per-axis variance (not negative; NaN for a
    tracker that reports none: its calibration is left out), and whose ``ucb`` is None or a
    (2,) half-width that is not negative. Without this, a wrong shape fails later in the
    metrics, and a negative variance passes unnoticed. Called on every step of every
    episode, so it reads the two entries directly rather than through array reductions."""
    if not isinstance(estimate, Estimate):
        raise TypeError(
            f"{type(tracker).__name__}.update must return a dgpt_gym.tracker.Estimate"
            f"(mean, var, ucb=None); got {type(estimate).__name__}"
        )
    mean = _pair(estimate.mean)
    if mean is None or not (math.isfinite(mean[0]) and math.isfinite(mean[1])):
        _bad_estimate(tracker, "mean", "a finite (2,) position (x, y)", estimate.mean)
    var = _pair(estimate.var)
    if var is None or var[0] < 0 or var[1] < 0:
        _bad_estimate(tracker, "var", _NOT_NEGATIVE.format("per-axis variance"), estimate.var)
    if estimate.ucb is not None:
        ucb = _pair(estimate.ucb)
        if ucb is None or ucb[0] < 0 or ucb[1] < 0:
            what = _NOT_NEGATIVE.format("per-axis half-width") + " or None"
            _bad_estimate(tracker, "ucb", what, estimate.ucb)


_NOT_NEGATIVE = "a (2,) {}, not negative (NaN: none reported)"


def _pair(value) -> np.ndarray | None:
    """``value`` as a (2,) real array, or None when it is not one."""
    array = value if type(value) is np.ndarray else np.asarray(value)
    if array.shape != (2,) or array.dtype.kind not in "fiu":
        return None
    return array


def _bad_estimate(tracker, name: str, allowed: str, value) -> None:
    raise ValueError(
        f"{type(tracker).__name__}.update must return Estimate.{name} as {allowed}; got {value!r}"
    )


def check_reset_signature(tracker) -> None:
    """Raise a ``TypeError`` naming ``tracker``'s ``reset`` unless it takes the call the
    evaluation makes, ``reset(spec, seed=seed)`` (and ``truth=`` for a reset that has it: an
    oracle's). A ``reset`` without a signature to read (compiled code) is not checked."""
    try:
        signature = inspect.signature(tracker.reset)
    except (TypeError, ValueError):
        return
    call = {"seed": 0}
    if "truth" in signature.parameters:
        call["truth"] = None
    try:
        signature.bind(None, **call)
    except TypeError as error:
        raise TypeError(
            f"{type(tracker).__name__}.reset must take reset(spec, seed=None): the "
            f"evaluation passes each episode's seed by keyword ({error})"
        ) from None


@runtime_checkable
class Tracker(Protocol):
    """What the evaluation loop and the RL wrappers need of a tracker."""

    name: str

    def reset(self, spec: ProblemSpec, seed: int | None = None) -> None:
        """Forget the last episode; ``spec`` describes the network and measurement model."""

    def update(self, obs: dict) -> Estimate:
        """Take the observation of step t (the env's dict; an optional ``"awake"`` boolean per
        sensor marks the sensors that could report, e.g. in the RL sensor task) and return
        the estimate of p_t."""

    def diagnostics(self) -> dict[str, float]:
        """Numbers the tracker reports about its own working over the episode so far (e.g.
        how often its fit ended on a bound), stored with the episode's metrics by the
        evaluation; none by default."""
        return {}

    def predict(self, obs, state=None, episode_start=None, deterministic: bool = True):
        """Stable-Baselines3's policy contract: returns ``(actions, state)``."""


class TrackerBase(abc.ABC):
    """Shared behaviour of the project's trackers.

    Subclasses implement :meth:`reset` and :meth:`update` and set ``name``. ``predict``
    follows Stable-Baselines3's policy contract, so
    ``stable_baselines3.common.evaluation.evaluate_policy(tracker, vec_env)`` runs any
    tracker: it takes a batch of observations (one per sub-environment), keeps one copy of
    the tracker per sub-environment, resets a copy when ``episode_start`` is set for it, and
    returns the batch of position estimates. Call :meth:`reset` with the environment's
    :class:`ProblemSpec` first (``info["problem_spec"]`` of ``env.reset()``); the copies
    inherit it.
    """

    name: str = "tracker"
    spec_: ProblemSpec | None = None

    @abc.abstractmethod
    def reset(self, spec: ProblemSpec, seed: int | None = None) -> None:
        """Forget the last episode; keep ``spec`` in ``self.spec_``."""

    @abc.abstractmethod
    def update(self, obs: dict) -> Estimate:
        """Take the observation of step t and return the estimate of p_t."""

    @classmethod
    def update_batch(cls, trackers: Sequence[TrackerBase], observations: Sequence[dict]) -> list:
        """One step of many episodes in lockstep: ``trackers[i].update(observations[i])``
        for every i (:func:`dgpt_gym.benchmark.episodes.run_episodes` calls this). A tracker class
        that can share work across episodes overrides it (:class:`agents.dgpt.DGPT`
        batches its learning and prediction); the estimates must equal the one-by-one ones."""
        return [tracker.update(obs) for tracker, obs in zip(trackers, observations)]

    def predict(self, obs, state=None, episode_start=None, deterministic: bool = True):
        if self.spec_ is None:
            raise RuntimeError(
                f"{type(self).__name__}.predict needs the problem: call "
                "tracker.reset(info['problem_spec']) with the env's reset info first"
            )
        batched = np.ndim(obs["measurements"]) == 3
        batch = obs if batched else {key: np.asarray(value)[None] for key, value in obs.items()}
        n_envs = len(batch["measurements"])
        if episode_start is None:
            episode_start = np.zeros(n_envs, dtype=bool)
        copies = self.__dict__.setdefault("_predict_copies", [])
        actions = np.empty((n_envs, 2))
        for index in range(n_envs):
            if index >= len(copies):
                copies.append(self._fresh_copy())
            elif episode_start[index]:
                copies[index] = self._fresh_copy()
            single = {key: np.asarray(value)[index] for key, value in batch.items()}
            actions[index] = copies[index].update(single).mean
        return (actions if batched else actions[0]), state

    def _fresh_copy(self) -> TrackerBase:
        copies = self.__dict__.pop("_predict_copies", None)
        try:
            clone = copy.deepcopy(self)
        finally:
            if copies is not None:
                self._predict_copies = copies
        clone.reset(self.spec_)
        return clone
