"""Adaptive rules for the tuning tasks (``DGPTrackGating-v0``, ``DGPTrackWindow-v0``) that
read only the observation (:data:`agents.rl.features.FEATURE_NAMES`), the baselines a learned
agent has to beat beside the fixed settings.

Both switch between two settings on the last step's surprise: the mean distance of the
gated summaries from their predictions (``innovation``). The greedy clairvoyant policy
(:mod:`agents.rl.clairvoyant`) gains by tight gates and by leaving C = 3 on many steps; these
rules test the simplest observable reading of that: a tight gate while the track is quiet
(the prediction was right last step), and a window chosen by the last surprise.
"""

from __future__ import annotations

import math

import numpy as np

from agents.rl.features import decode_features
from agents.rl.tuning_envs import DEFAULT_WINDOWS
from dgpt_gym.validation import check_choice, check_real

__all__ = ["QuietTrackGatePolicy", "SurpriseWindowPolicy", "TUNING_RULES", "TUNING_RULE_GRIDS"]


def _quiet(observation, quiet_m: float, sensing_range: float) -> bool:
    """The tracker has experts, the last step had gated summaries (measurements that the
    hard gate did not all drop: the innovation is then above zero), and they lay within
    ``quiet_m`` of the predictions on average."""
    seen = decode_features(observation)
    surprise_m = seen.innovation * sensing_range
    return bool(seen.n_experts > 0 and seen.silent_steps == 0 and 0.0 < surprise_m < quiet_m)


class QuietTrackGatePolicy:
    """``DGPTrackGating-v0``: the gate threshold ``tight`` while the track is quiet (the last
    step had gated summaries and they lay within ``quiet_m`` metres of their predictions on
    average), else ``loose``: after a silent step, and after a step whose measurements the
    gate dropped entirely. Thresholds are Mahalanobis distances, mapped to the
    action as the environment maps it back (its range, 1-30 by default, which ``from_env``
    takes from the environment)."""

    def __init__(
        self,
        tight: float,
        quiet_m: float,
        loose: float,
        min_threshold: float = 1.0,
        max_threshold: float = 30.0,
        sensing_range: float = 50.0,
    ) -> None:
        min_threshold = check_real("min_threshold", min_threshold, low=0.0, low_inclusive=False)
        max_threshold = check_real("max_threshold", max_threshold, low=min_threshold)
        loose = check_real("loose", loose, low=min_threshold, high=max_threshold)
        tight = check_real("tight", tight, low=min_threshold, high=loose, high_inclusive=False)
        quiet_m = check_real("quiet_m", quiet_m, low=0.0, low_inclusive=False)
        span = math.log(max_threshold / min_threshold)

        def action(threshold: float) -> np.ndarray:
            position = math.log(threshold / min_threshold) / span
            return np.array([2.0 * position - 1.0], dtype=np.float32)

        self.tight, self.loose = action(tight), action(loose)
        self.quiet_m, self.sensing_range = float(quiet_m), float(sensing_range)

    @classmethod
    def from_env(cls, env, **setting) -> QuietTrackGatePolicy:
        """The rule for ``env``'s threshold range and sensing range."""
        unwrapped = env.unwrapped
        return cls(
            **setting,
            min_threshold=unwrapped.min_threshold,
            max_threshold=unwrapped.max_threshold,
            sensing_range=unwrapped.inner.sensing_range,
        )

    def predict(self, observation):
        return self.tight if _quiet(observation, self.quiet_m, self.sensing_range) else self.loose


class SurpriseWindowPolicy:
    """``DGPTrackWindow-v0``: the window ``surprised`` after a step whose summaries lay more
    than ``surprise_m`` metres from their predictions on average (or without gated
    summaries), else ``quiet``; windows are lengths C of ``windows``."""

    def __init__(
        self,
        quiet: int,
        surprised: int,
        surprise_m: float,
        windows: tuple[int, ...] = DEFAULT_WINDOWS,
        sensing_range: float = 50.0,
    ) -> None:
        windows = tuple(windows)
        self.quiet = windows.index(check_choice("quiet", quiet, windows))
        self.surprised = windows.index(check_choice("surprised", surprised, windows))
        surprise_m = check_real("surprise_m", surprise_m, low=0.0, low_inclusive=False)
        self.surprise_m, self.sensing_range = float(surprise_m), float(sensing_range)

    @classmethod
    def from_env(cls, env, **setting) -> SurpriseWindowPolicy:
        """The rule for ``env``'s windows and sensing range."""
        unwrapped = env.unwrapped
        return cls(
            **setting, windows=unwrapped.windows, sensing_range=unwrapped.inner.sensing_range
        )

    def predict(self, observation):
        quiet = _quiet(observation, self.surprise_m, self.sensing_range)
        return self.quiet if quiet else self.surprised


TUNING_RULES = {"quiet-track gate": QuietTrackGatePolicy, "surprise window": SurpriseWindowPolicy}
"""The rules by name, as :func:`agents.rl.runs.run_policies` takes them (each made for its
environment by its ``from_env``)."""

TUNING_RULE_GRIDS = {
    "DGPTrackGating-v0": {
        "quiet-track gate": [
            {"tight": tight, "quiet_m": quiet, "loose": loose}
            for tight in (1.53, 2.34, 3.58)
            for quiet in (1.0, 2.0, 4.0)
            for loose in (8.38, 30.0)
        ]
    },
    "DGPTrackWindow-v0": {
        "surprise window": [
            {"quiet": quiet, "surprised": surprised, "surprise_m": surprise}
            for quiet, surprised in ((2, 3), (3, 2), (3, 4))
            for surprise in (2.0, 5.0, 10.0)
        ]
    },
}
"""The settings each task's rule is tuned over on training seeds (thresholds of the
environment's fixed grid; windows next to the best fixed C = 3)."""
