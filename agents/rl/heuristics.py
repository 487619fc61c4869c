"""Adaptive rules for ``DGPTrackSensors-v1`` that read only the observation, the baselines a
learned agent has to beat (:mod:`agents.rl.sensors_v1` documents the observation)."""

from __future__ import annotations

import numpy as np

from agents.rl.sensors_v1 import OBSERVED_CANDIDATES, WAKE_COUNTS, decode_observation

__all__ = ["UncertaintyRadiusPolicy", "SilenceSearchPolicy", "level_for", "HEURISTIC_GRIDS"]

_COUNTS = np.array([np.inf if count is None else count for count in WAKE_COUNTS])


def level_for(count: int) -> int:
    """The action waking the fewest sensors that still wakes at least ``count``."""
    return int(np.searchsorted(_COUNTS, count))


class UncertaintyRadiusPolicy:
    """Wake the charged sensors within ``range + k sigma`` of the prediction (sigma its
    larger predictive standard deviation), at least one; beyond the 16 observed sensors it
    counts with the observation's r + 2 sigma count."""

    def __init__(self, k: float, sensing_range: float = 50.0) -> None:
        self.k, self.sensing_range = float(k), float(sensing_range)

    @classmethod
    def from_env(cls, env, **setting) -> UncertaintyRadiusPolicy:
        """The rule for ``env``'s sensing range."""
        return cls(**setting, sensing_range=env.unwrapped.inner.sensing_range)

    def predict(self, observation):
        seen = decode_observation(observation)
        radius = (self.sensing_range + self.k * seen.sigma) / self.sensing_range
        count = int(np.sum(seen.distances <= radius))
        if count == OBSERVED_CANDIDATES and self.k >= 2.0:
            count = max(count, int(round(seen.within_reach)))
        return level_for(max(count, 1))


class SilenceSearchPolicy:
    """Wake the nearest ``n``; after ``silent`` steps in a row without a report, wake every
    charged sensor (search) until one reports again."""

    def __init__(self, n: int, silent: int) -> None:
        self.n, self.silent = int(n), int(silent)

    def predict(self, observation):
        if decode_observation(observation).silent_steps >= self.silent:
            return len(WAKE_COUNTS) - 1
        return level_for(self.n)


HEURISTIC_GRIDS = {
    "uncertainty radius": [{"k": k} for k in (0.0, 0.5, 1.0, 2.0, 3.0)],
    "silence search": [{"n": n, "silent": s} for n in (2, 4, 8) for s in (1, 2, 4)],
}
"""The settings each rule is tuned over on training seeds."""
