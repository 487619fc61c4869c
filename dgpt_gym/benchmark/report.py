"""Tables laid out like the paper's Tables II-IX, with the paper's values beside ours.

The paper's NRMSEs are transcribed once into ``data/paper_nrmse.csv`` (with the table each
comes from). Rows are noise level x clutter rate, columns approach x axis; every cell shows
our NRMSE, the paper's and the difference, in percent.
"""

from __future__ import annotations

import csv
import functools
import json
from pathlib import Path

import numpy as np

from dgpt_gym.benchmark.plots import new_figure, save_figure
from dgpt_gym.benchmark.protocol import PAPER_APPROACHES, TRAINING_SEEDS
from dgpt_gym.benchmark.windows import TUNED_WINDOWS_PATH
from dgpt_gym.naming import MODEL_SUFFIXES, PAPER_SUFFIX, TREND_SUFFIX, split_tracker_id, tracker_id

__all__ = [
    "PAPER_NRMSE_PATH",
    "paper_nrmse",
    "paper_value",
    "paper_table_markdown",
    "summary_against_paper",
    "write_paper_tables",
    "write_rows_csv",
]

PAPER_NRMSE_PATH = Path(__file__).with_name("data") / "paper_nrmse.csv"
APPROACH_NAMES = {"gp": "Standard GP", "dgpt-rbcm": "DGPT-RBCM", "dgpt-gpoe": "DGPT-GPoE"}
MODEL_NAMES = {
    "": ", the NCV GP in state-space form (default)",
    TREND_SUFFIX: ", the SE kernel around the pooled trend (`-trend`)",
    PAPER_SUFFIX: ", the paper's model as printed (`-paper`)",
}


@functools.lru_cache(maxsize=1)
def paper_nrmse() -> dict[tuple, tuple[float, str]]:
    """``{(inputs, scenario, noise_std, clutter_rate, approach, axis): (percent, table)}``."""
    with PAPER_NRMSE_PATH.open() as handle:
        lines = [line for line in handle if not line.startswith("#")]
    table = {}
    for row in csv.DictReader(lines):
        key = (
            row["inputs"],
            row["scenario"],
            float(row["noise_std"]),
            float(row["clutter_rate"]),
            row["approach"],
            row["axis"],
        )
        table[key] = (float(row["nrmse_percent"]), row["table"])
    return table


def paper_value(row: dict, axis: str) -> float | None:
    """The paper's NRMSE (%) for a per-cell summary ``row`` and ``axis``, or None where the
    paper has no such cell (other trackers, noise levels or clutter rates)."""
    approach, inputs, _ = split_tracker_id(row["tracker"])
    reference = paper_nrmse().get(
        (inputs, row["scenario"], row["noise_std"], row["clutter_rate"], approach, axis)
    )
    return None if reference is None else reference[0]


