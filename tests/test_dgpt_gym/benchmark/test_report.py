"""Paper tables, tuned windows and the grid runner."""

import json

import numpy as np
import pytest

from dgpt_gym.benchmark import baseline_report, report, tuning, windows
from dgpt_gym.benchmark.sweep import Grid, RunUnit, run_unit, run_units


def test_paper_values_are_transcribed():
    paper = report.paper_nrmse()
    assert len(paper) == 8 * 6 * 6  # Tables II-IX, 6 rows, 3 approaches x 2 axes
    assert paper[("tgp", "S1", 1.0, 1.0, "gp", "x")] == (0.77, "Table II")
    assert paper[("tgp", "S3", 2.0, 5.0, "dgpt-gpoe", "y")] == (3.27, "Table IV")
    assert paper[("stgp", "S4", 4.0, 5.0, "dgpt-rbcm", "x")] == (2.64, "Table IX")


def test_paper_table_cells_show_ours_paper_and_difference():
    rows = [
        {
            "tracker": "dgpt-rbcm",
            "scenario": "S1",
            "noise_std": 1.0,
            "clutter_rate": 1.0,
            "nrmse_x": 0.0105,
            "nrmse_y": 0.0090,
        }
    ]
    text = report.paper_table_markdown(rows, "S1", "tgp")
    assert "Table II" in text
    assert "| 1 | 1 | - | - | 1.05 (0.93, +0.12) | 0.90 (0.95, -0.05) | - | - |" in text
    summary = report.summary_against_paper(rows)
    assert summary == {
        "cells": 2,
        "at_or_below_paper": 1,
        "mean_ours": pytest.approx(0.975),
        "mean_paper": pytest.approx(0.94),
    }


def test_the_paper_model_as_printed_gets_its_own_tables():
    rows = [
        {
            "tracker": tracker,
            "scenario": "S1",
            "noise_std": 1.0,
            "clutter_rate": 1.0,
            "nrmse_x": nrmse,
            "nrmse_y": nrmse,
        }
        for tracker, nrmse in (
            ("dgpt-rbcm", 0.0105),
            ("dgpt-rbcm-trend", 0.0200),
            ("dgpt-rbcm-stgp-trend", 0.0250),
            ("dgpt-rbcm-paper", 0.0300),
        )
    ]
    ours = report.paper_table_markdown(rows, "S1", "tgp")
    trend = report.paper_table_markdown(rows, "S1", "tgp", suffix="-trend")
    assert "pooled trend" in trend
    assert "| 1 | 1 | - | - | 2.00 (0.93, +1.07) | 2.00 (0.95, +1.05) | - | - |" in trend
    assert report.summary_against_paper(rows, "-trend")["mean_ours"] == pytest.approx(2.25)
    # the default model has no STGP form: its STGP table is empty, the trend's is not
    assert report.paper_table_markdown(rows, "S1", "stgp") == ""
    assert "| 1 | 1 | - | - | 2.50 (" in report.paper_table_markdown(rows, "S1", "stgp", "-trend")
    printed = report.paper_table_markdown(rows, "S1", "tgp", suffix="-paper")
    assert "| 1 | 1 | - | - | 1.05 (0.93, +0.12) | 1.05 (0.95, +0.10) | - | - |" in ours
    assert "as printed" in printed
    assert "| 1 | 1 | - | - | 3.00 (0.93, +2.07) | 3.00 (0.95, +2.05) | - | - |" in printed
    assert report.summary_against_paper(rows, "-paper")["mean_ours"] == pytest.approx(3.0)
    assert report.summary_against_paper(rows)["mean_ours"] == pytest.approx(1.05)
    assert report.paper_value(rows[1], "x") == 0.93


def test_tuned_windows_lookup():
    tuned = windows.tuned_windows()
    assert set(tuned) >= {"gp-trend", "dgpt-rbcm-trend", "dgpt-gpoe-trend"}
    assert windows.tuned_kwargs("dgpt-rbcm-trend", "S2") == {
        "window": tuned["dgpt-rbcm-trend"]["S2"]
    }
    assert windows.tuned_kwargs("hybrid-trend", "S2") == {"window": tuned["dgpt-rbcm-trend"]["S2"]}
    # the state-space trackers' window learns q and is not tuned per scenario
    for tracker in ("centroid", "dgpt-rbcm", "gp", "hybrid"):
        assert windows.tuned_kwargs(tracker, "S2") == {}


