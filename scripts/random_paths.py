"""Do the trackers hold off the paper's four reference paths? The same trackers on the
reference paths (``trajectory="fixed"``) and on a new random path per episode
(``"random"``: the scenario's kind of motion with random waypoints, turn rates and start),
S1-S4, clutter rates 1 and 5, sigma_z = 1, on the evaluation seeds (0-99 by default; no
setting is chosen here: the windows are the grid's, tuned on training seeds of both path
modes).

Printed and written to ``--report`` (Markdown), per tracker and cell:

- the 2-D RMSE on random paths (root mean square over the episodes of each episode's
  RMSE, m) and its ratio to the reference paths' with a 95 % bootstrap interval (episodes
  resampled within each mode; issue 12's goal 4 asks for at most 1.3). The clairvoyant
  floor's own ratio shows how much harder the random paths are for any tracker;
- on random paths, each tracker's mean episode RMSE minus ``dgpt-rbcm``'s, paired by seed,
  with its 95 % t interval;
- on random paths, the calibration on steps where a sensor senses the target: 3-sigma
  coverage per axis (mean over episodes) and the median over episodes of the median 2-D NEES
  (nominal 1.39).

The runs go through the evaluation's results store (``--out``, resumable, each run stored
as it finishes); ``--out results/paper`` reuses the ``--paper`` grid's reference-path runs
of the same version, which are the same runs.

Every setting was chosen in the environment's one sensor layout (``layout_seed=0``).
``--layout per_episode`` asks whether the results hold in layouts no setting saw: both
path modes again with the run of seed s in layout s (:class:`Grid`'s ``layout``; seed 0's
is layout 0), on the same paths, against their runs in layout 0 (read from the store as
they are; the ratio's interval resamples the seeds together). Per path mode it writes the
tables above with layout 0 in place of the reference paths, plus each cell's median
episode RMSE and the UCB's coverage and half-width over the RMSE; then goal 4's ratio with
both path modes in unseen layouts.

``--verify N`` (either mode) then re-runs N of the runs the report read, whichever
dgpt-gym version stored them, and checks every metric but the wall-clock ones against the
stored one.

    python scripts/random_paths.py --report docs/random_paths.md
    python scripts/random_paths.py --trackers dgpt-rbcm imm-pda --runs 10
    python scripts/random_paths.py --layout per_episode --report docs/random_layouts.md --verify 400
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import dgpt_gym  # noqa: E402
from dgpt_gym.benchmark.episodes import (  # noqa: E402
    interval_half_width,
    root_mean_square,
    signed_interval,
)
from dgpt_gym.benchmark.store import ResultsStore  # noqa: E402
from dgpt_gym.benchmark.sweep import (  # noqa: E402
    Grid,
    on_every_path_mode,
    stored_metrics,
    sweep_metrics,
    verify_store,
)
from dgpt_gym.env import LAYOUT_MODES  # noqa: E402

TRACKERS = ("gp", "dgpt-rbcm", "dgpt-gpoe", "hybrid", "pda", "imm-pda", "cpf", "clairvoyant")
REFERENCE = "dgpt-rbcm"
SCENARIOS = ("S1", "S2", "S3", "S4")
CLUTTER_RATES = (1.0, 5.0)
NOISE_STD = 1.0
GOAL_RATIO = 1.3
"""Issue 12's goal 4: random-path RMSE at most this times the reference paths'."""
RESAMPLES = 2000
"""Bootstrap resamples of each ratio's interval."""


def path_grids(trackers, runs: int, first_seed: int, layout: str = "fixed") -> dict[str, Grid]:
    """The two grids, by path mode: ``trackers`` on S1-S4 x clutter 1, 5 at sigma_z 1, in
    the environment's layout or, with ``layout="per_episode"``, in layout s for seed s."""
    grid = Grid(
        trackers=tuple(trackers),
        scenarios=SCENARIOS,
        noise_levels=(NOISE_STD,),
        clutter_rates=CLUTTER_RATES,
        runs=runs,
        first_seed=first_seed,
        layout=layout,
    )
    return on_every_path_mode(grid)


def ratio_interval(base, other, seed: int = 0, paired: bool = False) -> tuple[float, float, float]:
    """RMS(``other``) / RMS(``base``) and its 95 % percentile-bootstrap interval. Unpaired,
    the episodes of each condition are resampled on their own (a random path and the
    reference path of a seed differ, so seeds do not pair them); ``paired``, the seeds are
    resampled together (the run of seed s in layout s and in layout 0 share their path)."""

    def ratio(a, b, axis=-1):
        return root_mean_square(b, axis) / root_mean_square(a, axis)

    result = stats.bootstrap(
        (np.asarray(base, float), np.asarray(other, float)),
        ratio,
        n_resamples=RESAMPLES,
        method="percentile",
        vectorized=True,
        paired=paired,
        random_state=np.random.default_rng(seed),  # scipy >= 1.10 (rng= from 1.15)
    )
    interval = result.confidence_interval
    return float(ratio(base, other)), float(interval.low), float(interval.high)


