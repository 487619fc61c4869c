"""What each part of the default GP tracker buys: ``dgpt-rbcm`` against the centralized GP,
the other three aggregations and the tracker with one part of its model taken out, paired by
seed on the evaluation seeds (0-99 by default), on the reference and the random paths, S1-S4,
clutter rates 1 and 5, sigma_z = 1. No setting is chosen here; every arm keeps
``dgpt-rbcm``'s other settings.

Printed and written to ``--report`` (Markdown):

- per path mode and cell, each arm's mean episode 2-D RMSE minus ``dgpt-rbcm``'s on the same
  seeds (m), with its 95 % t interval, and over the 8 cells (the cells' mean, whose
  interval adds the cells' variances of the mean: the cells are strata of equal size);
- per arm over all cells of a path mode: the root mean square of the episodes' RMSE, the
  3-sigma coverage on steps where a sensor senses the target (mean of the axes over the
  episodes; nominal 99.73 %), the median over episodes of the median 2-D NEES there
  (nominal 1.39) and the share of learning steps that left q on a bound (issue 12's
  goal: at most 10 %);
- per scenario, the share of learning steps that left q on a bound, for every arm that
  learns;
- with the window arms, the NRMSE (%, mean of the axes) per cell against the learning
  window, the default's included.

The runs go through the evaluation's results store (``--out``, resumable, each run stored
as it finishes). ``--out results/paper`` reuses the runs that the ``--paper`` grid and
``scripts/random_paths.py`` stored there (``dgpt-rbcm``, ``gp`` and ``dgpt-gpoe`` on both
path modes), which are the same runs.

    python scripts/ablations.py --out results/paper --report docs/ablations.md
    python scripts/ablations.py --arms gp dgpt-rbcm/no-turn-modes --runs 10
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import dgpt_gym  # noqa: E402
from agents.state_space_dgpt import (  # noqa: E402
    LEARNING_MEMORY,
    LEARNING_WINDOW,
    PROCESS_NOISE_BOUNDS,
)
from dgpt_gym.benchmark.episodes import (  # noqa: E402
    interval_half_width,
    signed_interval,
    stratified_difference,
)
from dgpt_gym.benchmark.sweep import Grid, Variant, on_every_path_mode, sweep_metrics  # noqa: E402
from dgpt_gym.env import TRAJECTORY_MODES  # noqa: E402

REFERENCE = "dgpt-rbcm"
SCENARIOS = ("S1", "S2", "S3", "S4")
CLUTTER_RATES = (1.0, 5.0)
NOISE_STD = 1.0


WINDOWS = (2, 8, 20)
"""The learning windows (steps with data) of the window arms, beside the default's."""


def _without(name: str, **overrides) -> Variant:
    return Variant(f"{REFERENCE}/{name}", REFERENCE, tuple(overrides.items()))


ARMS = {
    "gp": ("the centralized GP: one Kalman update on every summary", "gp"),
    "dgpt-bcm": ("BCM aggregation, the exact posterior (the same numbers as `gp`)", "dgpt-bcm"),
    "dgpt-gpoe": ("GPoE aggregation (weights 1/M)", "dgpt-gpoe"),
    "dgpt-poe": ("PoE aggregation (weights 1)", "dgpt-poe"),
    "dgpt-rbcm/no-learning": (
        "q not learnt: held at its start, 1 m^2/s^3",
        _without("no-learning", learn_process_noise=False),
    ),
    "dgpt-rbcm/q-floor": (
        "q not learnt: held on its lower bound, 1e-4 m^2/s^3, where the learning ends on "
        "most of S1's steps",
        _without("q-floor", learn_process_noise=False, process_noise=PROCESS_NOISE_BOUNDS[0]),
    ),
    "dgpt-rbcm/recursive-learning": (
        "q the maximum of the episode's step evidences so far (forgotten over "
        f"{LEARNING_MEMORY:g} steps) instead of a Newton step on the last {LEARNING_WINDOW} "
        "steps' likelihood",
        _without("recursive-learning", learning="recursive"),
    ),
    **{
        f"dgpt-rbcm/window-{window}": (
            f"q learnt from the last {window} steps with data instead of {LEARNING_WINDOW}",
            _without(f"window-{window}", window=window),
        )
        for window in WINDOWS
    },
    "dgpt-rbcm/no-manoeuvres": (
        "no manoeuvre component in the NCV mode (q_m = 0)",
        _without("no-manoeuvres", manoeuvre_intensity=0.0),
    ),
    "dgpt-rbcm/no-turn-modes": (
        "no coordinated-turn modes: the NCV mode alone",
        _without("no-turn-modes", turn_rates=()),
    ),
    "dgpt-rbcm/no-silence": (
        "coverage gaps predicted by the model alone, not conditioned on the silence of the "
        "awake sensors",
        _without("no-silence", silence_particles=0),
    ),
    "dgpt-rbcm/no-gating": (
        "no association: each sensor's unweighted mean of its measurements",
        _without("no-gating", gating=False),
    ),
    "dgpt-rbcm/local-association": (
        "each sensor's measurements weighed on their own (eq. (27)), not jointly",
        _without("local-association", association="local"),
    ),
}
"""The arms, by name: what each changes against ``dgpt-rbcm`` and the tracker (a registered
id or a :class:`~dgpt_gym.benchmark.sweep.Variant` of ``dgpt-rbcm``)."""