def test_tune_windows_picks_the_best_of_its_grid(tmp_path):
    best, rows = tuning.tune_windows(
        ["dgpt-rbcm-trend"],
        ["S3"],
        windows=[2, 6],
        seeds=[1000],
        clutter_rates=[1.0],
        progress=False,
    )
    scores = {row["window"]: row["nrmse"] for row in rows}
    assert best == {"dgpt-rbcm-trend": {"S3": min(scores, key=scores.get)}}
    direct = []
    for trajectory in ("fixed", "random"):  # windows are chosen on both path modes
        env_kwargs = {
            "scenario": "S3",
            "noise_std": 1.0,
            "clutter_rate": 1.0,
            "trajectory": trajectory,
        }
        unit = RunUnit(
            "dgpt-rbcm-trend",
            "agents.dgpt:DGPT",
            {"aggregation": "rbcm", "window": 6},
            env_kwargs,
            1000,
        )
        metrics = run_unit(unit)["metrics"]
        direct.append(0.5 * (metrics["nrmse_x"] + metrics["nrmse_y"]))
    assert direct[0] != direct[1]
    assert scores[6] == pytest.approx(np.mean(direct))
    path = tmp_path / "windows.json"
    windows.save_tuned_windows(best, rows, path)
    assert json.loads(path.read_text())["windows"] == best


def test_units_on_two_processes_equal_one():
    grid = Grid(
        trackers=("dgpt-gpoe-trend", "centroid"), scenarios=("S4",), clutter_rates=(5.0,), runs=2
    )
    units = grid.units()
    serial = run_units(units, workers=1, progress=False)
    parallel = run_units(units, workers=2, progress=False)
    for a, b in zip(serial, parallel):
        assert a["status"] == b["status"] == "ok"
        np.testing.assert_array_equal(
            [a["metrics"]["nrmse_x"], a["metrics"]["nrmse_y"]],
            [b["metrics"]["nrmse_x"], b["metrics"]["nrmse_y"]],
        )
    assert units[0].tracker_kwargs["window"] == windows.tuned_windows()["dgpt-gpoe-trend"]["S4"]


def test_hybrid_comparison_table_and_figure(tmp_path):
    rows = [
        {
            "tracker": tracker,
            "scenario": scenario,
            "nrmse_x": 0.01 * k,
            "nrmse_y": 0.02 * k,
            "rmse_std_x": 1.5 * k,
            "rmse_std_y": 2.5 * k,
            "n_runs": 3,
        }
        for k, (tracker, scenario) in enumerate(
            [("cpf", "S1"), ("hybrid", "S1"), ("hybrid", "S2")], start=1
        )
    ]
    text = report.hybrid_comparison_markdown(rows, "cmd")
    # trackers in the paper's order (hybrid before cpf); a missing cell is a dash
    assert "| hybrid | 2.00 / 4.00 | 3.00 / 5.00 | 3.00 / 6.00 | 4.50 / 7.50 |" in text
    assert "| cpf | 1.00 / 2.00 | 1.50 / 2.50 | - | - |" in text
    assert text.index("| hybrid |") < text.index("| cpf |")
    figure = report.plot_hybrid_comparison(rows, tmp_path / "figures" / "comparison.png")
    assert figure.exists() and figure.stat().st_size > 1000


def test_error_curves_are_the_per_step_errors_of_the_sweeps_runs(tmp_path):
    import gymnasium as gym

    from dgpt_gym import make_tracker
    from dgpt_gym.benchmark.episodes import run_episode
    from dgpt_gym.benchmark.outputs import error_curves
    from dgpt_gym.benchmark.plots import plot_error_against_time
    from dgpt_gym.benchmark.sweep import sweep_units

    grid = Grid(
        trackers=("imm-pda", "centroid"),
        scenarios=("S4",),
        clutter_rates=(1.0, 5.0),
        runs=2,
        tuned_windows=False,
    )
    curves, settings = error_curves(sweep_units([grid]))
    assert list(curves) == ["S4"] and list(curves["S4"]) == ["imm-pda"]  # centroid not drawn
    assert settings == "sigma_z 1 m, clutter rate 5"
    env = gym.make("DGPTrack-v0", scenario="S4", clutter_rate=5.0)
    alone = run_episode(env, make_tracker("imm-pda"), seed=1)
    np.testing.assert_allclose(
        curves["S4"]["imm-pda"][1], np.linalg.norm(alone.mean - alone.truth, axis=1)
    )
    path = plot_error_against_time(curves, tmp_path / "error.png", settings)
    assert path.stat().st_size > 1000