class Comparison(NamedTuple):
    """What :func:`report` compares: the runs of ``other`` against those of ``base``
    (names as they read in the headings), whether seeds pair them, and the ratio above
    which a cell is bold (None: none is)."""

    base: str
    other: str
    paired: bool
    goal: float | None


GOAL_4 = Comparison("reference paths", "random paths", paired=False, goal=GOAL_RATIO)
"""Issue 12's goal 4: random paths against the reference paths, in layout 0."""


def layout_comparison(paths: str) -> Comparison:
    """Unseen layouts against layout 0 on ``paths`` ("reference paths" or "random
    paths"): seed s in layout s and in layout 0 runs the same path."""
    return Comparison(f"layout 0, {paths}", f"unseen layouts, {paths}", paired=True, goal=None)


REPORT_SECTIONS = ("rmse", "ratio", "paired", "calibration")
"""The tables :func:`report` writes by default; ``"median"`` (each cell's median episode
RMSE) and ``"ucb"`` (the UCB's coverage and width) are there to ask for."""


def report(
    base: dict,
    other: dict,
    trackers,
    comparison: Comparison = GOAL_4,
    only: tuple[str, ...] = REPORT_SECTIONS,
) -> str:
    """The Markdown tables of the module docstring from the episodes of both conditions
    (those of ``only``, in order): ``other``'s RMSE (``base``'s beside it), their ratio,
    and on ``other`` the paired difference to the reference tracker and the calibration;
    on request each cell's median episode RMSE (``"median"``) and the UCB's coverage and
    half-width over the RMSE (``"ucb"``)."""
    cells = [(s, c) for s in SCENARIOS for c in CLUTTER_RATES]
    names = [f"{scenario} c{int(clutter)}" for scenario, clutter in cells]
    header = "| tracker | " + " | ".join(names) + " |\n|---|" + "---|" * len(cells)

    def column(episodes, tracker, scenario, clutter, key):
        return np.array(
            [run[key] for run in episodes[(tracker, scenario, NOISE_STD, clutter)]], float
        )

    tables = {
        name: [header] for name in ("rmse", "median", "ratio", "paired", "calibration", "ucb")
    }
    for tracker in trackers:
        row = {name: [] for name in tables}  # this tracker's cell of each table, by cell
        for scenario, clutter in cells:
            on_base = column(base, tracker, scenario, clutter, "rmse_2d")
            on_other = column(other, tracker, scenario, clutter, "rmse_2d")
            value, low, high = ratio_interval(on_base, on_other, paired=comparison.paired)
            bold = "**" if comparison.goal is not None and low > comparison.goal else ""
            row["ratio"].append(f"{bold}{value:.2f}{bold} [{low:.2f}, {high:.2f}]")
            row["rmse"].append(
                f"{root_mean_square(on_other):.2f} ({root_mean_square(on_base):.2f})"
            )
            row["median"].append(f"{np.median(on_other):.2f} ({np.median(on_base):.2f})")
            if tracker == REFERENCE or REFERENCE not in trackers:
                row["paired"].append("-")
            else:
                difference = on_other - column(other, REFERENCE, scenario, clutter, "rmse_2d")
                row["paired"].append(
                    signed_interval(np.mean(difference), interval_half_width(difference))
                )
            coverage = [
                100
                * np.nanmean(
                    column(other, tracker, scenario, clutter, f"coverage_3sigma_{a}_detected")
                )
                for a in "xy"
            ]
            nees = np.nanmedian(column(other, tracker, scenario, clutter, "nees_median_detected"))
            row["calibration"].append(f"{coverage[0]:.1f} / {coverage[1]:.1f}, {nees:.2f}")
            if "ucb" in only:  # hand-made episodes without a UCB's metrics need not have them
                row["ucb"].append(ucb_cell(other[(tracker, scenario, NOISE_STD, clutter)]))
        for name, table in tables.items():
            table.append(f"| `{tracker}` | " + " | ".join(row[name]) + " |")
    runs = len(next(iter(other.values())))
    resampled = (
        "seeds resampled together (they pair the runs)"
        if comparison.paired
        else "episodes resampled within each condition"
    )
    goal = (
        ""
        if comparison.goal is None
        else f" Issue 12's goal 4 asks for at most {comparison.goal}; bold: the whole "
        f"interval is above {comparison.goal}."
    )
    sections = {
        "rmse": [
            f"### RMSE, {comparison.other} ({comparison.base} in parentheses), m",
            "",
            f"Root mean square over the {runs} episodes of each episode's 2-D RMSE; `cN`: "
            "clutter rate N, sigma_z 1.",
            "",
            *tables["rmse"],
        ],
        "median": [
            f"### Median episode RMSE, {comparison.other} ({comparison.base} in parentheses), m",
            "",
            "Half the episodes lie below; the root mean square of the RMSE table is weighted "
            "toward the worst.",
            "",
            *tables["median"],
        ],
        "ratio": [
            f"### Ratio, {comparison.other} / {comparison.base}, with 95 % bootstrap intervals",
            "",
            f"The ratio of the two RMSEs; {resampled}.{goal}",
            "",
            *tables["ratio"],
        ],
        "paired": [
            f"### Paired difference to `{REFERENCE}`, {comparison.other}, m",
            "",
            "Mean over the seeds of the episode RMSE minus the reference's, with the 95 % t "
            "interval; bold: the interval excludes 0 (negative: better than the reference).",
            "",
            *tables["paired"],
        ],
        "calibration": [
            f"### Calibration, {comparison.other}, steps where a sensor senses the target",
            "",
            "3-sigma coverage X / Y, % (mean over episodes; nominal 99.73), and the median "
            "over episodes of the median 2-D NEES (nominal 1.39).",
            "",
            *tables["calibration"],
        ],
        "ucb": [
            f"### Upper confidence bound, {comparison.other}, steps where a sensor senses the "
            "target",
            "",
            "Coverage of the UCB X / Y, % (mean over episodes; issue 12 asks at least 99.7 for "
            "`dgpt-rbcm`), and its half-width over the RMSE on the same steps, X / Y (mean "
            "half-width over mean RMSE, as the grid's calibration table; at most 4); `-`: no "
            "UCB.",
            "",
            *tables["ucb"],
        ],
    }
    return "".join("\n".join(sections[name]) + "\n\n" for name in only)


