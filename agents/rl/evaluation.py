"""Baseline policies of the RL environments and their evaluation on held-out seeds.

A policy is anything with ``predict(observation) -> action``; trained Stable-Baselines3
models are wrapped by :class:`ModelPolicy`. :func:`evaluate_policy_on_seeds` runs one
episode per seed (``reset(seed=s)``), so every policy meets the same measurements;
:func:`run_policies` does that for several policies in worker processes.

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

import hashlib
import json
import os
from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

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
    "make_policy",
    "check_agent_folders",
    "run_policies",
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
        if values.size > 1:
            sem = values.std(ddof=1) / np.sqrt(values.size)
            summary[f"{key}_ci"] = float(sem * stats.t.ppf(0.5 + confidence / 2, values.size - 1))
        else:
            summary[f"{key}_ci"] = float("nan")
    return summary


def make_policy(kind: str, setting, env: gym.Env, seed: int, rules: dict | None = None):
    """A policy from a picklable description: ``kind`` ``"agent"`` (``setting`` the folder
    :func:`agents.rl.training.train_agent` wrote), ``"constant"`` (``setting`` the action),
    ``"random"`` (seeded with ``seed``), or a key of ``rules`` (a policy class called with
    the ``setting`` dict as keyword arguments)."""
    if kind == "agent":
        from agents.rl.training import load_agent

        model, config = load_agent(setting)
        return ModelPolicy(model, config["normalizer"])
    if kind == "constant":
        return ConstantPolicy(setting)
    if kind == "random":
        return RandomPolicy(env.action_space, seed=seed)
    if rules is None or kind not in rules:
        allowed = ["agent", "constant", "random", *(rules or {})]
        raise ValueError(f"kind must be one of {allowed}; got {kind!r}")
    return rules[kind](**setting)


def check_agent_folders(folders: Iterable[str | Path], env_id: str, env_kwargs: dict) -> None:
    """``ValueError`` naming the first folder that is not an agent saved by
    :func:`agents.rl.training.train_agent` for ``env_id`` with exactly ``env_kwargs``."""
    for folder in folders:
        config_path = Path(folder) / "config.json"
        if not config_path.is_file() or not (Path(folder) / "model.zip").is_file():
            raise ValueError(
                f"{folder} is not a trained agent's folder (it needs model.zip and config.json, "
                "as scripts/train_rl.py writes them)"
            )
        config = json.loads(config_path.read_text())
        if config.get("env") != env_id or config.get("env_kwargs") != env_kwargs:
            raise ValueError(
                f"{folder} was trained on {config.get('env')} {config.get('env_kwargs')}, "
                f"not {env_id} {env_kwargs}"
            )


def _run_block(task) -> list[dict]:
    """Episodes of one policy on some seeds (a worker's unit): an agent is loaded once, a
    random policy or rule is made afresh for each seed (the random one seeded with it)."""
    kind, setting, env_id, env_kwargs, seeds, rules = task
    env = gym.make(env_id, **env_kwargs)
    agent = make_policy(kind, setting, env, seeds[0]) if kind == "agent" else None
    rows = []
    for seed in seeds:
        policy = agent or make_policy(kind, setting, env, seed, rules)
        rows.append(run_policy_episode(env, policy, seed))
    env.close()
    return rows


AGENT_FILES = ("model.zip", "config.json", "vecnormalize.pkl")
"""What :func:`agents.rl.training.train_agent` saves of an agent (the last one only with
``VecNormalize``), the files that key an agent's cached episodes."""


def _cache_file(cache: Path, task) -> Path:
    """Where a task's rows are kept: named by a hash of the package version, the policy
    (an agent by the bytes of its saved files), the environment and the seeds. Code changes
    within a version are not in the key: clear the folder after one."""
    import dgpt_gym

    kind, setting, env_id, env_kwargs, seeds, _ = task
    if kind == "agent":
        digest = hashlib.sha256()
        for name in AGENT_FILES:
            path = Path(setting) / name
            if path.is_file():
                digest.update(hashlib.sha256(path.read_bytes()).digest() + name.encode())
        setting = digest.hexdigest()
    elif isinstance(setting, np.ndarray):
        setting = setting.tolist()
    key = json.dumps(
        [dgpt_gym.__version__, kind, setting, env_id, env_kwargs, seeds],
        sort_keys=True,
        default=str,
    )
    return cache / f"{kind}-{hashlib.sha256(key.encode()).hexdigest()[:20]}.json"


def _run_cached(task_and_cache) -> list[dict]:
    """:func:`_run_block`, its rows read from or written to the cache folder if one is given."""
    task, cache = task_and_cache
    if cache is None:
        return _run_block(task)
    path = _cache_file(cache, task)
    if path.exists():
        return json.loads(path.read_text())
    rows = _run_block(task)
    temporary = path.with_suffix(".tmp")
    temporary.write_text(json.dumps(rows))
    temporary.replace(path)  # a run interrupted while writing leaves no half file
    return rows


def run_policies(
    policies: list[tuple[str, object]],
    env_id: str,
    env_kwargs: dict,
    seeds: Iterable[int],
    workers: int | None = None,
    rules: dict | None = None,
    cache: str | Path | None = None,
) -> list[list[dict]]:
    """:func:`run_policy_episode` rows of every policy (``(kind, setting)`` as
    :func:`make_policy` takes them) on every seed, one list per policy in order; a process
    pool of ``workers`` (default: the CPU count; 1 runs here) takes one policy each. With a
    ``cache`` folder each policy's rows are kept there as they finish and read back by a
    later call with the same version, policy, environment and seeds, so an interrupted run
    loses no finished policy."""
    seeds = [int(seed) for seed in seeds]
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be a positive integer or None; got {workers!r}")
    if cache is not None:
        cache = Path(cache)
        cache.mkdir(parents=True, exist_ok=True)
    tasks = [
        ((kind, setting, env_id, env_kwargs, seeds, rules), cache) for kind, setting in policies
    ]
    workers = workers or os.cpu_count() or 1
    if workers == 1:
        return [_run_cached(task) for task in tasks]
    with ProcessPoolExecutor(workers) as pool:
        return list(pool.map(_run_cached, tasks))


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


def paired_interval(differences: np.ndarray) -> tuple[float, float]:
    """Mean of paired differences and the half-width of its Student-t 95 % interval."""
    sem = differences.std(ddof=1) / np.sqrt(differences.size)
    return float(differences.mean()), float(sem * stats.t.ppf(0.975, differences.size - 1))


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
        knob = _per_seed(by_name, agents, "per_step").mean(axis=0)
        difference, half = paired_interval(knob - _per_seed(by_name, [other], "per_step")[0])
        cells.append(f"{difference:+.{digits}f} +- {half:.{digits}f}")
        lines.append(f"| {other} | {' | '.join(cells)} |")
    return lines
