"""Do the trackers hold beyond the paper's clutter rates? The paper runs clutter rates 1 and 5
and claims its approaches "can deal with varying ... clutter rates" (Sec. VIII); this runs
the same trackers from clutter rate 1 to 50 (clutter at the detecting sensors, the paper's
setting), S1-S4, on the reference paths and on random ones, sigma_z = 1, on the evaluation
seeds (0-29 by default; no setting is chosen here: the windows are the grid's, tuned on
training seeds at clutter rates 1 and 5).

Printed and written to ``--report`` (Markdown), with a figure (``--figure``, PNG) of the RMSE
against the clutter rate per scenario and path mode:

- per path mode, the 2-D RMSE (root mean square over the episodes of each episode's RMSE, m)
  per tracker, scenario and clutter rate;
- per path mode and clutter rate, each tracker's episode RMSE minus ``dgpt-rbcm``'s, paired
  by seed, as the mean over the four scenarios with its 95 % stratified interval (each
  scenario a stratum of equal weight);
- the calibration on steps where a sensor senses the target, per tracker, path mode and
  clutter rate: the 3-sigma coverage (mean over the episodes, both axes and the four
  scenarios; the lowest of the eight scenario-axes in parentheses) and the median over the
  episodes of the four scenarios of each one's median 2-D NEES (nominal 1.39).

The runs go through the evaluation's results store (``--out``, resumable, each run stored as
it finishes); a store that already holds runs with the same keys reuses them, so
``--out results/paper`` takes the ``--paper`` grid's runs of the same version (clutter 1
and 5, reference paths) instead of running them again.

    python scripts/clutter_sweep.py --report docs/clutter_sweep.md \\
        --figure docs/figures/clutter_sweep.png
    python scripts/clutter_sweep.py --trackers dgpt-rbcm imm-pda --runs 5 --clutter-rates 1 20
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from matplotlib.ticker import LogLocator, ScalarFormatter

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import dgpt_gym  # noqa: E402
from dgpt_gym.benchmark.episodes import (  # noqa: E402
    root_mean_square,
    signed_interval,
    stratified_difference,
)
from dgpt_gym.benchmark.plots import new_figure, save_figure  # noqa: E402
from dgpt_gym.benchmark.sweep import Grid, on_every_path_mode, sweep_metrics  # noqa: E402
from dgpt_gym.env import TRAJECTORY_MODES  # noqa: E402

TRACKERS = ("dgpt-rbcm", "gp", "hybrid", "pda", "imm-pda", "cpf", "clairvoyant")
REFERENCE = "dgpt-rbcm"
SCENARIOS = ("S1", "S2", "S3", "S4")
CLUTTER_RATES = (1.0, 5.0, 10.0, 20.0, 50.0)
NOISE_STD = 1.0


def path_grids(trackers, clutter_rates, runs: int, first_seed: int) -> dict[str, Grid]:
    """The two grids, by path mode: ``trackers`` on S1-S4 x ``clutter_rates`` at sigma_z 1."""
    grid = Grid(
        trackers=tuple(trackers),
        scenarios=SCENARIOS,
        noise_levels=(NOISE_STD,),
        clutter_rates=tuple(float(rate) for rate in clutter_rates),
        runs=runs,
        first_seed=first_seed,
    )
    return on_every_path_mode(grid)


def _rate(clutter: float) -> str:
    return f"{clutter:g}"


def finite(values: np.ndarray) -> np.ndarray:
    """The finite entries of ``values`` (a tracker without a variance stores NaN coverage)."""
    return values[np.isfinite(values)]


def report(episodes: dict[str, dict], trackers, clutter_rates) -> str:
    """The Markdown tables of the module docstring from each path mode's stored metrics
    (:func:`~dgpt_gym.benchmark.sweep.stored_metrics`, keyed by cell)."""

    def column(mode, tracker, scenario, clutter, key):
        runs = episodes[mode][(tracker, scenario, NOISE_STD, clutter)]
        return np.array([run[key] for run in runs], float)

    rates = " | ".join(f"c{_rate(c)}" for c in clutter_rates)
    rule = "|---|" + "---|" * len(clutter_rates)
    lines = []
    for mode in episodes:
        lines += [
            f"### RMSE, m, {mode} paths",
            "",
            "Root mean square over the episodes of each episode's 2-D RMSE; `cN`: clutter rate N.",
            "",
            f"| scenario | tracker | {rates} |",
            "|---" + rule,
        ]
        for scenario in SCENARIOS:
            for tracker in trackers:
                cells = [
                    f"{root_mean_square(column(mode, tracker, scenario, c, 'rmse_2d')):.2f}"
                    for c in clutter_rates
                ]
                lines.append(f"| {scenario} | `{tracker}` | " + " | ".join(cells) + " |")
        lines.append("")
    if REFERENCE in trackers:
        lines += [
            f"### Paired difference to `{REFERENCE}`, m, mean over S1-S4",
            "",
            "Each seed's episode RMSE minus the reference's on the same seed, averaged per "
            "scenario and then over the four scenarios, with the 95 % stratified interval; "
            "bold: the interval excludes 0 (negative: better than the reference).",
            "",
            f"| tracker | paths | {rates} |",
            "|---" + rule,
        ]
        for tracker in trackers:
            if tracker == REFERENCE:
                continue
            for mode in episodes:
                cells = []
                for clutter in clutter_rates:
                    differences = [
                        column(mode, tracker, s, clutter, "rmse_2d")
                        - column(mode, REFERENCE, s, clutter, "rmse_2d")
                        for s in SCENARIOS
                    ]
                    cells.append(signed_interval(*stratified_difference(differences)))
                lines.append(f"| `{tracker}` | {mode} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += [
        "### Calibration on steps where a sensor senses the target",
        "",
        "3-sigma coverage, %, mean over episodes and over both axes and the four scenarios "
        "(nominal 99.73; the lowest scenario-axis in parentheses), and the median over "
        "episodes and scenarios of the median 2-D NEES (nominal 1.39). Trackers that report "
        "no variance are left out.",
        "",
        f"| tracker | paths | {rates} |",
        "|---" + rule,
    ]
    for tracker in trackers:
        for mode in episodes:
            cells = []
            for clutter in clutter_rates:
                # per scenario-axis, the mean over the episodes that report a variance
                coverage = []
                for scenario in SCENARIOS:
                    for a in "xy":
                        key = f"coverage_3sigma_{a}_detected"
                        values = finite(column(mode, tracker, scenario, clutter, key))
                        if values.size:
                            coverage.append(100 * np.mean(values))
                if not coverage:  # no variance reported in this cell
                    cells.append("-")
                    continue
                nees = finite(
                    np.concatenate(
                        [
                            column(mode, tracker, s, clutter, "nees_median_detected")
                            for s in SCENARIOS
                        ]
                    )
                )
                median = np.median(nees) if nees.size else np.nan
                cells.append(f"{np.mean(coverage):.2f} ({np.min(coverage):.2f}), {median:.2f}")
            if any(cell != "-" for cell in cells):
                lines.append(f"| `{tracker}` | {mode} | " + " | ".join(cells) + " |")
    lines.append("")
    return "\n".join(lines)


def plot(episodes: dict[str, dict], trackers, clutter_rates, path: Path) -> Path:
    """RMSE against the clutter rate, one panel per path mode (rows) and scenario
    (columns), both axes logarithmic."""
    modes = list(episodes)
    figure = new_figure((13, 3.2 * len(modes)))
    for row, mode in enumerate(modes):
        for index, scenario in enumerate(SCENARIOS):
            axes = figure.add_subplot(len(modes), len(SCENARIOS), row * len(SCENARIOS) + index + 1)
            for tracker in trackers:
                values = [
                    root_mean_square(
                        [
                            run["rmse_2d"]
                            for run in episodes[mode][(tracker, scenario, NOISE_STD, c)]
                        ]
                    )
                    for c in clutter_rates
                ]
                style = "k--" if tracker == "clairvoyant" else "-o"
                axes.plot(clutter_rates, values, style, label=tracker, ms=3, lw=1.2)
            axes.set(xscale="log", yscale="log", title=f"{scenario}, {mode} paths")
            axes.set_xticks(clutter_rates, [_rate(c) for c in clutter_rates])
            axes.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
            axes.yaxis.set_major_formatter(ScalarFormatter())
            axes.minorticks_off()
            if index == 0:
                axes.set_ylabel("2-D RMSE, m")
            if row == len(modes) - 1:
                axes.set_xlabel("clutter rate")
    figure.axes[0].legend(fontsize=7)
    return save_figure(figure, path)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trackers", nargs="+", default=list(TRACKERS), metavar="ID")
    parser.add_argument(
        "--clutter-rates", nargs="+", type=float, default=list(CLUTTER_RATES), metavar="RATE"
    )
    parser.add_argument("--runs", type=int, default=30, help="episodes per cell")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "clutter_sweep")
    parser.add_argument("--report", type=Path, help="also write the tables to this file")
    parser.add_argument("--figure", type=Path, help="write the RMSE figure (PNG) here")
    parser.add_argument("--workers", type=int, default=None, help="default: all cores")
    parser.add_argument("--no-progress", action="store_true")
    args = parser.parse_args(argv)
    if len(set(args.trackers)) != len(args.trackers):
        parser.error(f"--trackers must not repeat an id; got {args.trackers}")
    rates = sorted(set(args.clutter_rates))
    grids = path_grids(args.trackers, rates, args.runs, args.first_seed)
    episodes = {}
    for mode in TRAJECTORY_MODES:
        done, episodes[mode] = sweep_metrics(
            grids[mode], args.out, args.workers, not args.no_progress
        )
        print(f"{mode} paths: {done.ran} runs, {done.already_finished} already stored")
    text = report(episodes, args.trackers, rates)
    command = "python scripts/clutter_sweep.py " + " ".join(sys.argv[1:] if argv is None else argv)
    text = (
        f"# The trackers beyond the paper's clutter rates\n\nGenerated by `{command.strip()}` "
        f"(dgpt-gym {dgpt_gym.__version__}; seeds {args.first_seed}-"
        f"{args.first_seed + args.runs - 1}, sigma_z {NOISE_STD:g}, clutter at the sensors "
        f"that sense the target).\n\n{text}"
    )
    print(text)
    if args.report:
        args.report.write_text(text)
    if args.figure:
        print(f"figure: {plot(episodes, args.trackers, rates, args.figure)}")


if __name__ == "__main__":
    main()