def path_grids(arms, runs: int, first_seed: int) -> dict[str, Grid]:
    """``dgpt-rbcm`` and ``arms`` (names of :data:`ARMS`) on S1-S4 x clutter 1, 5 at
    sigma_z 1, by path mode."""
    grid = Grid(
        trackers=(REFERENCE, *(ARMS[name][1] for name in arms)),
        scenarios=SCENARIOS,
        noise_levels=(NOISE_STD,),
        clutter_rates=CLUTTER_RATES,
        runs=runs,
        first_seed=first_seed,
    )
    return on_every_path_mode(grid)


def report(episodes: dict[str, dict], arms) -> str:
    """The Markdown tables of the module docstring from each path mode's stored metrics
    (:func:`~dgpt_gym.benchmark.sweep.stored_metrics`, keyed by cell)."""
    cells = [(s, c) for s in SCENARIOS for c in CLUTTER_RATES]
    names = [f"{scenario} c{int(clutter)}" for scenario, clutter in cells]

    def column(mode, tracker, scenario, clutter, key):
        runs = episodes[mode][(tracker, scenario, NOISE_STD, clutter)]
        return np.array([run[key] for run in runs], float)

    lines = []
    for mode in TRAJECTORY_MODES:
        lines += [
            f"### {'Reference' if mode == 'fixed' else 'Random'} paths: episode RMSE minus "
            f"`{REFERENCE}`'s, m",
            "",
            "| arm | " + " | ".join(names) + " | all cells |",
            "|---|" + "---|" * (len(cells) + 1),
        ]
        for name in arms:
            differences = [
                column(mode, name, *cell, "rmse_2d") - column(mode, REFERENCE, *cell, "rmse_2d")
                for cell in cells
            ]
            row = [signed_interval(np.mean(d), interval_half_width(d)) for d in differences]
            row.append(signed_interval(*stratified_difference(differences)))
            lines.append(f"| `{name}` | " + " | ".join(row) + " |")
        lines.append("")
    lines += [
        "### Over all cells: RMSE and calibration on steps where a sensor senses the target",
        "",
        "Reference / random paths. RMSE: root mean square over the episodes of each "
        "episode's 2-D RMSE, m. Coverage: 3-sigma, mean of the axes over the episodes, % "
        "(nominal 99.73). NEES: median over episodes of the median 2-D NEES (nominal 1.39). "
        "On a bound: the learning steps that left q on a bound (either axis), mean over "
        "the episodes, %; - where q is not learnt.",
        "",
        "| arm | what it changes | RMSE | 3-sigma coverage | median NEES | on a bound |",
        "|---|---|---|---|---|---|",
    ]
    for name in (REFERENCE, *arms):
        rmse, coverage, nees, bound = [], [], [], []
        for mode in TRAJECTORY_MODES:
            values = np.concatenate([column(mode, name, *c, "rmse_2d") for c in cells])
            rmse.append(f"{np.sqrt(np.mean(values**2)):.2f}")
            axes = [
                np.concatenate(
                    [column(mode, name, *c, f"coverage_3sigma_{axis}_detected") for c in cells]
                )
                for axis in "xy"
            ]
            coverage.append(f"{100 * np.nanmean(axes):.2f}")
            per_episode = [column(mode, name, *c, "nees_median_detected") for c in cells]
            nees.append(f"{np.nanmedian(np.concatenate(per_episode)):.2f}")
            shares = np.concatenate([column(mode, name, *c, "share_at_bound") for c in cells])
            bound.append(_share_percent(shares))
        what = "the default" if name == REFERENCE else ARMS[name][0]
        lines.append(
            f"| `{name}` | {what} | {' / '.join(rmse)} | {' / '.join(coverage)} | "
            f"{' / '.join(nees)} | {' / '.join(bound)} |"
        )
    return "\n".join(lines + bound_table(episodes, arms) + window_table(episodes, arms)) + "\n"


