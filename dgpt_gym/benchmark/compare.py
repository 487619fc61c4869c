"""Two versions' grids, metric by metric: what a version changed in ``results_cells.csv``.

A version that means to change one tracker should leave every other tracker's metrics equal
to the last digit, and move the changed one by what its note says. This compares two
``results_cells.csv`` files (one row per cell, as :func:`dgpt_gym.benchmark.outputs.write_cells_csv`
writes them) and reports, per tracker, how many values are equal and the largest relative
difference, with the cell and the metric where it is. Step times and the version column are
left out: they differ between any two runs.

    git show v0.23.2:docs/results_cells.csv > /tmp/old.csv   # or any earlier commit
    python scripts/compare_cells.py /tmp/old.csv docs/results_cells.csv
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

CELL_COLUMNS = ("tracker", "scenario", "noise_std", "clutter_rate")
"""The columns that name a cell."""

IGNORED_COLUMNS = ("step_time_ms", "versions")
"""Columns that differ between any two runs of the same code."""


def read_cells(path: str | Path) -> dict[tuple[str, ...], dict[str, str]]:
    """The rows of a ``results_cells.csv``, keyed by :data:`CELL_COLUMNS`."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no results_cells.csv at {path}")
    with path.open(newline="") as handle:
        reader = csv.DictReader(handle)
        missing = [c for c in CELL_COLUMNS if c not in (reader.fieldnames or ())]
        if missing:
            raise ValueError(f"{path} lacks the cell columns {missing}: not a results_cells.csv")
        return {tuple(row[c] for c in CELL_COLUMNS): row for row in reader}


def relative_difference(old: str, new: str) -> float:
    """|new - old| / |old| for two CSV values (0 when equal, inf when one is not a number or
    one is NaN and the other not, |new| when old is 0); text values compare as text."""
    if old == new:
        return 0.0
    try:
        a, b = float(old), float(new)
    except ValueError:
        return math.inf
    if math.isnan(a) and math.isnan(b):
        return 0.0
    if math.isnan(a) or math.isnan(b):
        return math.inf
    if a == b:
        return 0.0
    return abs(b - a) / abs(a) if a != 0.0 else abs(b)


def compare_cells(
    old: dict[tuple[str, ...], dict[str, str]],
    new: dict[tuple[str, ...], dict[str, str]],
    ignored: tuple[str, ...] = IGNORED_COLUMNS,
) -> list[dict]:
    """Per tracker (in the new file's order): ``cells`` compared, ``only_old`` and
    ``only_new`` cells, ``values`` compared, ``equal`` values (the same text, or both NaN),
    ``max_relative`` difference and where it is (``where``: cell and metric, None when all
    are equal). Columns present in only one file are not compared."""
    trackers = list(dict.fromkeys(key[0] for key in [*new, *old]))
    rows = []
    for tracker in trackers:
        old_keys = {k for k in old if k[0] == tracker}
        new_keys = {k for k in new if k[0] == tracker}
        shared = sorted(old_keys & new_keys)
        row = {
            "tracker": tracker,
            "cells": len(shared),
            "only_old": len(old_keys - new_keys),
            "only_new": len(new_keys - old_keys),
            "values": 0,
            "equal": 0,
            "max_relative": 0.0,
            "where": None,
        }
        for key in shared:
            columns = [
                c for c in old[key] if c in new[key] and c not in CELL_COLUMNS and c not in ignored
            ]
            for column in columns:
                difference = relative_difference(old[key][column], new[key][column])
                row["values"] += 1
                row["equal"] += difference == 0.0
                if difference > row["max_relative"]:
                    row["max_relative"] = difference
                    row["where"] = (*key[1:], column)
        rows.append(row)
    return rows


def comparison_markdown(rows: list[dict]) -> str:
    """A Markdown table of :func:`compare_cells`' rows."""
    lines = [
        "| tracker | cells | equal values | largest relative difference | where (scenario, "
        "sigma_z, clutter, metric) | cells only in old / new |",
        "|---|---|---|---|---|---|",
    ]
    for row in rows:
        where = ", ".join(row["where"]) if row["where"] else "-"
        lines.append(
            f"| `{row['tracker']}` | {row['cells']} | {row['equal']} of {row['values']} | "
            f"{row['max_relative']:.3g} | {where} | {row['only_old']} / {row['only_new']} |"
        )
    return "\n".join(lines)
