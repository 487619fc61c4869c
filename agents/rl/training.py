"""Train a Stable-Baselines3 agent on an RL environment and compare it with the baselines.

:func:`train_agent` trains (with a progress bar, optional TensorBoard), saves the model and
its configuration; :func:`compare_with_baselines` searches the best fixed baseline on the
training seeds and evaluates the agent, the baselines and a random policy on held-out seeds;
:func:`plot_learning_curve` draws the training returns from the Monitor logs.
"""

from __future__ import annotations

import csv
import importlib.util
import inspect
import json
import pickle
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np
from threadpoolctl import threadpool_limits

from agents.rl.evaluation import (
    EVALUATION_SEEDS,
    TRAINING_SEEDS,
    ModelPolicy,
    RandomPolicy,
    baseline_policies,
    evaluate_policy_on_seeds,
    summarize_episodes,
)
from agents.rl.process_blocks import process_blocks_vec_env
from agents.rl.registration import ENVIRONMENTS
from agents.rl.vector import stable_baselines_vec_env
from dgpt_gym.benchmark.plots import new_figure, save_figure
from dgpt_gym.validation import check_bool, check_choice, check_integer

__all__ = [
    "ALGORITHMS",
    "RL_ENV_IDS",
    "check_algo_kwargs",
    "TRAINING_ENV_SEED",
    "train_agent",
    "compare_with_baselines",
    "comparison_markdown",
    "plot_learning_curve",
    "load_agent",
]

RL_ENV_IDS = tuple(environment.id for environment in ENVIRONMENTS)
ALGORITHMS = ("ppo", "a2c", "dqn")
TRAINING_ENV_SEED = 10_000
"""Training environments are seeded from here: far from the evaluation seeds."""

NORMALIZATION_FILE = "vecnormalize.pkl"
"""The ``VecNormalize`` statistics saved beside ``model.zip``."""


def _algorithm_class(algo: str):
    import stable_baselines3

    return getattr(stable_baselines3, algo.upper())


def check_algo_kwargs(algorithm, algo_kwargs: dict | None) -> dict:
    """``algo_kwargs`` checked against the constructor of the SB3 ``algorithm``: every name
    must be one of its parameters, and a value whose default is a number must be a number
    (a bool where the default is a bool). ``ValueError`` naming the argument otherwise."""
    algo_kwargs = dict(algo_kwargs or {})
    parameters = inspect.signature(algorithm.__init__).parameters
    taken = {"self", "policy", "env", "seed", "verbose", "tensorboard_log"}  # set by train_agent
    allowed = sorted(n for n in parameters if n not in taken and not n.startswith("_"))
    for name, value in algo_kwargs.items():
        if name not in allowed:
            raise ValueError(
                f"algo_kwargs has {name!r}, which {algorithm.__name__} does not take; "
                f"allowed: {allowed}"
            )
        default = parameters[name].default
        if isinstance(default, bool):
            check_bool(f"algo_kwargs[{name!r}]", value)
        elif isinstance(default, (int, float)) and (
            isinstance(value, bool) or not isinstance(value, (int, float))
        ):
            raise ValueError(
                f"algo_kwargs[{name!r}] must be a number like its default {default!r}; "
                f"got {value!r}"
            )
    return algo_kwargs


def _progress_callback(total: int, enabled: bool):
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm.auto import tqdm

    class TqdmCallback(BaseCallback):
        """A tqdm bar over environment steps."""

        def _on_training_start(self) -> None:
            self.bar = tqdm(total=total, desc="timesteps", disable=not enabled)

        def _on_step(self) -> bool:
            self.bar.n = self.num_timesteps
            self.bar.refresh()
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return TqdmCallback()


@dataclass(frozen=True)
class TrainedAgent:
    """A trained model, where it is saved, its configuration, and its observation
    normalisation (the training ``VecNormalize``, or None)."""

    model: object
    model_path: Path
    config: dict
    normalizer: object = None


