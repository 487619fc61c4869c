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
one more row: the IQM over all their episodes (seeds x agents) with a bootstrap stratified
by agent, as rliable does for several training runs.

One environment configuration is one task, so rliable's stratified bootstrap reduces to a
bootstrap over episodes (stratified by agent when several are pooled): ``scipy.stats.bootstrap``
of the 25 %-trimmed mean gives the same interval without another dependency.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import gymnasium as gym  # noqa: E402

import dgpt_gym  # noqa: E402, F401  (registers the environments)
from agents.rl.evaluation import (  # noqa: E402
    ConstantPolicy,
    ModelPolicy,
    RandomPolicy,
    run_policy_episode,
)
from agents.rl.heuristics import (  # noqa: E402
    HEURISTIC_GRIDS,
    SilenceSearchPolicy,
    UncertaintyRadiusPolicy,
)
from agents.rl.registration import ENVIRONMENTS  # noqa: E402
from agents.rl.training import load_agent  # noqa: E402

ENV_IDS = tuple(
    environment.id
    for environment in ENVIRONMENTS
    if environment.entry_point == "agents.rl.sensors_v1:DGPTrackSensorsV1Env"
)
"""The sensor tasks this script evaluates: v1 and every id that fixes its arguments (v2)."""
RULES = {"uncertainty radius": UncertaintyRadiusPolicy, "silence search": SilenceSearchPolicy}


def make_policy(kind: str, setting, env: gym.Env, seed: int):
    if kind == "agent":
        model, config = load_agent(setting)
        return ModelPolicy(model, config["normalizer"])
    if kind == "constant":
        return ConstantPolicy(setting)
    if kind == "random":
        return RandomPolicy(env.action_space, seed=seed)
    return RULES[kind](**setting)


def run_block(task):
    """Episodes of one policy on some seeds (a worker's unit)."""
    kind, setting, env_id, env_kwargs, seeds = task
    env = gym.make(env_id, **env_kwargs)
    rows = []
    agent = make_policy(kind, setting, env, seeds[0]) if kind == "agent" else None
    for seed in seeds:
        policy = agent or make_policy(kind, setting, env, seed)
        rows.append(run_policy_episode(env, policy, seed))
    return rows


def run_all(tasks, workers):
    if workers == 1:
        return [run_block(task) for task in tasks]
    with ProcessPoolExecutor(workers) as pool:
        return list(pool.map(run_block, tasks))


