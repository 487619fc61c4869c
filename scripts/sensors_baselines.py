"""The baselines of DGPTrackSensors-v1 / -v2 on held-out seeds and layouts, with IQM intervals.

1. Tunes the adaptive rules of ``agents/rl/heuristics.py`` on training seeds (1000 onwards,
   random paths in layouts drawn from those seeds): the setting with the best mean return.
2. Runs every policy on the evaluation seeds 0..N-1 (paths and layouts no training episode
   used): waking the nearest n for every n, waking all, a random policy, the tuned rules.
3. Writes docs/rl_sensors_v1.md or docs/rl_sensors_v2.md (interquartile mean of the return
   with a 95 % bootstrap interval, mean NRMSE, sensors woken per step, and the paired
   difference to the best rule seed by seed; with agents, also their paired differences to
   every tuned rule, of the IQM by a bootstrap over seeds and of the mean) and
   docs/figures/rl_sensors_v1_pareto.png or ..._v2_pareto.png (sensors woken per step
   against the mean error, every policy).

    python scripts/sensors_baselines.py                      # S1, clutter 5, 100 seeds
    python scripts/sensors_baselines.py --seeds 20 --training-seeds 10
    python scripts/sensors_baselines.py --models models/sensors-v1-ppo-seed*   # with agents
    python scripts/sensors_baselines.py --env DGPTrackSensors-v2 --models models/sensors-v2-ppo-seed*
    python scripts/sensors_baselines.py --training-table   # every policy on training seeds only

``--training-table`` runs every fixed count, the random policy and every setting of the rules
on the training seeds only, prints their means and writes the per-seed rows to
OUT/training_returns_VERSION.csv (what compared the trackers inside v1 and v2); it reports
nothing on the evaluation seeds.

``--models``: folders written by ``scripts/train_rl.py`` (model.zip, config.json,
vecnormalize.pkl); each agent is evaluated without training, and the agents together are
one more row: the IQM over all their episodes (seeds x agents) with a bootstrap over seeds
that resamples a seed's episodes together. The statistics are :mod:`agents.rl.evaluation`'s
(where the difference to the rliable library is explained), shared with
``scripts/tuning_baselines.py``.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import gymnasium as gym  # noqa: E402

import dgpt_gym  # noqa: E402, F401  (registers the environments)
from agents.rl.cli import add_evaluation_arguments  # noqa: E402
from agents.rl.evaluation import (  # noqa: E402
    agents_against,
    policy_cells,
)
from agents.rl.heuristics import (  # noqa: E402
    HEURISTIC_GRIDS,
    SilenceSearchPolicy,
    UncertaintyRadiusPolicy,
)
from agents.rl.registration import ENVIRONMENTS  # noqa: E402
from agents.rl.runs import check_agent_folders, run_policies, tune_rules  # noqa: E402

ENV_IDS = tuple(
    environment.id
    for environment in ENVIRONMENTS
    if environment.entry_point == "agents.rl.sensors_v1:DGPTrackSensorsV1Env"
)
"""The sensor tasks this script evaluates: v1 and every id that fixes its arguments (v2)."""
RULES = {"uncertainty radius": UncertaintyRadiusPolicy, "silence search": SilenceSearchPolicy}


def training_table(args, env, env_kwargs: dict, version: str) -> int:
    """Every fixed count, the random policy and every rule setting on the training seeds:
    prints the means and writes one row per (policy, seed) to
    ``OUT/training_returns_VERSION.csv``."""
    constants, _ = env.unwrapped.fixed_actions()
    policies = {name: ("constant", action) for name, action in constants.items()}
    policies["random"] = ("random", None)
    for kind, grid in HEURISTIC_GRIDS.items():
        for setting in grid:
            label = ", ".join(f"{key}={value}" for key, value in setting.items())
            policies[f"{kind} ({label})"] = (kind, setting)
    seeds = list(range(1000, 1000 + args.training_seeds))
    names = list(policies)
    results = run_policies(
        [policies[name] for name in names],
        args.env,
        env_kwargs,
        seeds,
        args.workers,
        RULES,
        args.cache,
    )
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"training_returns_{version}.csv"
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["policy", "seed", "return", "mean_error", "per_step"])
        for name, rows in zip(names, results):
            for row in rows:
                writer.writerow(
                    [name, row["seed"], row["return"], row["mean_error"], row["per_step"]]
                )
            print(
                f"{name:40s} mean return {np.mean([r['return'] for r in rows]):8.1f}  mean error "
                f"{np.mean([r['mean_error'] for r in rows]):7.1f} m  sensors per step "
                f"{np.mean([r['per_step'] for r in rows]):6.1f}"
            )
    print(f"wrote {path}")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default=ENV_IDS[0], choices=ENV_IDS, help="the task")
    parser.add_argument("--seeds", type=int, default=100, help="evaluation seeds 0..N-1")
    parser.add_argument("--training-seeds", type=int, default=20, help="seeds 1000..")
    parser.add_argument("--scenario", default="S1")
    parser.add_argument("--clutter-rate", type=float, default=5.0)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--out", type=Path, default=ROOT / "docs")
    add_evaluation_arguments(parser, ROOT / "results" / "rl" / "sensors_baselines")
    parser.add_argument(
        "--training-table",
        action="store_true",
        help="every policy on the training seeds only, to a CSV in --out; no evaluation",
    )
    args = parser.parse_args(argv)
    env_kwargs = {"scenario": args.scenario, "clutter_rate": args.clutter_rate}
    if args.workers < 1:
        parser.error(f"--workers must be >= 1; got {args.workers}")
    try:
        check_agent_folders(args.models, args.env, env_kwargs)
    except ValueError as error:
        parser.error(f"--models: {error}")
    if args.no_cache:
        args.cache = None
    env = gym.make(args.env, **env_kwargs)
    version = args.env.rsplit("-", 1)[1]
    if args.training_table:
        return training_table(args, env, env_kwargs, version)
    constants, _ = env.unwrapped.fixed_actions()

    # 1. the rules' settings on training seeds
    training = list(range(1000, 1000 + args.training_seeds))
    best, tuning = tune_rules(
        HEURISTIC_GRIDS, args.env, env_kwargs, training, args.workers, RULES, args.cache
    )
    for kind, setting, score in tuning:
        print(f"training  {kind:20s} {setting}: mean return {score:.2f}")
    training_score = {}

    # 2. every policy on the evaluation seeds
    evaluation = list(range(args.seeds))
    policies = {name: ("constant", action) for name, action in constants.items()}
    policies["random"] = ("random", None)
    for kind, (setting, score) in best.items():
        label = ", ".join(f"{key}={value}" for key, value in setting.items())
        policies[f"{kind} ({label})"] = (kind, setting)
        training_score[f"{kind} ({label})"] = score
    for folder in args.models:
        policies[f"agent {folder.name}"] = ("agent", folder)
    names = list(policies)
    results = run_policies(
        [policies[name] for name in names],
        args.env,
        env_kwargs,
        evaluation,
        args.workers,
        RULES,
        args.cache,
    )
    by_name = dict(zip(names, results))
    agents = [name for name in names if policies[name][0] == "agent"]
    best_rule = max(training_score, key=training_score.get)  # chosen on training seeds

    # 3. the table and the figure
    lines = [
        f"# {args.env} baselines ({args.scenario}, clutter rate {args.clutter_rate:g})",
        "",
        "Generated by `python scripts/sensors_baselines.py"
        + (f" --env {args.env}" if args.env != ENV_IDS[0] else "")
        + (f" --seeds {args.seeds}" if args.seeds != 100 else "")
        + (f" --training-seeds {args.training_seeds}" if args.training_seeds != 20 else "")
        + (" --models " + " ".join(str(path) for path in args.models) if args.models else "")
        + "`. The rules were tuned on training seeds "
        f"1000-{999 + args.training_seeds}; every row is on the evaluation seeds 0-{args.seeds - 1} "
        "(random paths in layouts no training episode used). IQM: interquartile mean of the "
        "episode returns with a 95 % bootstrap interval; paired: the mean per-seed return "
        f"difference to **{best_rule}** (the rule with the best mean return on the training "
        "seeds) with a 95 % t interval.",
        "",
        "| policy | IQM return [95 % CI] | mean return | NRMSE % | sensors per step | paired - best rule |",
        "|---|---|---|---|---|---|",
    ]
    reference = np.array([row["return"] for row in by_name[best_rule]])
    points = []
    if agents:
        lines.append(
            f"| **{len(agents)} agents together** | {policy_cells(by_name, agents, reference)} |"
        )
    for name in names:
        cells = policy_cells(by_name, [name], reference, is_reference=name == best_rule)
        lines.append(f"| {name} | {cells} |")
        rows = by_name[name]
        per_step = float(np.mean([row["per_step"] for row in rows]))
        error = float(np.mean([row["mean_error"] for row in rows]))
        points.append((name, per_step, error))
    if agents:
        lines += [
            "",
            f"The {len(agents)} agents together against each adaptive rule, paired by seed: the "
            "IQM of the agents' returns minus the rule's with a 95 % bootstrap interval over "
            "seeds (the same seeds resampled for both), and mean differences with 95 % t "
            "intervals:",
            "",
            *agents_against(
                by_name,
                agents,
                [n for n in names if policies[n][0] in HEURISTIC_GRIDS],
                "sensors per step",
                what="rule",
            ),
        ]
    text = "\n".join(lines) + "\n"
    args.out.mkdir(parents=True, exist_ok=True)
    table = args.out / f"rl_sensors_{version}.md"
    table.write_text(text)
    print(text)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(6.5, 4.2))
    for name, per_step, error in points:
        kind = policies[name][0]
        marker = {"constant": "o", "random": "x", "agent": "D"}.get(kind, "*")
        axis.scatter(per_step, error, marker=marker, s=60 if marker == "*" else 25)
        labelled = ("nearest 1", "nearest 4", "nearest 8", "nearest 16", "all")
        if kind != "constant" or name in labelled:
            axis.annotate(
                "PPO" if kind == "agent" else name.split(" (")[0],
                (per_step, error),
                fontsize=7,
                xytext=(4, 2),
                textcoords="offset points",
            )
    axis.set_xscale("symlog", linthresh=1)
    axis.set_yscale("log")
    axis.set_xlabel("sensors woken per step")
    axis.set_ylabel("mean error, m")
    axis.set_title(
        f"{args.env}, {args.scenario}, clutter {args.clutter_rate:g}, seeds 0-{args.seeds - 1}"
    )
    axis.grid(alpha=0.3)
    figure.tight_layout()
    path = args.out / "figures" / f"rl_sensors_{version}_pareto.png"
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    print(f"wrote {table} and {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
