"""``dgpt-train-rl`` (also ``python scripts/train_rl.py``): train a Stable-Baselines3 agent on an RL environment of dgpt-gym and compare it with the
baselines on held-out seeds.

Saves OUT/model.zip and OUT/config.json, evaluates the agent, the best fixed baseline (grid
search on training seeds), the default baseline, the other fixed ones and a random policy on
held-out seeds, prints the comparison table (also OUT/comparison.md and .json) and writes
OUT/learning_curve.png. Prints the training's speed first: steps per second and the minutes
that rate gives for 1e6 steps, set-up included (docs/performance.md quotes it). Needs the
'rl' extra (stable-baselines3, torch).
"""

from __future__ import annotations

import argparse
import ast
import importlib.util
import json
import sys
import time
from pathlib import Path

import dgpt_gym  # noqa: F401  (registers the environments)
from agents.rl.registration import ENVIRONMENTS
from agents.rl.training import (
    RL_ENV_IDS,
    compare_with_baselines,
    comparison_markdown,
    plot_learning_curve,
    train_agent,
)

RL_EXTRA = ("stable_baselines3", "torch")
"""What the 'rl' extra installs and training needs."""

TUNING_ENV_IDS = ("DGPTrackWindow-v0", "DGPTrackGating-v0")
TUNING_TASK_KWARGS = ["scenario=S3", "clutter_rate=5", "trajectory=random", "layout=per_episode"]
"""The documented window and gating task: S3 at clutter rate 5, a random path in a layout
drawn from the seed (``scripts/tuning_baselines.py``, ``scripts/clairvoyant_imitation.py``)."""

ENV_ALIASES = {environment.alias: environment.id for environment in ENVIRONMENTS}
PER_STEP = {environment.id: environment.per_step for environment in ENVIRONMENTS}


def add_evaluation_arguments(parser: argparse.ArgumentParser, cache: Path) -> None:
    """The arguments the evaluation scripts share (``scripts/sensors_baselines.py``,
    ``scripts/tuning_baselines.py``): ``--models`` (trained agents' folders) and ``--cache``
    / ``--no-cache`` (:func:`agents.rl.runs.run_policies`' folder of finished
    policies, ``cache`` by default)."""
    parser.add_argument(
        "--models", nargs="*", type=Path, default=[], help="trained agents' folders (train_rl.py)"
    )
    parser.add_argument(
        "--cache",
        type=Path,
        default=cache,
        help="folder keeping each policy's episodes as they finish, so that a rerun (or an "
        "interrupted run) reuses them; keyed by a hash of the packages' code, the policy, "
        f"the environment and the seeds (default: {cache})",
    )
    parser.add_argument("--no-cache", action="store_true", help="run every episode afresh")


def training_speed(timesteps: int, seconds: float) -> str:
    """The line ``main`` prints after training: ``timesteps`` in ``seconds``, the steps per
    second and the minutes per 1e6 steps at that rate."""
    rate = timesteps / seconds
    return (
        f"trained {timesteps} steps in {seconds:.1f} s: {rate:.0f} steps/s, "
        f"{1e6 / rate / 60:.1f} min per 1e6 steps"
    )


def default_output_folder(env_id: str, algo: str, seed: int) -> Path:
    """Where ``main`` saves an agent without ``--out``: one folder per environment id
    (version included: the sensor task's v0, v1 and v2 are different tasks), algorithm and
    seed, so that another training does not overwrite a finished one."""
    return Path("results") / "rl" / f"{env_id}-{algo}-seed{seed}"


def parse_kwargs(items: list[str]) -> dict:
    """``["scenario=S3", "clutter_rate=5"]`` -> ``{"scenario": "S3", "clutter_rate": 5}``
    (values are Python literals where they parse as one, else strings)."""
    kwargs = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key:
            raise ValueError(f"keyword arguments must look like KEY=VALUE; got {item!r}")
        try:
            kwargs[key] = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            kwargs[key] = text
    return kwargs


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--env",
        default="window",
        help=f"{', '.join(ENV_ALIASES)}, or a full id ({', '.join(PER_STEP)}); default: window",
    )
    parser.add_argument(
        "--algo",
        default="ppo",
        choices=["ppo", "a2c", "dqn"],
        help="algorithm (default: ppo; dqn needs a discrete action space: window, sensors-v1, sensors-v2)",
    )
    parser.add_argument(
        "--timesteps", type=int, default=20_000, help="training steps (default: 20000)"
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="seed of the algorithm and training envs"
    )
    parser.add_argument(
        "--n-envs", type=int, default=4, help="vectorized training envs (default: 4)"
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=1,
        help="processes stepping the training envs, each a block of them (default: 1, this "
        "process); the trained model does not depend on it. With --n-envs 32, 2 workers "
        "trained 1.25-1.3x faster on 2 cores (docs/performance.md)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output folder (default: results/rl/<env id>-<algo>-seed<seed>, so that "
        "trainings of other tasks or seeds keep their own)",
    )
    parser.add_argument(
        "--env-kwargs",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="environment arguments, e.g. scenario=S3 clutter_rate=5 compute_weight=0.2",
    )
    parser.add_argument(
        "--algo-kwargs",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="algorithm arguments, e.g. n_steps=256 batch_size=64 learning_rate=0.001",
    )
    parser.add_argument(
        "--eval-episodes",
        type=int,
        default=20,
        help="held-out evaluation seeds 0..N-1 (default: 20)",
    )
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bars")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    missing = [name for name in RL_EXTRA if importlib.util.find_spec(name) is None]
    if missing:
        print(f"error: {', '.join(missing)} not installed; install the 'rl' extra", file=sys.stderr)
        return 2
    env_id = ENV_ALIASES.get(args.env, args.env)
    try:
        if env_id not in RL_ENV_IDS:
            raise ValueError(
                f"env must be one of {sorted(ENV_ALIASES)} or {list(RL_ENV_IDS)}; got {args.env!r}"
            )
        if args.eval_episodes < 2:
            raise ValueError(f"eval-episodes must be >= 2; got {args.eval_episodes}")
        env_kwargs = parse_kwargs(args.env_kwargs)
        algo_kwargs = parse_kwargs(args.algo_kwargs)
        out = args.out or default_output_folder(env_id, args.algo, args.seed)
        started = time.perf_counter()
        agent = train_agent(
            env_id,
            args.algo,
            args.timesteps,
            args.seed,
            args.n_envs,
            out,
            env_kwargs,
            algo_kwargs,
            progress=not args.no_progress,
            workers=args.workers,
        )
    except (ValueError, TypeError) as error:  # bad names, values or keyword arguments
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(training_speed(args.timesteps, time.perf_counter() - started))
    rows = compare_with_baselines(
        env_id,
        agent.model,
        env_kwargs,
        agent.normalizer,
        evaluation_seeds=range(args.eval_episodes),
        progress=not args.no_progress,
    )
    command = "python scripts/train_rl.py " + " ".join(argv if argv is not None else sys.argv[1:])
    table = comparison_markdown(rows, env_id, PER_STEP[env_id])
    (out / "comparison.md").write_text(
        f"Command: `{command.strip()}`\n\nHeld-out seeds 0-{args.eval_episodes - 1}; mean +- 95 % CI.\n\n{table}\n"
    )
    (out / "comparison.json").write_text(
        json.dumps([{k: v for k, v in row.items() if k != "episodes_"} for row in rows], indent=1)
    )
    figure = plot_learning_curve(out, rows, title=f"{args.algo.upper()} on {env_id}")
    print(table)
    print(f"wrote {agent.model_path}, {out / 'comparison.md'} and {figure}")
    return 0