def iqm_interval(*samples: np.ndarray, seed: int = 0) -> tuple[float, float, float]:
    """Interquartile mean of the pooled ``samples`` and its 95 % percentile-bootstrap
    interval (2000 resamples). With several samples (the episodes of several agents) each
    is resampled on its own, the bootstrap stratified by sample that rliable uses."""

    def pooled_iqm(*resampled, axis=-1):
        return stats.trim_mean(np.concatenate(resampled, axis=axis), 0.25, axis=axis)

    result = stats.bootstrap(
        samples,
        pooled_iqm,
        n_resamples=2000,
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    interval = result.confidence_interval
    return float(pooled_iqm(*samples)), float(interval.low), float(interval.high)


def paired_iqm_difference(agents: np.ndarray, rule: np.ndarray, seed: int = 0):
    """IQM of the agents' returns (n_agents, n_seeds) minus the IQM of the rule's (n_seeds,)
    on the same seeds, with a 95 % percentile-bootstrap interval that resamples the seeds
    (the same ones for every agent and the rule: paired). Returns (difference, low, high)."""

    def difference(*resampled, axis=-1):
        pooled = np.concatenate(resampled[:-1], axis=axis)
        return stats.trim_mean(pooled, 0.25, axis=axis) - stats.trim_mean(
            resampled[-1], 0.25, axis=axis
        )

    result = stats.bootstrap(
        (*agents, rule),
        difference,
        paired=True,
        n_resamples=2000,
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    interval = result.confidence_interval
    return float(difference(*agents, rule)), float(interval.low), float(interval.high)


def paired_interval(differences: np.ndarray) -> tuple[float, float]:
    """Mean of paired differences and the half-width of its Student-t 95 % interval."""
    sem = differences.std(ddof=1) / np.sqrt(differences.size)
    return float(differences.mean()), float(sem * stats.t.ppf(0.975, differences.size - 1))


def _pooled(by_name: dict, agents: list[str], reference: np.ndarray) -> str:
    """The table cells of several trained agents together: the IQM over every (agent, seed)
    episode with its bootstrap stratified by agent (:func:`iqm_interval`), the mean, and
    the paired difference of the agents' mean return per seed to ``reference``."""
    returns = np.array([[row["return"] for row in by_name[name]] for name in agents])
    iqm, low, high = iqm_interval(*returns)
    difference, half = paired_interval(returns.mean(axis=0) - reference)
    nrmse = 100 * np.mean([[row["nrmse"] for row in by_name[name]] for name in agents])
    per_step = np.mean([[row["per_step"] for row in by_name[name]] for name in agents])
    return (
        f"{iqm:.1f} [{low:.1f}, {high:.1f}] | {returns.mean():.1f} | {nrmse:.2f} | "
        f"{per_step:.1f} | {difference:+.1f} +- {half:.1f}"
    )


def _against_each_rule(by_name: dict, agents: list[str], rules: list[str]) -> list[str]:
    """Table lines: the agents' mean per-seed return and sensors per step, paired with each
    adaptive rule's on the same seeds (the comparison the training-chosen best rule alone
    does not settle when another rule does better on the evaluation seeds)."""

    def per_seed(names, key):
        return np.mean([[row[key] for row in by_name[name]] for name in names], axis=0)

    lines = [
        "",
        f"The {len(agents)} agents together against each adaptive rule, paired by seed: the "
        "IQM of the agents' returns minus the rule's with a 95 % bootstrap interval over seeds "
        "(the same seeds resampled for both), and mean differences with 95 % t intervals:",
        "",
        "| rule | IQM return: agents - rule [95 % CI] | mean return: agents - rule | "
        "sensors per step: agents - rule |",
        "|---|---|---|---|",
    ]
    returns = np.array([[row["return"] for row in by_name[name]] for name in agents])
    for rule in rules:
        rule_returns = np.array([row["return"] for row in by_name[rule]])
        iqm, low, high = paired_iqm_difference(returns, rule_returns)
        cells = [f"{iqm:+.1f} [{low:+.1f}, {high:+.1f}]"]
        for key in ("return", "per_step"):
            difference, half = paired_interval(per_seed(agents, key) - per_seed([rule], key))
            cells.append(f"{difference:+.1f} +- {half:.1f}")
        lines.append(f"| {rule} | {' | '.join(cells)} |")
    return lines


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
    results = run_all(
        [(*policies[name], args.env, env_kwargs, seeds) for name in names], args.workers
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
    parser.add_argument(
        "--models", nargs="*", type=Path, default=[], help="trained agents' folders (train_rl.py)"
    )
    parser.add_argument(
        "--training-table",
        action="store_true",
        help="every policy on the training seeds only, to a CSV in --out; no evaluation",
    )
    args = parser.parse_args(argv)
    env_kwargs = {"scenario": args.scenario, "clutter_rate": args.clutter_rate}
    env = gym.make(args.env, **env_kwargs)
    version = args.env.rsplit("-", 1)[1]
    if args.training_table:
        return training_table(args, env, env_kwargs, version)
    constants, _ = env.unwrapped.fixed_actions()

    # 1. the rules' settings on training seeds
    training = list(range(1000, 1000 + args.training_seeds))
    tuning = [(kind, setting) for kind, grid in HEURISTIC_GRIDS.items() for setting in grid]
    results = run_all([(k, s, args.env, env_kwargs, training) for k, s in tuning], args.workers)
    best = {}
    for (kind, setting), rows in zip(tuning, results):
        score = float(np.mean([row["return"] for row in rows]))
        print(f"training  {kind:20s} {setting}: mean return {score:.2f}")
        if kind not in best or score > best[kind][1]:
            best[kind] = (setting, score)
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
        config = json.loads((folder / "config.json").read_text())
        if config["env"] != args.env or config["env_kwargs"] != env_kwargs:
            parser.error(f"{folder} was trained on {config['env']} {config['env_kwargs']}")
        policies[f"agent {folder.name}"] = ("agent", folder)
    names = list(policies)
    results = run_all(
        [(*policies[name], args.env, env_kwargs, evaluation) for name in names], args.workers
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
            f"| **{len(agents)} agents together** | {_pooled(by_name, agents, reference)} |"
        )
    for name in names:
        rows = by_name[name]
        returns = np.array([row["return"] for row in rows])
        iqm, low, high = iqm_interval(returns)
        difference, half = paired_interval(returns - reference)
        per_step = float(np.mean([row["per_step"] for row in rows]))
        error = float(np.mean([row["mean_error"] for row in rows]))
        nrmse = 100 * float(np.mean([row["nrmse"] for row in rows]))
        paired = "-" if name == best_rule else f"{difference:+.1f} +- {half:.1f}"
        lines.append(
            f"| {name} | {iqm:.1f} [{low:.1f}, {high:.1f}] | {returns.mean():.1f} | "
            f"{nrmse:.2f} | {per_step:.1f} | {paired} |"
        )
        points.append((name, per_step, error))
    if agents:
        lines += _against_each_rule(
            by_name, agents, [n for n in names if policies[n][0] in HEURISTIC_GRIDS]
        )
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