def train_agent(
    env_id: str,
    algo: str = "ppo",
    timesteps: int = 20_000,
    seed: int = 0,
    n_envs: int = 4,
    out: str | Path = "results/rl",
    env_kwargs: dict | None = None,
    algo_kwargs: dict | None = None,
    progress: bool = True,
    torch_threads: int = 1,
    normalize: bool = True,
    workers: int = 1,
) -> TrainedAgent:
    """Train ``algo`` on ``env_id`` for ``timesteps`` steps over ``n_envs`` environments whose
    trackers step in lockstep (:func:`agents.rl.vector.stable_baselines_vec_env`; a
    ``VecMonitor`` logs the episodes to ``out/monitor``); save ``out/model.zip`` and
    ``out/config.json``. ``normalize``: observations and rewards go through SB3's
    ``VecNormalize`` (unnormalised returns of -100 to -1000 gave value losses of ~4e4 and
    policy steps ~1000x too small), whose statistics are saved as ``out/vecnormalize.pkl``
    and applied to observations wherever the model acts (:func:`load_agent`,
    :class:`agents.rl.evaluation.ModelPolicy`). TensorBoard logs go to ``out/tensorboard``
    when tensorboard is installed. ``torch_threads``: the policy networks are tiny, and
    more than one torch or BLAS thread only adds synchronisation (``torch.set_num_threads``,
    ``threadpoolctl``); both limits stay set for the process. ``workers``: processes that
    step the environments, each a contiguous block of them in lockstep
    (:func:`agents.rl.process_blocks.process_blocks_vec_env`; 1 steps them in this process).
    The environments' numbers, and so the trained model, do not depend on it."""
    import torch
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    check_choice("env", env_id, RL_ENV_IDS)
    check_choice("algo", algo, ALGORITHMS)
    check_integer("timesteps", timesteps, low=1)
    check_integer("n_envs", n_envs, low=1)
    check_integer("seed", seed, low=0)
    env_kwargs = dict(env_kwargs or {})
    probe = gym.make(env_id, **env_kwargs)  # fails early on bad env arguments
    if algo == "dqn" and not isinstance(probe.action_space, gym.spaces.Discrete):
        raise ValueError(
            f"algo 'dqn' needs a Discrete action space; {env_id} has {probe.action_space}: "
            "use ppo or a2c"
        )
    probe.close()
    torch.set_num_threads(check_integer("torch_threads", torch_threads, low=1))
    threadpool_limits(limits=1)  # numpy's BLAS too: the trackers' matrices are tiny
    out = Path(out)
    check_bool("normalize", normalize)
    algorithm = _algorithm_class(algo)
    algo_kwargs = check_algo_kwargs(algorithm, algo_kwargs)
    env_seed = TRAINING_ENV_SEED + seed * n_envs
    # the environments come last among the checks (process_blocks_vec_env checks workers):
    # a rejected argument leaves no folder and no worker process behind
    if workers == 1:
        venv = stable_baselines_vec_env(env_id, n_envs, env_seed, env_kwargs)
    else:
        venv = process_blocks_vec_env(env_id, n_envs, env_seed, env_kwargs, workers)
    (out / "monitor").mkdir(parents=True, exist_ok=True)
    venv = VecMonitor(venv, filename=str(out / "monitor" / "train"))
    if normalize:
        venv = VecNormalize(venv)
    tensorboard = str(out / "tensorboard") if importlib.util.find_spec("tensorboard") else None
    try:
        model = algorithm(
            "MlpPolicy", venv, seed=seed, verbose=0, tensorboard_log=tensorboard, **algo_kwargs
        )
        if tensorboard is None:
            # without a folder Stable-Baselines3's own logger makes an empty one under the
            # temporary directory on every run; this logger writes nowhere
            model.set_logger(Logger(folder=None, output_formats=[]))
        # SB3 checks some values (n_steps, batch_size, schedules) only when it starts
        model.learn(total_timesteps=timesteps, callback=_progress_callback(timesteps, progress))
    except (AssertionError, TypeError, ValueError, RuntimeError) as error:
        venv.close()
        if not algo_kwargs:
            raise
        raise ValueError(
            f"algo_kwargs {algo_kwargs} rejected by {algorithm.__name__}: {error}"
        ) from None
    model_path = out / "model.zip"
    model.save(model_path)
    if normalize:
        venv.save(str(out / NORMALIZATION_FILE))
    config = {
        "env": env_id,
        "env_kwargs": env_kwargs,
        "algo": algo,
        "algo_kwargs": algo_kwargs or {},
        "timesteps": timesteps,
        "seed": seed,
        "n_envs": n_envs,
        "training_env_seed": env_seed,
        "normalize": normalize,
    }
    (out / "config.json").write_text(json.dumps(config, indent=1) + "\n")
    venv.close()
    return TrainedAgent(model, model_path, config, venv if normalize else None)


def load_normalization(out: str | Path):
    """The ``VecNormalize`` statistics saved by :func:`train_agent` in ``out`` (frozen), or
    None if the agent was trained without normalisation."""
    path = Path(out) / NORMALIZATION_FILE
    if not path.exists():
        return None
    with path.open("rb") as handle:
        normalizer = pickle.load(handle)  # SB3's own format (VecNormalize.save)
    normalizer.training, normalizer.norm_reward = False, False
    return normalizer