def paper_table_markdown(rows: list[dict], scenario: str, inputs: str, suffix: str = "") -> str:
    """One of Tables II-IX: ``rows`` are per-cell summaries (:func:`dgpt_gym.benchmark.sweep.summarize_store`);
    ``suffix`` picks the model (:data:`dgpt_gym.naming.MODEL_SUFFIXES`): ``""`` the default,
    ``"-trend"`` the pooled SE trend, ``"-paper"`` the paper's model as printed."""
    ours = {
        (r["tracker"], r["noise_std"], r["clutter_rate"]): r
        for r in rows
        if r["scenario"] == scenario
        and r["tracker"] in {tracker_id(a, inputs, suffix) for a in PAPER_APPROACHES}
    }
    if not ours:
        return ""
    paper = paper_nrmse()
    table_name = next(name for key, (_, name) in paper.items() if key[:2] == (inputs, scenario))
    noise_levels = sorted({key[1] for key in ours})
    clutter_rates = sorted({key[2] for key in ours})
    header = ["noise std (m)", "clutter rate"] + [
        f"{APPROACH_NAMES[a]} {axis.upper()}" for a in PAPER_APPROACHES for axis in "xy"
    ]
    model = MODEL_NAMES[suffix]
    lines = [
        f"**{scenario}, {inputs.upper()}{model}** (paper: {table_name}). Cells: ours % (paper %, ours - paper).",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
    ]
    for noise in noise_levels:
        for clutter in clutter_rates:
            cells = [f"{noise:g}", f"{clutter:g}"]
            for approach in PAPER_APPROACHES:
                row = ours.get((tracker_id(approach, inputs, suffix), noise, clutter))
                for axis in "xy":
                    reference = paper.get((inputs, scenario, noise, clutter, approach, axis))
                    if row is None:
                        cells.append("-")
                        continue
                    value = 100 * row[f"nrmse_{axis}"]
                    if reference is None or not np.isfinite(value):
                        cells.append(f"{value:.2f}")
                    else:
                        cells.append(
                            f"{value:.2f} ({reference[0]:.2f}, {value - reference[0]:+.2f})"
                        )
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def summary_against_paper(rows: list[dict], suffix: str = "") -> dict[str, float]:
    """How our NRMSEs compare with the paper's over every cell both have: the number of
    cells, those at or below the paper's, and the mean of ours and of the paper's (%), for
    the model ``suffix`` (:data:`dgpt_gym.naming.MODEL_SUFFIXES`)."""
    paper = paper_nrmse()
    ours, theirs = [], []
    for row in rows:
        for inputs in ("tgp", "stgp"):
            for approach in PAPER_APPROACHES:
                if row["tracker"] != tracker_id(approach, inputs, suffix):
                    continue
                for axis in "xy":
                    key = (
                        inputs,
                        row["scenario"],
                        row["noise_std"],
                        row["clutter_rate"],
                        approach,
                        axis,
                    )
                    if key in paper:
                        ours.append(100 * row[f"nrmse_{axis}"])
                        theirs.append(paper[key][0])
    ours, theirs = np.array(ours), np.array(theirs)
    return {
        "cells": int(ours.size),
        "at_or_below_paper": int(np.sum(ours <= theirs)),
        "mean_ours": float(ours.mean()) if ours.size else float("nan"),
        "mean_paper": float(theirs.mean()) if theirs.size else float("nan"),
    }


def write_paper_tables(rows: list[dict], path: str | Path, command: str) -> None:
    """Markdown with one paper-style table per scenario and input type, and a CSV of ``rows``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    runs = sorted({row["n_runs"] for row in rows})
    parts = [
        "## NRMSE beside the paper's Tables II-IX",
        "",
        f"Command: `{command}` ({', '.join(map(str, runs))} Monte Carlo runs per cell, seeds from 0;"
        " the `-trend` and `-paper` trackers' window lengths tuned per scenario on training"
        " seeds, `dgpt_gym/benchmark/tuned_windows.json`).",
        "",
    ]
    for suffix in MODEL_SUFFIXES:
        summary = summary_against_paper(rows, suffix)
        if not summary["cells"]:
            continue
        noise = sorted(
            {r["noise_std"] for r in rows if split_tracker_id(r["tracker"])[2] == suffix}
        )
        parts += [
            f"Summary{MODEL_NAMES[suffix]} (sigma_z {', '.join(f'{n:g}' for n in noise)} m):"
            f" {summary['at_or_below_paper']} of {summary['cells']} cells at or below the paper's"
            f" value; mean NRMSE {summary['mean_ours']:.2f} % (paper {summary['mean_paper']:.2f} %"
            " on the same cells).",
            "",
        ]
    scenarios = sorted({row["scenario"] for row in rows})
    for inputs in ("tgp", "stgp"):
        for scenario in scenarios:
            for suffix in MODEL_SUFFIXES:
                table = paper_table_markdown(rows, scenario, inputs, suffix)
                if table:
                    parts += [table, ""]
    parts += windows_markdown()
    path.write_text("\n".join(parts))
    write_rows_csv(rows, path.with_suffix(path.suffix + ".csv"))


def write_rows_csv(rows: list[dict], path: Path) -> Path:
    """``rows`` as CSV, with the union of their keys as columns (trackers report different
    metrics: a GP tracker's ``share_at_bound_*`` is absent for a Kalman filter)."""
    keys = list(dict.fromkeys(key for row in rows for key in row))
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=keys)
        writer.writeheader()
        writer.writerows(rows)
    return path