def _share_percent(shares) -> str:
    """The mean of the episodes' shares of learning steps on a bound, in %, over the
    episodes that learnt (a NaN share: no learning step); "-" when none did."""
    shares = np.asarray(shares, float)
    learnt = shares[np.isfinite(shares)]
    return f"{100 * learnt.mean():.0f}" if learnt.size else "-"


def bound_table(episodes: dict[str, dict], arms) -> list[str]:
    """Per scenario (both clutter rates), the mean over the episodes that learnt of the share
    of learning steps that left q on a bound, %, reference / random paths, for
    ``dgpt-rbcm`` and each arm in ``arms`` that learns; each scenario's truth beside."""
    lines = [
        "",
        "### Learning steps with q on a bound, per scenario",
        "",
        "Mean over the episodes that learnt, %, reference / random paths, clutter 1 and 5. "
        "The paths' own intensity within a leg: S1 0.04 m^2/s^3 (nearly constant velocity), "
        "S2 and S3 0 between the turns; S4's motion is not NCV.",
        "",
        "| arm | " + " | ".join(SCENARIOS) + " |",
        "|---|" + "---|" * len(SCENARIOS),
    ]
    for name in (REFERENCE, *arms):
        row = []
        for scenario in SCENARIOS:
            shares = []
            for mode in TRAJECTORY_MODES:
                shares.append(
                    _share_percent(
                        [
                            run["share_at_bound"]
                            for clutter in CLUTTER_RATES
                            for run in episodes[mode][(name, scenario, NOISE_STD, clutter)]
                        ]
                    )
                )
            row.append(" / ".join(shares))
        if any(cell != "- / -" for cell in row):
            lines.append(f"| `{name}` | " + " | ".join(row) + " |")
    return lines


def window_table(episodes: dict[str, dict], arms) -> list[str]:
    """Issue 12's "NRMSE against window length per scenario": per path mode and cell, the
    mean over episodes of the NRMSE averaged over the axes (%, the paper's measure), for the
    default's learning window and each window arm in ``arms``; [] without window arms."""
    windows = sorted(
        [(LEARNING_WINDOW, REFERENCE)]
        + [(w, f"{REFERENCE}/window-{w}") for w in WINDOWS if f"{REFERENCE}/window-{w}" in arms]
    )
    if len(windows) == 1:
        return []
    cells = [(s, c) for s in SCENARIOS for c in CLUTTER_RATES]
    lines = [
        "",
        "### NRMSE against the learning window",
        "",
        "Mean over the episodes of the NRMSE averaged over the two axes, % (the paper's "
        f"measure); the default learns q over {LEARNING_WINDOW} steps with data.",
    ]
    for mode in TRAJECTORY_MODES:
        lines += [
            "",
            f"{'Reference' if mode == 'fixed' else 'Random'} paths:",
            "",
            "| window | " + " | ".join(f"{s} c{int(c)}" for s, c in cells) + " |",
            "|---|" + "---|" * len(cells),
        ]
        for window, name in windows:
            row = []
            for scenario, clutter in cells:
                runs = episodes[mode][(name, scenario, NOISE_STD, clutter)]
                values = [(run["nrmse_x"] + run["nrmse_y"]) / 2 for run in runs]
                row.append(f"{100 * np.mean(values):.2f}")
            lines.append(f"| {window} | " + " | ".join(row) + " |")
    return lines


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--arms",
        nargs="+",
        default=list(ARMS),
        choices=list(ARMS),
        metavar="ARM",
        help=f"default: all of {', '.join(ARMS)}",
    )
    parser.add_argument("--runs", type=int, default=100, help="episodes per cell")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "ablations")
    parser.add_argument("--report", type=Path, help="also write the tables to this file")
    parser.add_argument("--workers", type=int, default=None, help="default: all cores")
    parser.add_argument("--no-progress", action="store_true")
    args = parser.parse_args(argv)
    grids = path_grids(args.arms, args.runs, args.first_seed)
    episodes = {}
    for mode, grid in grids.items():
        done, episodes[mode] = sweep_metrics(grid, args.out, args.workers, not args.no_progress)
        print(f"{mode} paths: {done.ran} runs, {done.already_finished} already stored")
    command = "python scripts/ablations.py " + " ".join(sys.argv[1:] if argv is None else argv)
    text = (
        f"# What each part of `{REFERENCE}` buys\n\nGenerated by `{command.strip()}` "
        f"(dgpt-gym {dgpt_gym.__version__}; seeds {args.first_seed}-"
        f"{args.first_seed + args.runs - 1}, paired by seed).\n\n" + report(episodes, args.arms)
    )
    print(text)
    if args.report:
        args.report.write_text(text)


if __name__ == "__main__":
    main()