def load_agent(out: str | Path):
    """The model and configuration saved by :func:`train_agent` in ``out``, with the
    observation normalisation (``config["normalizer"]``, None without)."""
    out = Path(out)
    config = json.loads((out / "config.json").read_text())
    model = _algorithm_class(config["algo"]).load(out / "model.zip")
    return model, {**config, "normalizer": load_normalization(out)}


def compare_with_baselines(
    env_id: str,
    model,
    env_kwargs: dict | None = None,
    normalizer=None,
    training_seeds=TRAINING_SEEDS,
    evaluation_seeds=EVALUATION_SEEDS,
    progress: bool = True,
) -> list[dict]:
    """Rows (name, role, :func:`summarize_episodes`) for the trained agent (its observations
    normalised by ``normalizer`` if given), the best fixed baseline (grid search on
    ``training_seeds``), the default baseline, every other fixed baseline and a random
    policy, all on ``evaluation_seeds``."""
    from tqdm.auto import tqdm

    env = gym.make(env_id, **(env_kwargs or {}))
    policies, default = baseline_policies(env)
    search = {
        name: summarize_episodes(evaluate_policy_on_seeds(env, policy, training_seeds))["return"]
        for name, policy in tqdm(policies.items(), desc="best fixed baseline", disable=not progress)
    }
    best = max(search, key=search.get)
    candidates = [("trained agent", "agent", ModelPolicy(model, normalizer))]
    if default == best:
        candidates.append((best, "best fixed (training seeds) and default", policies[best]))
    else:
        candidates.append((best, "best fixed (training seeds)", policies[best]))
        candidates.append((default, "default", policies[default]))
    candidates += [
        (name, "fixed", policy) for name, policy in policies.items() if name not in (best, default)
    ]
    candidates.append(("random", "random", RandomPolicy(env.action_space, seed=0)))
    rows = []
    for name, role, policy in tqdm(candidates, desc="held-out evaluation", disable=not progress):
        episodes = evaluate_policy_on_seeds(env, policy, evaluation_seeds)
        rows.append(
            {"policy": name, "role": role, **summarize_episodes(episodes), "episodes_": episodes}
        )
    env.close()
    return rows


def comparison_markdown(rows: list[dict], env_id: str, per_step_label: str) -> str:
    """The comparison as a Markdown table (mean +- 95 % CI half-width over held-out seeds)."""
    lines = [
        f"| {env_id} policy | role | episode return | NRMSE % | {per_step_label} |",
        "|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row['policy']} | {row['role']} | {row['return']:.2f} +- {row['return_ci']:.2f} | "
            f"{100 * row['nrmse']:.2f} +- {100 * row['nrmse_ci']:.2f} | "
            f"{row['per_step']:.2f} |"
        )
    return "\n".join(lines)


def monitor_returns(folder: Path) -> tuple[np.ndarray, np.ndarray]:
    """(cumulative timesteps, return) of every training episode in the Monitor CSVs of
    ``folder`` (a JSON comment line, then columns r, l, t), ordered by wall time."""
    episodes = []
    for path in sorted(folder.glob("*.monitor.csv")):
        with path.open() as handle:
            handle.readline()  # the JSON header
            episodes += [
                (float(row["t"]), float(row["r"]), int(row["l"])) for row in csv.DictReader(handle)
            ]
    episodes.sort()
    lengths = np.array([length for _, _, length in episodes], dtype=float)
    returns = np.array([value for _, value, _ in episodes])
    return np.cumsum(lengths), returns


def plot_learning_curve(out: str | Path, rows: list[dict] | None = None, title: str = "") -> Path:
    """Training episode returns against timesteps (Monitor logs in ``out/monitor``), a
    moving average, and the held-out mean return of the best fixed baseline if ``rows``."""

    out = Path(out)
    x, y = monitor_returns(out / "monitor")
    figure = new_figure((7, 4), dpi=80)
    axes = figure.add_subplot(1, 1, 1)
    axes.plot(x, y, ".", ms=3, alpha=0.4, label="training episode")
    if y.size >= 5:
        width = max(5, y.size // 20)
        smooth = np.convolve(y, np.ones(width) / width, mode="valid")
        axes.plot(x[width - 1 :], smooth, lw=2, label=f"moving mean ({width} episodes)")
    baselines = [row for row in rows or [] if row["role"] not in ("fixed", "agent")]
    for index, row in enumerate(baselines):
        axes.axhline(
            row["return"], ls="--", lw=1, color=f"C{index + 2}", label=f"{row['policy']} (held-out)"
        )
    axes.set(xlabel="timesteps", ylabel="episode return", title=title)
    axes.legend(fontsize=7)
    return save_figure(figure, out / "learning_curve.png")
