"""The window and gating tasks' fixed settings and trained agents on held-out seeds, with IQM
intervals.

1. Runs every fixed setting of the task (``fixed_actions()``: every window length C, or nine
   gate thresholds) on the training seeds (1000 onwards) and keeps the one with the best
   mean return, the "best fixed setting".
   The task's adaptive rule (:mod:`agents.rl.tuning_rules`: a tight gate while the track is
   quiet, or a window chosen by the last step's surprise) is tuned on the same seeds.
2. Runs every fixed setting, the tuned rule, a random policy and each trained agent
   (``--models``, folders of ``scripts/train_rl.py``, evaluated without training) on the
   evaluation seeds 0..N-1
   (``--first-seed 1000``: on the training seeds, to choose between agents).
   With the default ``trajectory=random layout=per_episode`` these are paths and sensor
   layouts that no training episode used.
   With ``--clairvoyant``, two references that see the truth and that no agent could run
   (:mod:`agents.rl.clairvoyant`): the greedy clairvoyant policy, which tries every fixed
   setting at each step and keeps the best (the best fixed setting where several tie), and
   the best fixed setting of each episode with hindsight. They show what adapting the knob
   could gain.
3. Writes docs/rl_window_v0.md or docs/rl_gating_v0.md: the interquartile mean (IQM) of the
   episode return with a 95 % bootstrap interval over seeds (the agents' episodes on a seed
   resampled together), mean return, NRMSE, the mean knob per step, the paired difference
   to the best fixed setting seed by seed, and the agents' paired IQM and mean differences to the
   best fixed and the default setting; and docs/figures/rl_window_v0.png (or gating): the
   IQM return of every policy against its mean knob.

    python scripts/tuning_baselines.py --env DGPTrackWindow-v0 --clairvoyant --models models/window-ppo-seed*
    python scripts/tuning_baselines.py --env DGPTrackGating-v0 --clairvoyant --models models/gating-ppo-seed*
    python scripts/tuning_baselines.py --env DGPTrackWindow-v0 --seeds 20 --training-seeds 5

The statistics are :mod:`agents.rl.evaluation`'s (shared with ``scripts/sensors_baselines.py``).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import gymnasium as gym  # noqa: E402

import dgpt_gym  # noqa: E402, F401  (registers the environments)
from agents.rl.clairvoyant import hindsight_best_per_seed  # noqa: E402
from agents.rl.cli import (  # noqa: E402
    TUNING_ENV_IDS,
    TUNING_TASK_KWARGS,
    add_evaluation_arguments,
    parse_kwargs,
)
from agents.rl.evaluation import (  # noqa: E402
    agents_against,
    iqm_interval,
    policy_cells,
)
from agents.rl.runs import (  # noqa: E402
    best_fixed_setting,
    check_agent_folders,
    run_policies,
    tune_rules,
)
from agents.rl.tuning_rules import TUNING_RULE_GRIDS, TUNING_RULES  # noqa: E402

KNOB_LABELS = {"window": "mean window C", "gate_threshold": "mean gate threshold"}
CLAIRVOYANT = "clairvoyant, greedy per step (sees the truth)"
HINDSIGHT = "clairvoyant, best fixed per episode (hindsight)"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default=TUNING_ENV_IDS[0], choices=TUNING_ENV_IDS, help="the task")
    parser.add_argument("--seeds", type=int, default=100, help="evaluation seeds F..F+N-1")
    parser.add_argument(
        "--first-seed",
        type=int,
        default=0,
        help="F, the first evaluation seed (default 0; 1000 compares agents on the training "
        "seeds, to choose among them without looking at the evaluation seeds)",
    )
    parser.add_argument("--training-seeds", type=int, default=20, help="seeds 1000..")
    parser.add_argument(
        "--env-kwargs",
        nargs="*",
        default=TUNING_TASK_KWARGS,
        metavar="KEY=VALUE",
        help=f"environment arguments (default: {' '.join(TUNING_TASK_KWARGS)})",
    )
    parser.add_argument(
        "--clairvoyant",
        action="store_true",
        help="add the clairvoyant references (agents.rl.clairvoyant); the greedy one steps "
        "the environment once per action per step, about as long as all fixed settings",
    )
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--out", type=Path, default=ROOT / "docs")
    add_evaluation_arguments(parser, ROOT / "results" / "rl" / "tuning_baselines")
    args = parser.parse_args(argv)
    if args.no_cache:
        args.cache = None
    if args.seeds < 2 or args.training_seeds < 1 or args.workers < 1 or args.first_seed < 0:
        parser.error(
            "--seeds must be >= 2, --training-seeds >= 1, --workers >= 1 and --first-seed >= 0"
        )
    evaluation = range(args.first_seed, args.first_seed + args.seeds)
    seed_range = f"{evaluation[0]}-{evaluation[-1]}"
    try:
        env_kwargs = parse_kwargs(args.env_kwargs)
        env = gym.make(args.env, **env_kwargs)
    except (TypeError, ValueError) as error:
        parser.error(f"--env-kwargs: {error}")
    try:
        check_agent_folders(args.models, args.env, env_kwargs)
    except ValueError as error:
        parser.error(f"--models: {error}")
    constants, default = env.unwrapped.fixed_actions()
    knob = env.unwrapped.knob
    env.close()

    # 1. the best fixed setting on training seeds
    training = range(1000, 1000 + args.training_seeds)
    best, scores = best_fixed_setting(args.env, env_kwargs, training, args.workers, args.cache)
    for name, score in scores.items():
        print(f"training  {name:28s} mean return {score:9.2f}")

    # the task's adaptive rule, tuned on the same training seeds
    tuned, tuning = tune_rules(
        TUNING_RULE_GRIDS.get(args.env, {}),
        args.env,
        env_kwargs,
        training,
        args.workers,
        TUNING_RULES,
        args.cache,
    )
    for kind, setting, score in tuning:
        print(f"training  {kind} {setting}: mean return {score:9.2f}")

    # 2. every policy on the evaluation seeds
    policies = {name: ("constant", action) for name, action in constants.items()}
    policies["random"] = ("random", None)
    for kind, (setting, _) in tuned.items():
        label = ", ".join(f"{key}={value}" for key, value in setting.items())
        policies[f"{kind} ({label}; tuned on training seeds)"] = (kind, setting)
    if args.clairvoyant:
        policies[CLAIRVOYANT] = ("clairvoyant", constants[best])
    for folder in args.models:
        policies[f"agent {folder.name}"] = ("agent", folder)
    names = list(policies)
    results = run_policies(
        [policies[name] for name in names],
        args.env,
        env_kwargs,
        evaluation,
        args.workers,
        TUNING_RULES,
        args.cache,
    )
    by_name = dict(zip(names, results))
    if args.clairvoyant:
        by_name[HINDSIGHT] = hindsight_best_per_seed({name: by_name[name] for name in constants})
        policies[HINDSIGHT] = ("hindsight", None)
        names.insert(names.index(CLAIRVOYANT) + 1, HINDSIGHT)
    agents = [name for name in names if policies[name][0] == "agent"]

    # 3. the tables and the figure
    knob_label = KNOB_LABELS.get(knob, f"mean {knob}")
    command = (
        f"python scripts/tuning_baselines.py --env {args.env}"
        + (f" --first-seed {args.first_seed}" if args.first_seed else "")
        + (" --clairvoyant" if args.clairvoyant else "")
        + (f" --seeds {args.seeds}" if args.seeds != 100 else "")
        + (f" --training-seeds {args.training_seeds}" if args.training_seeds != 20 else "")
        + (
            f" --env-kwargs {' '.join(args.env_kwargs)}"
            if args.env_kwargs != TUNING_TASK_KWARGS
            else ""
        )
        + (" --models " + " ".join(str(path) for path in args.models) if args.models else "")
    )
    reference = np.array([row["return"] for row in by_name[best]])
    lines = [
        f"# {args.env}: fixed settings and agents ({', '.join(args.env_kwargs)})",
        "",
        f"Generated by `{command}`. The best fixed setting, **{best}**, has the best mean "
        f"return on the training seeds 1000-{999 + args.training_seeds}"
        + (
            ", and the rule's setting is the best of its grid there "
            f"(`agents.rl.tuning_rules.TUNING_RULE_GRIDS`, {len(tuning)} settings)"
            if tuned
            else ""
        )
        + f"; every row is on the evaluation seeds {seed_range}. IQM: interquartile mean "
        "of the episode returns "
        "with a 95 % bootstrap interval; paired: the mean per-seed return difference to the "
        "best fixed setting with a 95 % t interval.",
        "",
        f"| policy | IQM return [95 % CI] | mean return | NRMSE % | {knob_label} | "
        "paired - best fixed |",
        "|---|---|---|---|---|---|",
    ]
    if agents:
        cells = policy_cells(by_name, agents, reference, digits=2, knob_digits=2)
        lines.append(f"| **{len(agents)} agents together** | {cells} |")
    for name in names:
        cells = policy_cells(
            by_name, [name], reference, digits=2, knob_digits=2, is_reference=name == best
        )
        role = " (best fixed, training seeds)" if name == best else ""
        role += " (default)" if name == default else ""
        lines.append(f"| {name}{role} | {cells} |")
    if args.clairvoyant:
        lines += [
            "",
            "The two clairvoyant rows see the true position, so no agent can run them "
            "(`agents.rl.clairvoyant`): the greedy one tries every fixed setting at each "
            "step on copies of the environment (the same measurements and random draws) and "
            "keeps the one whose step scores best, the best fixed setting where several tie; "
            "the other takes, seed by seed, the fixed setting "
            "with the best episode return. Their paired difference to the best fixed "
            "setting shows what adapting the knob could gain: overstated by the luck that "
            "choosing with hindsight picks up, and, for the greedy one, understated by "
            "choices whose gain comes in later steps.",
        ]
    if agents:
        others = [best] if default == best else [best, default]
        lines += [
            "",
            f"The {len(agents)} agents together against the best fixed setting and the "
            "default, paired by seed (the IQM difference with a bootstrap that resamples the "
            "same seeds for both sides; mean differences with 95 % t intervals):",
            "",
            *agents_against(by_name, agents, others, knob_label, what="setting", digits=2),
        ]
    text = "\n".join(lines) + "\n"
    slug = args.env.removeprefix("DGPTrack").lower().replace("-", "_")
    args.out.mkdir(parents=True, exist_ok=True)
    table = args.out / f"rl_{slug}.md"
    table.write_text(text)
    print(text)

    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(6.5, 4.2))
    points = {}
    for name in names:
        returns = np.array([row["return"] for row in by_name[name]])
        knob_mean = float(np.mean([row["per_step"] for row in by_name[name]]))
        points[name] = (knob_mean, *iqm_interval(returns))
    # the chart shows the policies near the best; those far below (tight gates that lose
    # the target) are named under it rather than squeezing the others into a line
    _, _, random_low, _ = points["random"]
    best_iqm = max(iqm for _, iqm, _, _ in points.values())
    floor = random_low - 0.5 * (best_iqm - random_low)
    below = [name for name, (_, iqm, _, _) in points.items() if iqm < floor]
    style = {
        "constant": dict(fmt="o", color="0.45"),
        "random": dict(fmt="x", color="k"),
        "agent": dict(fmt="D", color="C3"),
        "clairvoyant": dict(fmt="*", color="C0", ms=9),
        **{kind: dict(fmt="^", color="C2") for kind in TUNING_RULES},
        "hindsight": dict(fmt="s", color="C0"),
    }
    for name, (knob_mean, iqm, low, high) in points.items():
        if name in below:
            continue
        kind = policies[name][0]
        axis.errorbar(
            knob_mean, iqm, yerr=[[iqm - low], [high - iqm]], capsize=2, **{"ms": 5, **style[kind]}
        )
        if kind in ("constant", "random"):
            axis.annotate(
                name.removeprefix("fixed ") + (" (best fixed)" if name == best else ""),
                (knob_mean, iqm),
                fontsize=7,
                xytext=(4, -10 if kind == "random" else 3),
                textcoords="offset points",
            )
    axis.set_xscale("log")
    axis.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
    axis.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    axis.set_xticks([2, 3, 5, 10, 20, 30] if knob == "gate_threshold" else [2, 3, 4, 6, 10, 20])
    if below:
        axis.text(
            0.01,
            0.01,
            "below the chart: " + ", ".join(name.removeprefix("fixed ") for name in below),
            transform=axis.transAxes,
            fontsize=7,
        )
    axis.set_xlabel(f"{knob_label} per step")
    axis.set_ylabel("IQM episode return (95 % CI)")
    title = f"{args.env}, seeds {seed_range}; red diamonds: the agents"
    if tuned:
        title += "; green triangle: the tuned rule"
    if args.clairvoyant:
        title += ";\nblue: clairvoyant (star greedy per step, square best fixed per episode)"
    axis.set_title(title, fontsize=9)
    axis.grid(alpha=0.3)
    figure.tight_layout()
    path = args.out / "figures" / f"rl_{slug}.png"
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    print(f"wrote {table} and {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
