"""Baseline policies of the RL environments and their evaluation on held-out seeds.

A policy is anything with ``predict(observation) -> action``; trained Stable-Baselines3
models are wrapped by :class:`ModelPolicy`. :func:`evaluate_policy_on_seeds` runs one
episode per seed (``reset(seed=s)``), so every policy meets the same measurements.
"""

from __future__ import annotations

from collections.abc import Iterable

import gymnasium as gym
import numpy as np
from scipy import stats

from agents.rl.base import TrackerInsideEnv
from dgpt_gym.benchmark import metrics
from dgpt_gym.benchmark.protocol import TRAINING_SEEDS

__all__ = [
    "ConstantPolicy",
    "RandomPolicy",
    "ModelPolicy",
    "baseline_policies",
    "run_policy_episode",
    "evaluate_policy_on_seeds",
    "summarize_episodes",
    "TRAINING_SEEDS",
    "EVALUATION_SEEDS",
]

EVALUATION_SEEDS = range(0, 20)
"""Held-out seeds: no training episode uses them (training envs are seeded from 10_000)."""


class ConstantPolicy:
    """The same action every step (a fixed window, threshold or set of woken sensors)."""

    def __init__(self, action) -> None:
        self.action = action

    def predict(self, observation):
        return self.action


class RandomPolicy:
    """Uniform random actions from the action space, seeded."""

    def __init__(self, action_space: gym.Space, seed: int = 0) -> None:
        self.action_space = action_space
        self.action_space.seed(seed)

    def predict(self, observation):
        return self.action_space.sample()


class ModelPolicy:
    """A Stable-Baselines3 model's deterministic action; ``normalizer`` (the training
    ``VecNormalize``, frozen) normalises the observation first, as in training."""

    def __init__(self, model, normalizer=None) -> None:
        self.model = model
        self.normalizer = normalizer

    def predict(self, observation):
        if self.normalizer is not None:
            observation = self.normalizer.normalize_obs(observation)
        action, _ = self.model.predict(observation, deterministic=True)
        return action


def baseline_policies(env: gym.Env) -> tuple[dict[str, object], str]:
    """The fixed baselines of an RL environment as policies: ``{name: policy}`` (the grid the
    best fixed baseline is searched in) and the name of the default one, from the
    environment's ``fixed_actions()`` (:class:`agents.rl.base.TrackerInsideEnv`)."""
    inner = env.unwrapped
    if not isinstance(inner, TrackerInsideEnv):
        raise ValueError(
            f"env must be one of the RL environments of agents.rl; got {type(inner)!r}"
        )
    actions, default = inner.fixed_actions()
    return {name: ConstantPolicy(action) for name, action in actions.items()}, default


def run_policy_episode(env: gym.Env, policy, seed: int) -> dict[str, float]:
    """One episode of ``policy``: its return, NRMSE per axis (paper Sec. VII-E), mean error
    (m), and the mean per step of the knob it set (``env.unwrapped.knob``: window,
    threshold or sensors woken)."""
    observation, _ = env.reset(seed=seed)
    total, done = 0.0, False
    truth, estimates, knobs = [], [], []
    while not done:
        observation, reward, terminated, truncated, info = env.step(policy.predict(observation))
        total += reward
        done = terminated or truncated
        truth.append(info["position"])
        estimates.append(info["estimate"])
        knobs.append(info[env.unwrapped.knob])
    nrmse = metrics.nrmse(np.array(estimates), np.array(truth))
    return {
        "seed": seed,
        "return": total,
        "nrmse": float(np.mean(nrmse)),
        "nrmse_x": float(nrmse[0]),
        "nrmse_y": float(nrmse[1]),
        "mean_error": float(np.mean(np.linalg.norm(np.array(estimates) - truth, axis=1))),
        "per_step": float(np.mean(knobs)),
    }


def evaluate_policy_on_seeds(env: gym.Env, policy, seeds: Iterable[int]) -> list[dict]:
    """:func:`run_policy_episode` for every seed."""
    return [run_policy_episode(env, policy, int(seed)) for seed in seeds]


def summarize_episodes(episodes: list[dict], confidence: float = 0.95) -> dict[str, float]:
    """Mean and the half-width of a Student-t confidence interval of the return and NRMSE,
    and the mean per-step knob, over episodes."""
    summary = {"episodes": len(episodes)}
    for key in ("return", "nrmse", "per_step"):
        values = np.array([episode[key] for episode in episodes], dtype=float)
        summary[key] = float(values.mean())
        if values.size > 1:
            sem = values.std(ddof=1) / np.sqrt(values.size)
            summary[f"{key}_ci"] = float(sem * stats.t.ppf(0.5 + confidence / 2, values.size - 1))
        else:
            summary[f"{key}_ci"] = float("nan")
    return summary