def ucb_cell(episodes: list[dict]) -> str:
    """The UCB's coverage per axis (mean over ``episodes``, %) and its half-width over the
    RMSE (the means over episodes of each), on the steps where a sensor senses the target;
    "-" for a tracker without a UCB."""

    def mean(key):  # over the episodes that have the value, as the grid's summaries
        values = np.array([episode[key] for episode in episodes], dtype=float)
        return float(np.mean(values[~np.isnan(values)])) if (~np.isnan(values)).any() else np.nan

    coverage = [100 * mean(f"ucb_coverage_{axis}_detected") for axis in "xy"]
    if np.isnan(coverage).all():
        return "-"
    ratio = [
        mean(f"ucb_width_{axis}_detected") / 2.0 / mean(f"rmse_{axis}_detected") for axis in "xy"
    ]
    return f"{coverage[0]:.2f} / {coverage[1]:.2f}, {ratio[0]:.2f} / {ratio[1]:.2f}"


def stored_versions(grids, out: Path) -> list[str]:
    """The dgpt-gym versions that stored the finished runs of ``grids`` in ``out``."""
    keys = {unit.key for grid in grids for unit in grid.units()}
    with ResultsStore(out) as store:
        return sorted({row["version"] for row in store.rows(keys, status="ok")})


def layout_runs(trackers, runs: int, first_seed: int, out: Path, workers, progress):
    """The episodes in layout 0 (already in ``out``: the default run of this script, or the
    ``--paper`` grid's and this script's with ``--out results/paper``; read as stored,
    whichever version stored them) and in unseen layouts (run now, or found in ``out``), by
    path mode; the versions that stored the layout-0 runs; and every grid read."""
    base_grids = path_grids(trackers, runs, first_seed)
    unseen_grids = path_grids(trackers, runs, first_seed, layout="per_episode")
    try:  # before running anything
        base = {mode: stored_metrics(grid, out) for mode, grid in base_grids.items()}
    except ValueError as error:
        raise SystemExit(
            f"{error}: run `python scripts/random_paths.py --out {out}` (same --trackers, "
            "--runs, --first-seed) first, for the runs in layout 0"
        ) from None
    unseen = {}
    for mode, grid in unseen_grids.items():
        done, unseen[mode] = sweep_metrics(grid, out, workers, progress)
        print(
            f"{mode} paths in unseen layouts: {done.ran} runs, "
            f"{done.already_finished} already stored"
        )
    versions = stored_versions(base_grids.values(), out)
    return base, unseen, versions, [*base_grids.values(), *unseen_grids.values()]


