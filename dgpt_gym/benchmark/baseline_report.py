"""Tables of the paper's trackers against the field's standard trackers and the clairvoyant
floor, of every tracker's consistency (NEES, sigma coverage, track loss), and of the
calibration goals per cell.

Inputs are per-cell summaries (:func:`dgpt_gym.benchmark.sweep.summarize_store` with
:func:`dgpt_gym.benchmark.episodes.add_floor_ratios` applied); metric names are those of
:meth:`dgpt_gym.benchmark.episodes.EpisodeResult.metrics`.
"""

from __future__ import annotations

import math

import numpy as np

from dgpt_gym.benchmark.episodes import interval_half_width
from dgpt_gym.benchmark.metrics import NOMINAL_ANEES, NOMINAL_COVERAGE, NOMINAL_MEDIAN_NEES
from dgpt_gym.benchmark.protocol import DEFAULT_GP_TRACKERS, PAPER_GP_TRACKERS

__all__ = [
    "CALIBRATION_GOALS",
    "CALIBRATION_TRACKERS",
    "calibration_markdown",
    "COMPARISON_TRACKERS",
    "FLOOR",
    "PAIRED_REFERENCE",
    "comparison_markdown",
    "consistency_markdown",
    "paired_markdown",
]

PAIRED_REFERENCE = "dgpt-rbcm"
"""The paper's main tracker, against which every other is compared seed by seed."""

FLOOR = "clairvoyant"
COMPARISON_TRACKERS = (
    ("clairvoyant", "imm-pda", "pda")
    + PAPER_GP_TRACKERS
    + ("hybrid", "hybrid-trend", "hybrid-paper", "cpf")
)
"""Row order of the comparison; trackers of the sweep not listed here follow."""


CALIBRATION_TRACKERS = DEFAULT_GP_TRACKERS + ("hybrid",)
"""The trackers whose uncertainty the calibration goals concern: the default GP trackers and
the exact hybrid."""

CALIBRATION_GOALS = {
    "coverage_3sigma": 0.99,
    "nees_median": (0.7, 2.8),
    "ucb_coverage": 0.997,
    "ucb_half_width_to_rmse": 4.0,
}
"""Per cell, on steps where some sensor senses the target: 3-sigma coverage of at least 99 %
per axis (nominal 99.73 %) and a median 2-D NEES within [0.7, 2.8] (nominal 1.39); for
DGPT-RBCM's UCB, coverage of at least 99.7 % with a mean half-width of at most 4 times the
RMSE. A cell whose mean misses the coverage goal may still be consistent with it: the
table gives the interval over runs."""


def _value(row: dict, key: str) -> float:
    value = row.get(key)
    return float("nan") if value is None else float(value)


def _ordered_trackers(summaries: list[dict]) -> list[str]:
    present = list(dict.fromkeys(row["tracker"] for row in summaries))
    return [t for t in COMPARISON_TRACKERS if t in present] + [
        t for t in present if t not in COMPARISON_TRACKERS
    ]


