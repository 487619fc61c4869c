"""dgpt_gym.benchmark.compare on small hand-written results_cells.csv files."""

import math

import pytest

from dgpt_gym.benchmark.compare import (
    compare_cells,
    comparison_markdown,
    read_cells,
    relative_difference,
)

HEADER = "tracker,scenario,noise_std,clutter_rate,rmse_2d,anees,step_time_ms,versions,window\n"


def write(path, rows):
    path.write_text(HEADER + "".join(row + "\n" for row in rows))
    return path


def test_relative_difference_by_hand():
    assert relative_difference("2.0", "2.0") == 0.0
    assert relative_difference("2.0", "2.5") == 0.25
    assert relative_difference("-4.0", "-3.0") == 0.25
    assert relative_difference("0.0", "0.5") == 0.5  # no scale: the absolute difference
    assert relative_difference("nan", "nan") == 0.0
    assert relative_difference("nan", "1.0") == math.inf
    assert relative_difference("", "") == 0.0
    assert relative_difference("", "3") == math.inf
    assert relative_difference("1e-3", "0.001") == 0.0  # the same number, other text


def test_compare_cells_counts_and_locates_the_largest_change(tmp_path):
    old = write(
        tmp_path / "old.csv",
        [
            "gp,S1,1.0,1.0,8.0,2.0,0.6,0.23.2,",
            "gp,S2,1.0,5.0,4.0,nan,0.7,0.23.2,",
            "pda,S1,1.0,1.0,9.0,3.0,0.2,0.23.2,",
            "pda,S3,1.0,1.0,5.0,3.0,0.2,0.23.2,",
            "pda,S3,1.0,5.0,5.0,3.0,0.2,0.23.2,",  # two cells the new grid lacks
        ],
    )
    new = write(
        tmp_path / "new.csv",
        [
            "gp,S1,1.0,1.0,8.0,2.0,0.9,0.23.3,",  # only the step time and version differ
            "gp,S2,1.0,5.0,4.0,nan,1.1,0.23.3,",
            "pda,S1,1.0,1.0,9.9,3.0,0.3,0.23.3,",  # rmse +10 %
            "pda,S4,1.0,1.0,5.0,3.0,0.2,0.23.3,",  # a cell the old grid lacks
        ],
    )
    rows = {row["tracker"]: row for row in compare_cells(read_cells(old), read_cells(new))}
    # compared per cell: rmse_2d, anees, window (step_time_ms and versions left out)
    assert rows["gp"] == {
        "tracker": "gp",
        "cells": 2,
        "only_old": 0,
        "only_new": 0,
        "values": 6,
        "equal": 6,
        "max_relative": 0.0,
        "where": None,
    }
    assert rows["pda"]["cells"] == 1
    assert (rows["pda"]["only_old"], rows["pda"]["only_new"]) == (2, 1)
    assert (rows["pda"]["values"], rows["pda"]["equal"]) == (3, 2)
    assert rows["pda"]["max_relative"] == pytest.approx(0.1, rel=1e-12)
    assert rows["pda"]["where"] == ("S1", "1.0", "1.0", "rmse_2d")
    table = comparison_markdown(list(rows.values()))
    assert "| `pda` | 1 | 2 of 3 | 0.1 | S1, 1.0, 1.0, rmse_2d | 2 / 1 |" in table
    assert "| `gp` | 2 | 6 of 6 | 0 | - | 0 / 0 |" in table


def test_read_cells_names_what_is_wrong(tmp_path):
    with pytest.raises(FileNotFoundError, match="no results_cells.csv at"):
        read_cells(tmp_path / "missing.csv")
    (tmp_path / "other.csv").write_text("tracker,rmse\ngp,1.0\n")
    with pytest.raises(ValueError, match="lacks the cell columns"):
        read_cells(tmp_path / "other.csv")