def layouts_report(base: dict, unseen: dict, trackers, versions: list[str]) -> str:
    """The tables of :func:`report` for each path mode, unseen layouts against layout 0
    (``base`` and ``unseen`` by path mode, as :func:`layout_runs` returns them), and goal
    4's ratio with both path modes in unseen layouts; ``versions``: those that stored the
    layout-0 runs."""
    sections = [
        f"## {paths.capitalize()}\n\n"
        + report(
            base[mode],
            unseen[mode],
            trackers,
            layout_comparison(paths),
            only=("rmse", "median", "ratio", "paired", "calibration", "ucb"),
        )
        for mode, paths in (("random", "random paths"), ("fixed", "reference paths"))
    ]
    sections.append(
        "## Random against reference paths, both in unseen layouts\n\n"
        "Issue 12's goal 4 with the reference paths in unseen layouts too, a few of which "
        "leave a coverage gap on them.\n\n"
        + report(
            unseen["fixed"],
            unseen["random"],
            trackers,
            GOAL_4._replace(base="reference paths in unseen layouts", other="random paths"),
            only=("ratio",),
        )
    )
    return (
        "Layout 0 is the one every setting was chosen in (training seeds 1000 and up); the "
        "run of seed s here is in layout s, on the same path as its layout-0 run (seed 0's "
        "is layout 0 itself, so one pair of each cell is the same run twice). The layout-0 "
        f"runs are read as stored, by dgpt-gym {', '.join(versions)}.\n\n" + "".join(sections)
    )


def verify(grids, out: Path, count: int, workers) -> int:
    """``--verify N``: re-run N of the runs the report read, whichever version stored them,
    and compare every metric but the wall-clock ones; 1 if one differs."""
    checked = verify_store(
        grids, out, count, workers or os.cpu_count() or 1, progress=False, any_version=True
    )
    for line in checked.mismatches:
        print(f"  differs: {line}")
    verdict = (
        "every metric but the wall-clock ones equals the stored one"
        if not checked.mismatches
        else "some differ"
    )
    print(
        f"re-ran {checked.checked} of the runs read, {checked.checked_other_versions} of them "
        f"stored by other versions than {dgpt_gym.__version__}: {verdict}"
    )
    return 1 if checked.mismatches else 0


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trackers", nargs="+", default=list(TRACKERS), metavar="ID")
    parser.add_argument("--runs", type=int, default=100, help="episodes per cell")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "random_paths")
    parser.add_argument("--report", type=Path, help="also write the tables to this file")
    parser.add_argument("--workers", type=int, default=None, help="default: all cores")
    parser.add_argument(
        "--layout",
        choices=LAYOUT_MODES,
        default="fixed",
        help="fixed: random against reference paths in layout 0; per_episode: both path "
        "modes in unseen layouts (seed s in layout s) against layout 0",
    )
    parser.add_argument(
        "--verify",
        type=int,
        metavar="N",
        help="then re-run N of the runs the report read, whichever version stored them, and "
        "check that every metric but the wall-clock ones is the stored one",
    )
    parser.add_argument("--no-progress", action="store_true")
    args = parser.parse_args(argv)
    progress = not args.no_progress
    if args.layout == "per_episode":
        title = "The trackers in unseen sensor layouts"
        base, unseen, versions, grids = layout_runs(
            args.trackers, args.runs, args.first_seed, args.out, args.workers, progress
        )
        if versions != [dgpt_gym.__version__]:
            print(
                f"note: the layout-0 runs were stored by dgpt-gym {', '.join(versions)}; "
                "--verify N re-runs N of the runs read with this code",
                file=sys.stderr,
            )
        text = layouts_report(base, unseen, args.trackers, versions)
    else:
        title = "The trackers off the reference paths"
        episodes, grids = {}, list(path_grids(args.trackers, args.runs, args.first_seed).values())
        for grid in grids:
            done, episodes[grid.trajectory] = sweep_metrics(grid, args.out, args.workers, progress)
            print(
                f"{grid.trajectory} paths: {done.ran} runs, {done.already_finished} already stored"
            )
        text = report(episodes["fixed"], episodes["random"], args.trackers)
    command = "python scripts/random_paths.py " + " ".join(sys.argv[1:] if argv is None else argv)
    text = (
        f"# {title}\n\nGenerated by `{command.strip()}` "
        f"(dgpt-gym {dgpt_gym.__version__}; seeds {args.first_seed}-"
        f"{args.first_seed + args.runs - 1}).\n\n{text}"
    )
    print(text)
    if args.report:
        args.report.write_text(text)
    if args.verify is not None:
        raise SystemExit(verify(grids, args.out, args.verify, args.workers))


if __name__ == "__main__":
    main()
