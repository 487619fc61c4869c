"""Clairvoyant references for the tuning tasks: what adapting the knob could gain, measured
with the truth that no agent sees.

Two references, each with hindsight that no agent has:

- :class:`GreedyClairvoyantPolicy` tries every action of the step on copies of the
  environment (the same measurements and random draws) and takes the one whose step scores
  best: adaptation step by step, knowing that step's error. It is greedy: a choice whose
  gain comes in later steps is not seen (the SE DGPT's fit is warm-started from the
  previous step's and its gate uses the previous step's model, so a step's window or
  threshold reaches a little into the next ones).
- :func:`hindsight_best_per_seed` takes, seed by seed, the fixed setting whose episode
  scored best: one setting per episode, chosen knowing the whole episode.

How much they beat the best fixed setting shows what adapting the knob could gain. Both
overstate it by luck (with hindsight among k actions, one that was best by chance counts
as gain); the greedy one understates it by the later effects it ignores. If neither beats
the best fixed setting by much, a learned policy has little to find, whatever it
observes; if they do, an agent that falls short falls short in its learning.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence

import gymnasium as gym
import numpy as np

from agents.rl.base import TrackerInsideEnv

__all__ = ["GreedyClairvoyantPolicy", "hindsight_best_per_seed"]


class GreedyClairvoyantPolicy:
    """Each step, the candidate action with the best reward in this step, found by stepping
    a deep copy of ``env``'s unwrapped environment once per candidate (the copy holds the
    environment's and the tracker's random generators, so every copy meets the same
    measurements and draws as the real step will). The candidates are ``actions``, by
    default the environment's fixed settings (``fixed_actions()`` of
    :class:`agents.rl.base.TrackerInsideEnv`: every window length, or nine gate
    thresholds), the grid the best fixed setting is chosen from. Among candidates that tie
    for the best reward (a step without measurements, where no window or gate changes the
    estimate) it takes the one nearest ``prefer`` in candidate order (give the best fixed
    setting, so that the policy leaves it only where another setting scores strictly
    better, and no further than the tie needs), else the first. Costs one extra step and
    copy per candidate and step; ``env`` must not render (each copy would draw)."""

    def __init__(self, env: gym.Env, actions: Sequence | None = None, prefer=None) -> None:
        self.env = env.unwrapped
        if getattr(self.env, "render_mode", None) is not None:
            raise ValueError(
                "env must not render (render_mode None): every candidate's copy would draw; "
                f"got render_mode={self.env.render_mode!r}"
            )
        if actions is None:
            if not isinstance(self.env, TrackerInsideEnv):
                raise ValueError(
                    "actions must be given for an environment without fixed_actions() "
                    f"(not one of agents.rl's); got env {type(self.env).__name__}"
                )
            actions = list(self.env.fixed_actions()[0].values())
        self.actions = list(actions)
        if not self.actions:
            raise ValueError("actions must hold at least one candidate action; got none")
        self.preferred = None
        if prefer is not None:
            matches = [i for i, action in enumerate(self.actions) if np.array_equal(action, prefer)]
            if not matches:
                raise ValueError(
                    f"prefer must be one of the candidate actions {self.actions}; got {prefer!r}"
                )
            self.preferred = matches[0]
        self.last_rewards = None

    def predict(self, observation):
        rewards = np.array(
            [copy.deepcopy(self.env).step(action)[1] for action in self.actions], dtype=float
        )
        self.last_rewards = rewards
        tied = np.flatnonzero(rewards == rewards.max())
        best = int(tied[0])
        if self.preferred is not None:
            best = int(tied[np.argmin(np.abs(tied - self.preferred))])
        return self.actions[best]


def hindsight_best_per_seed(rows_by_setting: dict[str, list[dict]]) -> list[dict]:
    """Seed by seed, the row (a :func:`agents.rl.evaluation.run_policy_episode` row) of the
    setting with the highest return; ``rows_by_setting`` maps each fixed setting's name to
    its rows, seeds in the same order for every setting. Each returned row gains
    ``"setting"``, the chosen setting's name; ties go to the first setting."""
    names = list(rows_by_setting)
    if not names:
        raise ValueError("rows_by_setting must name at least one setting; got {}")
    lengths = {len(rows) for rows in rows_by_setting.values()}
    if len(lengths) != 1:
        raise ValueError(f"every setting needs the same seeds; got row counts {sorted(lengths)}")
    chosen = []
    for per_setting in zip(*(rows_by_setting[name] for name in names)):
        seeds = {row["seed"] for row in per_setting}
        if len(seeds) != 1:
            raise ValueError(f"the settings' rows must be on the same seed; got seeds {seeds}")
        best = int(np.argmax([row["return"] for row in per_setting]))
        chosen.append({**per_setting[best], "setting": names[best]})
    return chosen