def test_bounds_table_and_csv_take_what_each_tracker_reports(tmp_path):
    from dgpt_gym.benchmark.outputs import bounds_markdown

    rows = [
        {
            "tracker": "dgpt-rbcm",
            "scenario": "S1",
            "share_at_bound": 0.5,
            "share_at_bound_signal_var": 0.25,
            "share_at_bound_noise_var": 0.5,
        },
        {
            "tracker": "dgpt-rbcm",
            "scenario": "S1",
            "share_at_bound": 1.0,
            "share_at_bound_signal_var": 0.75,
            "share_at_bound_noise_var": 0.0,
        },
        {"tracker": "imm-pda", "scenario": "S1"},
    ]
    lines = bounds_markdown(rows)
    # the mean over the scenario's cells, in %; imm-pda reports nothing and gets no row
    assert "| tracker | scenario | any | signal_var | noise_var |" in lines
    assert "| dgpt-rbcm | S1 | 75 | 50 | 25 |" in lines
    assert not any(line.startswith("| imm-pda") for line in lines)
    assert bounds_markdown(rows[2:]) == []
    # the first row lacks the GP keys: the columns are the union, not the first row's keys
    path = report.write_rows_csv([rows[2], *rows[:2]], tmp_path / "rows.csv")
    header = path.read_text().splitlines()[0].split(",")
    assert header == [
        "tracker",
        "scenario",
        "share_at_bound",
        "share_at_bound_signal_var",
        "share_at_bound_noise_var",
    ]


def _calibration_cell(
    scenario, coverage, interval, nees, ucb_coverage, ucb_width, rmse, ucb_interval
):
    """A summary row of dgpt-rbcm at sigma_z 1, clutter 5 with per-axis (x, y) values. The
    UCB's values are on detected steps; over all steps its coverage is 1 point lower, with
    no interval, and its width and RMSE twice and four times those."""
    row = {"tracker": "dgpt-rbcm", "scenario": scenario, "noise_std": 1.0, "clutter_rate": 5.0}
    row["nees_median_detected"] = nees
    for axis, c, h, u, w, r, uh in zip(
        "xy", coverage, interval, ucb_coverage, ucb_width, rmse, ucb_interval
    ):
        row[f"coverage_3sigma_{axis}_detected"] = c
        row[f"coverage_3sigma_{axis}_detected_ci95"] = h
        row[f"ucb_coverage_{axis}_detected"] = u
        row[f"ucb_coverage_{axis}_detected_ci95"] = uh
        row[f"ucb_width_{axis}_detected"] = w
        row[f"rmse_{axis}_detected"] = r
        row[f"ucb_coverage_{axis}"] = u - 0.01
        row[f"ucb_width_{axis}"] = 2 * w
        row[f"rmse_{axis}"] = 4 * r
    return row


def test_calibration_table_marks_cells_below_the_goal_and_tallies_them():
    summaries = [
        # y: 98.5 + 0.3 = 98.8 < 99: the whole interval is below the goal
        _calibration_cell(
            "S1", (0.995, 0.985), (0.002, 0.003), 1.2, (0.999, 0.998), (8, 10), (2, 1), (0, 0)
        ),
        # x: 98.9 + 0.5 reaches 99: below on the mean only; y has no interval. The UCB's
        # x: 99.6 + 0.05 < 99.7, wholly below its goal
        _calibration_cell(
            "S2",
            (0.989, 0.999),
            (0.005, np.nan),
            0.5,
            (0.996, 0.997),
            (6, 6),
            (1, 3),
            (0.0005, 0.001),
        ),
        {"tracker": "pda", "scenario": "S1", "noise_std": 1.0, "clutter_rate": 5.0},
    ]
    lines = baseline_report.calibration_markdown(summaries).splitlines()
    assert "| scenario | sigma_z | clutter | dgpt-rbcm |" in lines  # only trackers that ran
    assert "| S1 | 1 | 5 | 99.50 ± 0.20 / **98.50 ± 0.30** ↓ |" in lines
    assert "| S2 | 1 | 5 | **98.90 ± 0.50** / 99.90 |" in lines
    # UCB on detected steps, coverage: mean of 99.9, 99.8, 99.6, 99.7 and the lowest, and
    # one below 99.7 (99.7 itself meets it), surely; half-width / RMSE: 4/2, 5/1, 3/1, 3/3 ->
    # mean 2.75, highest 5, one above 4; over all steps one point lower (all four below,
    # none surely without intervals) and half the ratio (none above); NEES 0.5 is outside
    # [0.7, 2.8]
    assert (
        "| dgpt-rbcm | 2 | 2 (1) | 0.50-1.20 | 1 | 99.75 (99.60; 1 below, 1 surely) |"
        " 2.75 (5.00; 1 above) | 98.75 (98.60; 4 below, 0 surely) | 1.38 (2.50; 0 above) |"
    ) in lines
    assert baseline_report.calibration_markdown(summaries[2:]) == ""
