"""Baseline policies of the RL environments and their evaluation on held-out seeds.

A policy is anything with ``predict(observation) -> action``; trained Stable-Baselines3
models are wrapped by :class:`ModelPolicy`. :func:`evaluate_policy_on_seeds` runs one
episode per seed (``reset(seed=s)``), so every policy meets the same measurements
(:mod:`agents.rl.runs` does that for several policies, trained agents included, in worker
processes).

The statistics of the evaluation protocol (``scripts/sensors_baselines.py``,
``scripts/tuning_baselines.py``): the interquartile mean (IQM) of the episode returns with a
95 % percentile-bootstrap interval over seeds (the episodes of several trained agents pooled,
a seed's episodes resampled together: :func:`iqm_interval`); its paired difference between
policies on shared seeds (:func:`paired_iqm_difference`); and the Student-t interval of a
mean paired difference (:func:`paired_interval`). ``scipy.stats.bootstrap`` of the
25 %-trimmed mean gives these without another dependency. The rliable library's IQM is
over training runs' scores, each a run's mean over its episodes, with runs resampled within
each task; with five runs on one task that is an IQM of five numbers, so the episodes are
pooled here instead, and each agent also has its own row.
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
    "policy_cells",
    "agents_against",
    "iqm_interval",
    "paired_iqm_difference",
    "paired_interval",
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
        summary[f"{key}_ci"] = (
            paired_interval(values, confidence)[1] if values.size > 1 else float("nan")
        )
    return summary


def iqm_interval(*samples: np.ndarray, seed: int = 0) -> tuple[float, float, float]:
    """Interquartile mean of the pooled ``samples`` and its 95 % percentile-bootstrap
    interval (2000 resamples). Several samples are the episodes of several trained agents
    on the same seeds, in the same order: a resample draws seeds and takes every agent's
    episode on each, because the agents' returns on a seed go together (a hard path is hard
    for all of them), so their episodes are not independent draws. The interval is that of
    these agents over seeds; it leaves out the variation between training runs, which the
    agents' own rows show."""

    def pooled_iqm(*resampled, axis=-1):
        return stats.trim_mean(np.concatenate(resampled, axis=axis), 0.25, axis=axis)

    if len({sample.shape for sample in samples}) > 1:
        raise ValueError(
            f"samples must be the same seeds' returns; got shapes {[x.shape for x in samples]}"
        )
    result = stats.bootstrap(
        samples,
        pooled_iqm,
        paired=len(samples) > 1,
        n_resamples=2000,
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    interval = result.confidence_interval
    return float(pooled_iqm(*samples)), float(interval.low), float(interval.high)


def paired_iqm_difference(agents: np.ndarray, reference: np.ndarray, seed: int = 0):
    """IQM of the agents' returns (n_agents, n_seeds) minus the IQM of a reference policy's
    (n_seeds,) on the same seeds, with a 95 % percentile-bootstrap interval that resamples
    the seeds (the same ones for every agent and the reference: paired). Returns
    (difference, low, high)."""

    def difference(*resampled, axis=-1):
        pooled = np.concatenate(resampled[:-1], axis=axis)
        return stats.trim_mean(pooled, 0.25, axis=axis) - stats.trim_mean(
            resampled[-1], 0.25, axis=axis
        )

    result = stats.bootstrap(
        (*agents, reference),
        difference,
        paired=True,
        n_resamples=2000,
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    interval = result.confidence_interval
    return float(difference(*agents, reference)), float(interval.low), float(interval.high)


def paired_interval(differences: np.ndarray, confidence: float = 0.95) -> tuple[float, float]:
    """Mean of paired differences (or of any sample) and the half-width of its Student-t
    interval at ``confidence``."""
    sem = differences.std(ddof=1) / np.sqrt(differences.size)
    half = sem * stats.t.ppf(0.5 + confidence / 2, differences.size - 1)
    return float(differences.mean()), float(half)


def _per_seed(by_name: dict, names: list[str], key: str) -> np.ndarray:
    """``key`` of every episode of the policies ``names``: (len(names), n_seeds)."""
    return np.array([[row[key] for row in by_name[name]] for name in names], dtype=float)


def policy_cells(
    by_name: dict,
    names: list[str],
    reference: np.ndarray,
    digits: int = 1,
    knob_digits: int = 1,
    is_reference: bool = False,
) -> str:
    """Markdown cells of one policy (``names`` of one) or of several trained agents
    together (their episodes pooled): the IQM return with its 95 % bootstrap interval
    over seeds (:func:`iqm_interval`), the mean return, the NRMSE (%), the mean
    knob per step, and the mean per-seed return minus ``reference``'s (the reference
    policy's returns on the same seeds) with its t interval ("-" for the reference itself,
    ``is_reference``). ``by_name`` maps a policy's name to its
    :func:`run_policy_episode` rows, seeds in the same order for every policy."""
    returns = _per_seed(by_name, names, "return")
    iqm, low, high = iqm_interval(*returns)
    if is_reference:
        paired = "-"
    else:
        difference, half = paired_interval(returns.mean(axis=0) - reference)
        paired = f"{difference:+.{digits}f} +- {half:.{digits}f}"
    nrmse = 100 * _per_seed(by_name, names, "nrmse").mean()
    knob = _per_seed(by_name, names, "per_step").mean()
    return (
        f"{iqm:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}] | {returns.mean():.{digits}f} | "
        f"{nrmse:.2f} | {knob:.{knob_digits}f} | {paired}"
    )


def agents_against(
    by_name: dict,
    agents: list[str],
    others: list[str],
    knob_label: str,
    what: str = "policy",
    digits: int = 1,
) -> list[str]:
    """Markdown table lines: the trained ``agents`` together against each of ``others``,
    paired by seed: the IQM of the agents' returns minus the other's with a 95 % bootstrap
    interval over seeds (:func:`paired_iqm_difference`); the difference of the mean return
    with two 95 % t intervals, over seeds (the agents' mean per seed: how sure the
    comparison is for these agents) and, with two agents or more, over agents (each agent's
    mean difference: how much it varies from one training run to another); and the
    difference of the knob per step (``knob_label``) over seeds. ``what`` names the others
    in the header."""
    returns = _per_seed(by_name, agents, "return")
    knob = _per_seed(by_name, agents, "per_step").mean(axis=0)
    over_agents = len(agents) > 1
    lines = [
        f"| {what} | IQM return: agents - {what} [95 % CI] | mean return: agents - {what}, "
        "t over seeds | "
        + (f"the same, t over the {len(agents)} agents | " if over_agents else "")
        + f"{knob_label}: agents - {what} |",
        "|---|---|---|---|" + ("---|" if over_agents else ""),
    ]
    for other in others:
        reference = _per_seed(by_name, [other], "return")[0]
        iqm, low, high = paired_iqm_difference(returns, reference)
        cells = [f"{iqm:+.{digits}f} [{low:+.{digits}f}, {high:+.{digits}f}]"]
        difference, half = paired_interval(returns.mean(axis=0) - reference)
        cells.append(f"{difference:+.{digits}f} +- {half:.{digits}f}")
        if over_agents:
            difference, half = paired_interval((returns - reference).mean(axis=1))
            cells.append(f"{difference:+.{digits}f} +- {half:.{digits}f}")
        difference, half = paired_interval(knob - _per_seed(by_name, [other], "per_step")[0])
        cells.append(f"{difference:+.{digits}f} +- {half:.{digits}f}")
        lines.append(f"| {other} | {' | '.join(cells)} |")
    return lines