def comparison_markdown(summaries: list[dict], noise_std: float = 1.0) -> str:
    """Per tracker and (scenario, clutter rate) at ``noise_std``: mean NRMSE over both axes
    (%, with the 95 % interval over runs), and the 2-D RMSE divided by the clairvoyant
    floor's."""
    rows = [row for row in summaries if row["noise_std"] == noise_std]
    cells = sorted({(row["scenario"], row["clutter_rate"]) for row in rows})
    by_key = {(row["tracker"], row["scenario"], row["clutter_rate"]): row for row in rows}
    header = "| tracker | " + " | ".join(f"{s} c{c:g}" for s, c in cells) + " | mean |"
    rule = "|---|" + "---|" * (len(cells) + 1)
    nrmse_lines = [header, rule]
    ratio_lines = [header, rule]
    for tracker in _ordered_trackers(rows):
        nrmse_cells, ratio_cells, nrmses, ratios = [], [], [], []
        for scenario, clutter in cells:
            row = by_key.get((tracker, scenario, clutter))
            if row is None:
                nrmse_cells.append("-")
                ratio_cells.append("-")
                continue
            nrmse = 50 * (row["nrmse_x"] + row["nrmse_y"])
            interval = 50 * (_value(row, "nrmse_x_ci95") + _value(row, "nrmse_y_ci95"))
            nrmses.append(nrmse)
            nrmse_cells.append(
                f"{nrmse:.2f}" + ("" if math.isnan(interval) else f" ± {interval:.2f}")
            )
            ratio = _value(row, "rmse_ratio_to_floor")
            ratios.append(ratio)
            ratio_cells.append("-" if math.isnan(ratio) else f"{ratio:.2f}")
        complete = len(nrmses) == len(cells)
        nrmse_mean = f"{np.mean(nrmses):.2f}" if complete else "-"
        finite = [r for r in ratios if not math.isnan(r)]
        ratio_mean = f"{np.mean(finite):.2f}" if complete and len(finite) == len(cells) else "-"
        nrmse_lines.append(f"| {tracker} | " + " | ".join(nrmse_cells) + f" | {nrmse_mean} |")
        ratio_lines.append(f"| {tracker} | " + " | ".join(ratio_cells) + f" | {ratio_mean} |")
    runs = sorted({int(row["n_runs"]) for row in rows})
    return "\n".join(
        [
            f"### Mean NRMSE over both axes, %, sigma_z = {noise_std:g}"
            f" ({', '.join(map(str, runs))} runs per cell; ± the 95 % interval over runs)",
            "",
            *nrmse_lines,
            "",
            f"### 2-D RMSE divided by the clairvoyant floor's, sigma_z = {noise_std:g}",
            "",
            *ratio_lines,
            "",
        ]
    )


