"""Running policies over seeds for the evaluation scripts: trained agents (loaded from the
folders :func:`agents.rl.training.train_agent` writes), constant actions, random policies and
rules, one policy per worker process, each policy's episodes kept in a cache folder as it
finishes (``scripts/sensors_baselines.py``, ``scripts/tuning_baselines.py``)."""

from __future__ import annotations

import functools
import hashlib
import json
import os
from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import gymnasium as gym
import numpy as np

import agents
import baselines
import dgpt_gym
from agents.rl.clairvoyant import GreedyClairvoyantPolicy
from agents.rl.evaluation import ConstantPolicy, ModelPolicy, RandomPolicy, run_policy_episode
from agents.rl.training import load_agent

__all__ = [
    "AGENT_FILES",
    "make_policy",
    "check_agent_folders",
    "run_policies",
    "best_fixed_setting",
    "tune_rules",
    "cached_json",
    "source_digest",
    "code_digest",
]

SOURCE_SUFFIXES = (".py", ".json", ".csv")
"""The files of a package whose change can change an episode: code and the data it reads
(tuned windows, the paper's tables)."""

AGENT_FILES = ("model.zip", "config.json", "vecnormalize.pkl")
"""What :func:`agents.rl.training.train_agent` saves of an agent (the last one only with
``VecNormalize``), the files that key an agent's cached episodes."""


def make_policy(kind: str, setting, env: gym.Env, seed: int, rules: dict | None = None):
    """A policy from a picklable description: ``kind`` ``"agent"`` (``setting`` the folder
    :func:`agents.rl.training.train_agent` wrote), ``"constant"`` (``setting`` the action),
    ``"random"`` (seeded with ``seed``), ``"clairvoyant"`` (the greedy one of
    :mod:`agents.rl.clairvoyant`; ``setting`` the action it keeps among ties, or None), or a key of ``rules`` (a policy class
    called with the ``setting`` dict as keyword arguments, through its
    ``from_env(env, **setting)`` where it has one, which takes ``env``'s settings too, such
    as its sensing range)."""
    if kind == "agent":
        model, config = load_agent(setting)
        return ModelPolicy(model, config["normalizer"])
    if kind == "constant":
        return ConstantPolicy(setting)
    if kind == "random":
        return RandomPolicy(env.action_space, seed=seed)
    if kind == "clairvoyant":
        return GreedyClairvoyantPolicy(env, prefer=setting)
    if rules is None or kind not in rules:
        allowed = ["agent", "constant", "random", "clairvoyant", *(rules or {})]
        raise ValueError(f"kind must be one of {allowed}; got {kind!r}")
    rule = rules[kind]
    return rule.from_env(env, **setting) if hasattr(rule, "from_env") else rule(**setting)


def check_agent_folders(folders: Iterable[str | Path], env_id: str, env_kwargs: dict) -> None:
    """``ValueError`` naming the first folder that is not an agent saved by
    :func:`agents.rl.training.train_agent` for ``env_id`` with exactly ``env_kwargs``, or
    the first name two folders share: the reports label an agent's rows by its folder's
    name, so one agent's rows would replace the other's."""
    folders = [Path(folder) for folder in folders]
    seen = {}
    for folder in folders:
        if folder.name in seen:
            raise ValueError(
                f"{seen[folder.name]} and {folder} have the same name, which labels an "
                "agent's rows; give each agent a folder of its own name"
            )
        seen[folder.name] = folder
    for folder in folders:
        config_path = folder / "config.json"
        if not config_path.is_file() or not (folder / "model.zip").is_file():
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


def source_digest(roots: Iterable[Path]) -> str:
    """SHA-256 over the files under ``roots`` whose names end in :data:`SOURCE_SUFFIXES`,
    each with its path relative to its root, in sorted order."""
    digest = hashlib.sha256()
    for root in roots:
        root = Path(root)
        paths = sorted(
            path
            for path in root.rglob("*")
            if path.suffix in SOURCE_SUFFIXES and "__pycache__" not in path.parts
        )
        for path in paths:
            name = f"{root.name}/{path.relative_to(root).as_posix()}"
            digest.update(name.encode() + b"\0" + hashlib.sha256(path.read_bytes()).digest())
    return digest.hexdigest()