def windows_markdown() -> list[str]:
    """The tuned window lengths and the grid-search scores they were chosen by."""

    if not TUNED_WINDOWS_PATH.exists():
        return []

    stored = json.loads(TUNED_WINDOWS_PATH.read_text())
    grid = stored["grid"]
    windows = sorted({row["window"] for row in grid})
    lines = [
        "## Window lengths",
        "",
        "Chosen by `python scripts/evaluate.py --tune-windows`: for each tracker and scenario the window"
        f" with the lowest NRMSE (mean over axes, the reference and random paths, clutter rates 1"
        " and 5, sigma_z = 1, training seeds"
        f" {TRAINING_SEEDS.start}-{TRAINING_SEEDS.stop - 1}, disjoint from the evaluation seeds). Cells: NRMSE %"
        " of each window; the chosen one in bold.",
        "",
        "| tracker | scenario | " + " | ".join(f"C = {w}" for w in windows) + " |",
        "|---|---|" + "---|" * len(windows),
    ]
    for tracker, by_scenario in stored["windows"].items():
        for scenario, chosen in by_scenario.items():
            scores = {
                row["window"]: row["nrmse"]
                for row in grid
                if row["tracker"] == tracker and row["scenario"] == scenario
            }
            cells = [
                (f"**{100 * scores[w]:.2f}**" if w == chosen else f"{100 * scores[w]:.2f}")
                if w in scores
                else "-"
                for w in windows
            ]
            lines.append(f"| {tracker} | {scenario} | " + " | ".join(cells) + " |")
    return lines + [""]


HYBRID_COMPARISON_TRACKERS = (
    "gp",
    "dgpt-rbcm",
    "hybrid",
    "gp-trend",
    "dgpt-rbcm-trend",
    "hybrid-trend",
    "hybrid-paper",
    "cpf",
)


def _comparison_layout(rows: list[dict]):
    """Trackers of the comparison present in ``rows`` (in order), scenarios, rows by key."""
    trackers = [t for t in HYBRID_COMPARISON_TRACKERS if any(r["tracker"] == t for r in rows)]
    scenarios = sorted({r["scenario"] for r in rows})
    return trackers, scenarios, {(r["tracker"], r["scenario"]): r for r in rows}


def hybrid_comparison_markdown(rows: list[dict], command: str) -> str:
    """The paper's Fig. 8 as a table: NRMSE and STD of the RMSE over runs per scenario and
    tracker (the paper prints only bars, so there are no values to set beside them)."""
    trackers, scenarios, by_key = _comparison_layout(rows)
    runs = sorted({r["n_runs"] for r in rows})
    lines = [
        "## Hybrid filter and CPF (paper Fig. 8)",
        "",
        f"Command: `{command}` (sigma_z = 1, clutter rate 5, {', '.join(map(str, runs))} Monte Carlo"
        " runs per cell). Cells: NRMSE X / Y in %, and the STD of the per-run RMSE X / Y in m.",
        "",
        "| tracker | " + " | ".join(f"{s} NRMSE % | {s} STD RMSE m" for s in scenarios) + " |",
        "|---|" + "---|---|" * len(scenarios),
    ]
    for tracker in trackers:
        cells = []
        for scenario in scenarios:
            row = by_key.get((tracker, scenario))
            if row is None:
                cells += ["-", "-"]
                continue
            cells.append(f"{100 * row['nrmse_x']:.2f} / {100 * row['nrmse_y']:.2f}")
            cells.append(f"{row['rmse_std_x']:.2f} / {row['rmse_std_y']:.2f}")
        lines.append(f"| {tracker} | " + " | ".join(cells) + " |")
    return "\n".join(lines + ["", "![Fig. 8](figures/hybrid_comparison.png)", ""])


def plot_hybrid_comparison(rows: list[dict], path: str | Path) -> Path:
    """Bar charts of NRMSE and STD of RMSE per scenario, axis and tracker (paper Fig. 8)."""

    trackers, scenarios, by_key = _comparison_layout(rows)
    figure = new_figure((10, 6))
    panels = [
        ("nrmse_x", "(a) NRMSE X, %", 100),
        ("nrmse_y", "(b) NRMSE Y, %", 100),
        ("rmse_std_x", "(c) STD of RMSE X, m", 1),
        ("rmse_std_y", "(d) STD of RMSE Y, m", 1),
    ]
    width = 0.8 / len(trackers)
    for index, (key, title, scale) in enumerate(panels):
        axes = figure.add_subplot(2, 2, index + 1)
        for offset, tracker in enumerate(trackers):
            values = [
                scale * by_key[(tracker, s)][key] if (tracker, s) in by_key else np.nan
                for s in scenarios
            ]
            axes.bar(np.arange(len(scenarios)) + offset * width, values, width, label=tracker)
        axes.set_xticks(np.arange(len(scenarios)) + 0.4 - width / 2, scenarios)
        axes.set_title(title, fontsize=9)
        if index == 0:
            axes.legend(fontsize=7)
    return save_figure(figure, path)