def consistency_markdown(summaries: list[dict]) -> str:
    """Per tracker, averaged over its cells: ANEES and median NEES (2-D), the per-axis
    coverage of the 1, 2 and 3 sigma intervals, on steps where some sensor senses the
    target and on coverage-gap steps, and the track-loss rate."""
    nominal = (
        f"nominal: ANEES {NOMINAL_ANEES:g}, median NEES {NOMINAL_MEDIAN_NEES:.2f}, coverage "
        + " / ".join(f"{100 * NOMINAL_COVERAGE[k]:.1f}" for k in (1, 2, 3))
        + " %"
    )
    lines = [
        f"Means over each tracker's cells ({nominal}). Coverage X / Y: share of steps whose"
        " estimate +- k sigma contains the true coordinate. Track loss: share of runs with at"
        " least 10 consecutive steps of error above twice the sensing range.",
        "",
        "| tracker | steps | ANEES | median NEES | 1 sigma X / Y % | 2 sigma X / Y % | 3 sigma X / Y % | track loss % |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for tracker in _ordered_trackers(summaries):
        mine = [row for row in summaries if row["tracker"] == tracker]
        for part, suffix in (("detected", "_detected"), ("gap", "_gap")):

            def mean(key: str, rows=mine, suffix=suffix) -> float:
                values = [_value(row, key + suffix) for row in rows]
                values = [v for v in values if not math.isnan(v)]
                return float(np.mean(values)) if values else float("nan")

            coverage = [
                f"{100 * mean(f'coverage_{k}sigma_x'):.1f} / {100 * mean(f'coverage_{k}sigma_y'):.1f}"
                for k in (1, 2, 3)
            ]
            loss = 100 * float(np.mean([_value(row, "track_loss_rate") for row in mine]))
            lines.append(
                f"| {tracker if part == 'detected' else ''} | {part} | {mean('anees'):.2f} | "
                f"{mean('nees_median'):.2f} | "
                + " | ".join(coverage)
                + f" | {f'{loss:.1f}' if part == 'detected' else ''} |"
            )
    return "\n".join(lines + [""])


def paired_markdown(
    per_run: dict[tuple, dict[int, float]],
    noise_std: float = 1.0,
    reference: str = PAIRED_REFERENCE,
) -> str:
    """Paired comparison with ``reference`` at ``noise_std``: per tracker and (scenario,
    clutter rate), the mean over shared seeds of (tracker - reference) mean-over-axes NRMSE,
    in percentage points, with the 95 % Student-t interval of that mean. ``per_run`` maps
    (tracker, scenario, noise_std, clutter_rate) to {seed: NRMSE}."""
    cells = sorted({(k[1], k[3]) for k in per_run if k[2] == noise_std})
    trackers = _ordered_trackers(
        [{"tracker": k[0]} for k in per_run if k[2] == noise_std and k[0] != reference]
    )
    lines = [
        f"### Paired NRMSE difference to {reference}, percentage points, sigma_z = {noise_std:g}",
        "",
        f"Mean over the seeds both ran of (tracker - {reference}), ± its 95 % interval;"
        " negative: more accurate than the paper's tracker. Bold: the interval excludes 0.",
        "",
        "| tracker | " + " | ".join(f"{s} c{c:g}" for s, c in cells) + " |",
        "|---|" + "---|" * len(cells),
    ]
    for tracker in trackers:
        row = []
        for scenario, clutter in cells:
            mine = per_run.get((tracker, scenario, noise_std, clutter), {})
            theirs = per_run.get((reference, scenario, noise_std, clutter), {})
            seeds = sorted(set(mine) & set(theirs))
            if len(seeds) < 2:
                row.append("-")
                continue
            differences = 100 * np.array([mine[s] - theirs[s] for s in seeds])
            mean, half = float(np.mean(differences)), interval_half_width(differences)
            text = f"{mean:+.2f} ± {half:.2f}"
            row.append(f"**{text}**" if abs(mean) > half else text)
        lines.append(f"| {tracker} | " + " | ".join(row) + " |")
    return "\n".join(lines + [""])


def _coverage_cell(row: dict, axis: str) -> tuple[str, bool, bool]:
    """``row``'s 3-sigma coverage on detected steps along ``axis`` as "mean ± interval" (%),
    whether the mean is below the goal, and whether the whole interval is."""
    goal = CALIBRATION_GOALS["coverage_3sigma"]
    mean = _value(row, f"coverage_3sigma_{axis}_detected")
    half = _value(row, f"coverage_3sigma_{axis}_detected_ci95")
    text = f"{100 * mean:.2f}" + ("" if math.isnan(half) else f" ± {100 * half:.2f}")
    below = mean < goal
    return text, below, below and not math.isnan(half) and mean + half < goal


def _ucb_summary(rows: list[dict], suffix: str) -> str:
    """Two table cells: the UCB's coverage over ``rows`` (cells) and axes on the steps of
    ``suffix`` ("" all, "_detected"), mean (lowest; how many cell-axes miss the goal, and
    in how many the whole 95 % interval over runs does), and its half-width over the RMSE
    on the same steps, mean (highest; how many miss); "- | -" without a UCB."""
    coverage = np.array(
        [_value(row, f"ucb_coverage_{axis}{suffix}") for row in rows for axis in "xy"]
    )
    if np.all(np.isnan(coverage)):
        return "- | -"
    ratios = np.array(
        [
            _value(row, f"ucb_width_{axis}{suffix}") / 2.0 / _value(row, f"rmse_{axis}{suffix}")
            for row in rows
            for axis in "xy"
        ]
    )
    intervals = np.array(
        [_value(row, f"ucb_coverage_{axis}{suffix}_ci95") for row in rows for axis in "xy"]
    )
    goal = CALIBRATION_GOALS["ucb_coverage"]
    below = int(np.sum(coverage < goal))
    surely_below = int(np.sum(coverage + intervals < goal))  # NaN interval: not counted
    above = int(np.sum(ratios > CALIBRATION_GOALS["ucb_half_width_to_rmse"]))
    return (
        f"{100 * np.nanmean(coverage):.2f} ({100 * np.nanmin(coverage):.2f}; {below} below,"
        f" {surely_below} surely) | "
        f"{np.nanmean(ratios):.2f} ({np.nanmax(ratios):.2f}; {above} above)"
    )


def calibration_markdown(summaries: list[dict], trackers=CALIBRATION_TRACKERS) -> str:
    """The calibration goals (:data:`CALIBRATION_GOALS`) per cell of ``trackers``: each
    cell's 3-sigma coverage per axis on detected steps with its 95 % interval over runs,
    then per tracker how many cells miss each goal."""
    rows = [row for row in summaries if row["tracker"] in trackers]
    present = [t for t in trackers if any(row["tracker"] == t for row in rows)]
    if not present:
        return ""
    by_key = {
        (row["tracker"], row["scenario"], row["noise_std"], row["clutter_rate"]): row
        for row in rows
    }
    cells = sorted({key[1:] for key in by_key})
    low, high = CALIBRATION_GOALS["nees_median"]
    coverage_goal = 100 * CALIBRATION_GOALS["coverage_3sigma"]
    lines = [
        f"3-sigma coverage on detected steps (some sensor senses the target), X / Y %: the mean"
        f" over runs ± its 95 % interval. Goal: at least {coverage_goal:g} % per axis in every"
        f" cell (nominal {100 * NOMINAL_COVERAGE[3]:.2f} %). **Bold**: the mean is below the"
        " goal; marked ↓: the whole interval is.",
        "",
        "| scenario | sigma_z | clutter | " + " | ".join(present) + " |",
        "|---|---|---|" + "---|" * len(present),
    ]
    tallies = {tracker: {"below": 0, "surely_below": 0} for tracker in present}
    for scenario, noise_std, clutter in cells:
        entries = []
        for tracker in present:
            row = by_key.get((tracker, scenario, noise_std, clutter))
            if row is None:
                entries.append("-")
                continue
            tally = tallies[tracker]
            axes = [_coverage_cell(row, axis) for axis in "xy"]
            tally["below"] += any(below for _, below, _ in axes)
            tally["surely_below"] += any(surely for _, _, surely in axes)
            entries.append(
                " / ".join(
                    f"**{text}**{' ↓' if surely else ''}" if below else text
                    for text, below, surely in axes
                )
            )
        lines.append(f"| {scenario} | {noise_std:g} | {clutter:g} | " + " | ".join(entries) + " |")
    lines += [
        "",
        f"Per tracker, over its cells. Median NEES: the mean over runs of each run's median 2-D"
        f" NEES on detected steps, goal [{low:g}, {high:g}] (nominal {NOMINAL_MEDIAN_NEES:.2f})."
        " UCB on detected steps (the goal's) and, for comparison, on all steps: its coverage,"
        f" goal at least {100 * CALIBRATION_GOALS['ucb_coverage']:g} % per axis, and its mean"
        " half-width over the RMSE on the same steps per axis, goal at most"
        f" {CALIBRATION_GOALS['ucb_half_width_to_rmse']:g} (DGPT-RBCM's goals; shown for all):"
        " the mean over cells and axes, and in brackets the worst cell and axis and the number of"
        " cell-axes that miss the goal (for the coverage: and whose whole 95 % interval over"
        " runs does).",
        "",
        "| tracker | cells | 3-sigma below goal (interval wholly below) | median NEES, range"
        " | median NEES outside goal | UCB coverage %, detected | UCB half-width / RMSE,"
        " detected | UCB coverage %, all steps | UCB half-width / RMSE, all steps |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for tracker in present:
        mine = [row for row in rows if row["tracker"] == tracker]
        nees = np.array([_value(row, "nees_median_detected") for row in mine])
        tally = tallies[tracker]
        lines.append(
            f"| {tracker} | {len(mine)} | {tally['below']} ({tally['surely_below']}) | "
            f"{np.nanmin(nees):.2f}-{np.nanmax(nees):.2f} | "
            f"{int(np.sum((nees < low) | (nees > high)))} | {_ucb_summary(mine, '_detected')} | "
            f"{_ucb_summary(mine, '')} |"
        )
    return "\n".join(lines + [""])