@functools.cache
def code_digest() -> str:
    """:func:`source_digest` of the packages an episode runs (the environments, the
    trackers, the baselines), once per process."""
    return source_digest(Path(package.__file__).parent for package in (agents, baselines, dgpt_gym))


def _cache_file(cache: Path, task) -> Path:
    """Where a task's rows are kept: named by a hash of the code (:func:`code_digest`, so
    that an edit to a tracker or an environment cannot return stale rows), the policy (an
    agent by the bytes of its saved files), the environment and the seeds."""
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
        [code_digest(), kind, setting, env_id, env_kwargs, seeds],
        sort_keys=True,
        default=str,
    )
    return cache / f"{kind}-{hashlib.sha256(key.encode()).hexdigest()[:20]}.json"


def _run_cached(task_and_cache) -> list[dict]:
    """:func:`_run_block`, its rows read from or written to the cache folder if one is given."""
    task, cache = task_and_cache
    if cache is None:
        return _run_block(task)
    return cached_json(_cache_file(cache, task), lambda: _run_block(task))


def cached_json(path: Path, compute):
    """The JSON value kept at ``path``, or ``compute()``'s, written there first through a
    temporary file, so that a run interrupted while writing leaves no half file."""
    if path.exists():
        return json.loads(path.read_text())
    value = compute()
    temporary = path.with_suffix(".tmp")
    temporary.write_text(json.dumps(value))
    temporary.replace(path)
    return value


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
    later call with the same code (:func:`code_digest`), policy, environment and seeds, so
    an interrupted run
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


def best_fixed_setting(
    env_id: str,
    env_kwargs: dict,
    seeds: Iterable[int],
    workers: int | None = None,
    cache: str | Path | None = None,
) -> tuple[str, dict[str, float]]:
    """The name of the environment's fixed setting (``fixed_actions()`` of
    :class:`agents.rl.base.TrackerInsideEnv`) with the best mean return on ``seeds`` (give
    training seeds), and every setting's mean return, by :func:`run_policies`."""
    env = gym.make(env_id, **env_kwargs)
    settings, _ = env.unwrapped.fixed_actions()
    env.close()
    results = run_policies(
        [("constant", action) for action in settings.values()],
        env_id,
        env_kwargs,
        seeds,
        workers,
        cache=cache,
    )
    scores = {
        name: float(np.mean([row["return"] for row in rows]))
        for name, rows in zip(settings, results)
    }
    return max(scores, key=scores.get), scores


def tune_rules(
    grids: dict[str, list[dict]],
    env_id: str,
    env_kwargs: dict,
    seeds: Iterable[int],
    workers: int | None = None,
    rules: dict | None = None,
    cache: str | Path | None = None,
) -> tuple[dict[str, tuple[dict, float]], list[tuple[str, dict, float]]]:
    """Each rule's setting with the best mean return on ``seeds`` (give training seeds):
    ``{kind: (setting, mean return)}`` over ``grids`` (``{kind: [setting, ...]}``, the
    ``rules``' keyword arguments), and every ``(kind, setting, mean return)`` in grid order,
    by :func:`run_policies`."""
    tuning = [(kind, setting) for kind, grid in grids.items() for setting in grid]
    results = run_policies(tuning, env_id, env_kwargs, seeds, workers, rules, cache)
    best, scores = {}, []
    for (kind, setting), rows in zip(tuning, results):
        score = float(np.mean([row["return"] for row in rows]))
        scores.append((kind, setting, score))
        if kind not in best or score > best[kind][1]:
            best[kind] = (setting, score)
    return best, scores
