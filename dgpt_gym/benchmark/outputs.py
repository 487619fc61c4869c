"""Every table and figure of an evaluation sweep, regenerated from its results store.

:func:`write_outputs` reads the finished runs of a sweep from ``out/results.sqlite`` and
writes, to the report folder, what the sweep's runs allow:

| file | content | paper |
|---|---|---|
| ``results.md`` | headline against the paper, NRMSE per tracker and scenario, failures, timings, links | |
| ``results_cells.csv`` | every cell's summary (means over runs, STD of RMSE, ratio to the floor) | |
| ``results_baselines.md`` | NRMSE against the standard trackers and the clairvoyant floor; NEES, coverage, track loss; the calibration goals per cell | |
| ``results_tables.md`` (+ ``.csv``) | NRMSE beside the paper's, laid out like the paper | Tables II-IX |
| ``results_hybrid.md``, ``figures/hybrid_comparison.png`` | NRMSE and STD of RMSE bars at sigma_z = 1, clutter 5 | Fig. 8 |
| ``results_uncertainty.md``, ``figures/ucb_vs_ci.png`` | UCB and 3-sigma coverage and width; one S1 run | Figs. 4-7, Sec. VII-G |
| ``figures/error_vs_time.png`` | 2-D error against time, median and interquartile band over runs, per scenario | |
| ``figures/scenarios.png`` | trajectories over the sensor field | Fig. 3 |
| ``figures/training_time.png`` | DGP training time (from the benchmark's CSV) | Fig. 2 |
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dgpt_gym.benchmark import baseline_report, report
from dgpt_gym.benchmark.episodes import add_floor_ratios
from dgpt_gym.benchmark.plots import (
    plot_error_against_time,
    plot_scenarios,
    plot_training_time,
    plot_ucb_vs_ci,
    read_training_time,
)
from dgpt_gym.benchmark.protocol import PAPER_AS_PRINTED_TRACKERS, PAPER_GP_TRACKERS
from dgpt_gym.benchmark.store import ResultsStore
from dgpt_gym.benchmark.sweep import Grid, episode_results, summarize_store, sweep_units
from dgpt_gym.naming import TREND_SUFFIX

__all__ = ["write_outputs", "uncertainty_markdown", "results_markdown", "PAPER_UCB_GAIN"]

PAPER_UCB_GAIN = {"x": 88.0, "y": 42.0}
"""Sec. VII-G: the UCB covers the truth 88 % (X) and 42 % (Y) more often than the CI."""


def per_run_nrmse(grids: list[Grid], out: str | Path) -> dict[tuple, dict[int, float]]:
    """{(tracker, scenario, noise_std, clutter_rate): {seed: mean-over-axes NRMSE}} of the
    sweep's finished runs in the store at ``out``."""
    keys = {unit.key for unit in sweep_units(grids)}
    per_run: dict[tuple, dict[int, float]] = {}
    with ResultsStore(out) as store:
        for row in store.rows(keys, status="ok"):
            cell = (row["tracker"], row["scenario"], row["noise_std"], row["clutter_rate"])
            metrics = row["metrics"]
            per_run.setdefault(cell, {})[row["seed"]] = 0.5 * (
                metrics["nrmse_x"] + metrics["nrmse_y"]
            )
    return per_run


def baselines_markdown(
    summaries: list[dict], command: str, per_run: dict[tuple, dict[int, float]] | None = None
) -> str:
    """``results_baselines.md``: every tracker against the standard trackers and the
    clairvoyant floor, per noise level (with the paired comparison to DGPT-RBCM when the
    per-run values are given), every tracker's consistency, and the calibration goals per cell
    (:func:`dgpt_gym.benchmark.baseline_report.calibration_markdown`)."""
    parts = [
        "## The paper's trackers against the standard trackers and the clairvoyant floor",
        "",
        f"Command: `{command}`. The clairvoyant filter is told which measurements are the"
        " target's and uses the scenario's true motion model (baselines/clairvoyant.py): the"
        " accuracy floor. pda and imm-pda are Kalman filters with probabilistic data"
        " association (baselines/pda.py), tuned on training seeds (baseline_tuning.md).",
        "",
    ]
    for noise in sorted({row["noise_std"] for row in summaries}):
        parts.append(baseline_report.comparison_markdown(summaries, noise))
        if per_run:
            parts.append(baseline_report.paired_markdown(per_run, noise))
    parts += [
        "## Consistency: NEES, sigma coverage and track loss",
        "",
        baseline_report.consistency_markdown(summaries),
    ]
    calibration = baseline_report.calibration_markdown(summaries)
    if calibration:
        parts += ["## Calibration goals per cell", "", calibration]
    return "\n".join(parts)


def write_cells_csv(summaries: list[dict], path: Path) -> Path:
    """One CSV row per cell: its settings and :func:`summarize_runs` of its runs."""
    return report.write_rows_csv(summaries, path)


def _percent_pair(row: dict, key: str) -> str:
    return f"{100 * row[f'{key}_x']:.2f} / {100 * row[f'{key}_y']:.2f}"


def ucb_gain(rows: list[dict]) -> dict[str, float]:
    """Per axis, how much more often the UCB covers the truth than the CI, in percent of the
    CI's coverage, over the mean coverages of ``rows`` (the paper's 88 % / 42 %)."""
    gains = {}
    for axis in "xy":
        ucb = np.mean([row[f"ucb_coverage_{axis}"] for row in rows])
        ci = np.mean([row[f"ci_coverage_{axis}"] for row in rows])
        gains[axis] = float(100 * (ucb - ci) / ci) if ci > 0 else float("inf")
    return gains


def uncertainty_markdown(summaries: list[dict], command: str, figure: str | None) -> str:
    """Sec. VII-G as tables: coverage of the truth by the UCB and by the 3-sigma CI, and
    their mean full widths, per cell of the trackers that give a UCB."""
    rows = [row for row in summaries if np.isfinite(row.get("ucb_coverage_x", np.nan))]
    lines = [
        "## UCB against the confidence interval (paper Sec. VII-G, Figs. 4-7)",
        "",
        f"Command: `{command}`. Coverage: share of steps whose band (estimate +- UCB half-width,"
        " or +- 3 sigma) contains the true coordinate, mean over runs; width: mean full width"
        " (2 x half-width), m. The paper reports the UCB covering the truth"
        f" {PAPER_UCB_GAIN['x']:.0f} % (X) and {PAPER_UCB_GAIN['y']:.0f} % (Y) more often than"
        " the CI; the gain column is (UCB coverage - CI coverage) / CI coverage.",
        "",
        "| tracker | coverage gain X / Y % (paper 88 / 42) | UCB coverage X / Y % | CI coverage X / Y % | UCB width X / Y m | CI width X / Y m | cells |",
        "|---|---|---|---|---|---|---|",
    ]
    for tracker in dict.fromkeys(row["tracker"] for row in rows):
        mine = [row for row in rows if row["tracker"] == tracker]
        mean = {
            key: np.mean([row[key] for row in mine])
            for key in mine[0]
            if key.endswith(("_x", "_y")) and isinstance(mine[0][key], float)
        }
        gain = ucb_gain(mine)
        lines.append(
            f"| {tracker} | {gain['x']:+.0f} / {gain['y']:+.0f} | {_percent_pair(mean, 'ucb_coverage')} | "
            f"{_percent_pair(mean, 'ci_coverage')} | {mean['ucb_width_x']:.1f} / {mean['ucb_width_y']:.1f} | "
            f"{mean['ci_width_x']:.1f} / {mean['ci_width_y']:.1f} | {len(mine)} |"
        )
    lines += [
        "",
        "Per cell:",
        "",
        "| tracker | scenario | noise std | clutter | UCB coverage X / Y % | CI coverage X / Y % | UCB width X / Y m | CI width X / Y m | runs |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row['tracker']} | {row['scenario']} | {row['noise_std']:g} | {row['clutter_rate']:g} | "
            f"{_percent_pair(row, 'ucb_coverage')} | {_percent_pair(row, 'ci_coverage')} | "
            f"{row['ucb_width_x']:.1f} / {row['ucb_width_y']:.1f} | "
            f"{row['ci_width_x']:.1f} / {row['ci_width_y']:.1f} | {row['n_runs']} |"
        )
    if figure:
        lines += ["", f"![Figs. 4-7]({figure})"]
    return "\n".join(lines + [""])


def nrmse_by_scenario_markdown(summaries: list[dict]) -> str:
    """Mean NRMSE (both axes, every noise level and clutter rate) per tracker and scenario."""
    scenarios = sorted({row["scenario"] for row in summaries})
    lines = [
        "| tracker | " + " | ".join(scenarios) + " |",
        "|---|" + "---|" * len(scenarios),
    ]
    for tracker in dict.fromkeys(row["tracker"] for row in summaries):
        cells = []
        for scenario in scenarios:
            values = [
                0.5 * (row["nrmse_x"] + row["nrmse_y"])
                for row in summaries
                if row["tracker"] == tracker and row["scenario"] == scenario
            ]
            cells.append(f"{100 * np.mean(values):.2f}" if values else "-")
        lines.append(f"| {tracker} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def paper_comparison_markdown(summaries: list[dict]) -> list[str]:
    """Headline against Tables II-IX, overall and per scenario and clutter rate."""
    overall = report.summary_against_paper(summaries)
    if not overall["cells"]:
        return []
    lines = [
        f"**{overall['at_or_below_paper']} of {overall['cells']} cells of Tables II-V (the default"
        " model has temporal inputs only) are at or below the paper's NRMSE; mean NRMSE"
        f" {overall['mean_ours']:.2f} % against the paper's {overall['mean_paper']:.2f} %.**",
        "",
    ]
    trend = report.summary_against_paper(summaries, TREND_SUFFIX)
    if trend["cells"]:
        lines += [
            f"The pooled SE trend (`-trend`, the default of dgpt-gym 0.8): {trend['at_or_below_paper']}"
            f" of {trend['cells']} cells of Tables II-IX at or below the paper's; mean NRMSE"
            f" {trend['mean_ours']:.2f} % against {trend['mean_paper']:.2f} %.",
            "",
        ]
    lines += [
        "Per scenario and clutter rate, the default model:",
        "",
        "| scenario | clutter rate | ours % | paper % | cells at or below the paper |",
        "|---|---|---|---|---|",
    ]
    for scenario in sorted({row["scenario"] for row in summaries}):
        for clutter in sorted({row["clutter_rate"] for row in summaries}):
            part = report.summary_against_paper(
                [r for r in summaries if r["scenario"] == scenario and r["clutter_rate"] == clutter]
            )
            if part["cells"]:
                lines.append(
                    f"| {scenario} | {clutter:g} | {part['mean_ours']:.2f} | {part['mean_paper']:.2f}"
                    f" | {part['at_or_below_paper']} / {part['cells']} |"
                )
    return lines + [""]


def bounds_markdown(summaries: list[dict]) -> list[str]:
    """Per tracker that reports it (DGPT, the GP trackers, the hybrid filter): the share of
    fitted steps with a hyperparameter on a bound, overall and per hyperparameter, per
    scenario (mean over the scenario's cells)."""
    rows = [row for row in summaries if np.isfinite(row.get("share_at_bound", np.nan))]
    if not rows:
        return []
    names = list(
        dict.fromkeys(
            key.removeprefix("share_at_bound_")
            for row in rows
            for key in row
            if key.startswith("share_at_bound_") and np.isfinite(row[key])
        )
    )
    lines = [
        "## Hyperparameters on their bounds",
        "",
        "Share of the steps whose maximum-likelihood fit ended with a hyperparameter on a bound"
        " (either axis): for the default state-space trackers the process noise q on"
        " `agents.state_space_dgpt.PROCESS_NOISE_BOUNDS`, for the `-trend` and `-paper`"
        " trackers eq. (22)'s hyperparameters on `agents.dgpt.HYPERPARAMETER_BOUNDS`. Those"
        " steps the window's data did not identify the model. Mean over the cells of each"
        " scenario; %.",
        "",
        "| tracker | scenario | any | " + " | ".join(names) + " |",
        "|---|---|---|" + "---|" * len(names),
    ]
    for tracker in dict.fromkeys(row["tracker"] for row in rows):
        for scenario in sorted({row["scenario"] for row in rows if row["tracker"] == tracker}):
            cell = [r for r in rows if r["tracker"] == tracker and r["scenario"] == scenario]

            def share(key, cell=cell):
                values = [r.get(key, np.nan) for r in cell]
                return "-" if np.all(np.isnan(values)) else f"{100 * np.nanmean(values):.0f}"

            lines.append(
                f"| {tracker} | {scenario} | {share('share_at_bound')} | "
                + " | ".join(share(f"share_at_bound_{name}") for name in names)
                + " |"
            )
    return lines + [""]


def results_markdown(
    summaries: list[dict], failures: list[dict], total_units: int, command: str, links: list[str]
) -> str:
    """``results.md``: what the sweep measured, in one page."""
    finished = int(sum(row["n_runs"] for row in summaries))
    versions = sorted({version for row in summaries for version in row["versions"].split()})
    lines = [
        "# Results",
        "",
        f"Generated from the results database by `{command}` (runs by dgpt-gym "
        f"{', '.join(versions) or '-'}); do not edit by hand, re-run the command.",
        "",
        f"Runs: {finished} finished of {total_units}; **{len(failures)} failed**.",
        "",
    ]
    if failures:
        lines += [
            "| tracker | scenario | noise std | clutter | seed | error |",
            "|---|---|---|---|---|---|",
        ]
        for row in failures[:20]:
            lines.append(
                f"| {row['tracker']} | {row['scenario']} | {row['noise_std']:g} | "
                f"{row['clutter_rate']:g} | {row['seed']} | {row['error']} |"
            )
        lines.append("")
    lines += paper_comparison_markdown(summaries)
    lines += [
        "## Mean NRMSE (%) per tracker and scenario",
        "",
        "Mean over both axes and every noise level and clutter rate of the sweep.",
        "",
        nrmse_by_scenario_markdown(summaries),
        "",
        *bounds_markdown(summaries),
        "## Tracker step time",
        "",
        "| tracker | median step time (ms), mean over runs |",
        "|---|---|",
    ]
    for tracker in dict.fromkeys(row["tracker"] for row in summaries):
        times = [row["step_time_ms"] for row in summaries if row["tracker"] == tracker]
        lines.append(f"| {tracker} | {np.mean(times):.2f} |")
    lines += ["", "## Files", ""] + [f"- {link}" for link in links]
    return "\n".join(lines + [""])


def _figure_run(units: list, summaries: list[dict]):
    """The unit of Figs. 4-7: DGPT-RBCM (else the first tracker with a UCB) on S1 (else the
    first scenario), the lowest noise level and clutter rate, the first seed."""
    with_ucb = [row for row in summaries if np.isfinite(row.get("ucb_coverage_x", np.nan))]
    if not with_ucb:
        return None
    trackers = [row["tracker"] for row in with_ucb]
    tracker = "dgpt-rbcm" if "dgpt-rbcm" in trackers else trackers[0]
    units = [unit for unit in units if unit.tracker == tracker]
    scenarios = {unit.env_kwargs["scenario"] for unit in units}
    scenario = "S1" if "S1" in scenarios else sorted(scenarios)[0]
    units = [unit for unit in units if unit.env_kwargs["scenario"] == scenario]
    return min(
        units,
        key=lambda u: (u.env_kwargs["noise_std"], u.env_kwargs["clutter_rate"], u.seed),
    )


ERROR_CURVE_TRACKERS = ("dgpt-rbcm", "hybrid", "imm-pda", "clairvoyant")
"""Trackers drawn in ``figures/error_vs_time.png`` when the sweep has them."""
ERROR_CURVE_RUNS = 20
"""Runs per scenario of that figure: its first seeds, re-run (the store keeps no per-step
errors); 20 put the median's standard error at about a quarter of the band's width."""


def error_curves(units: list) -> tuple[dict[str, dict[str, np.ndarray]], str]:
    """``{scenario: {tracker: (runs, steps) 2-D errors}}`` for the trackers of
    :data:`ERROR_CURVE_TRACKERS` in the sweep, at its lowest noise level and highest clutter
    rate, on the first :data:`ERROR_CURVE_RUNS` seeds of each scenario; and those settings
    as text."""
    units = [unit for unit in units if unit.tracker in ERROR_CURVE_TRACKERS]
    if not units:
        return {}, ""
    noise = min(unit.env_kwargs["noise_std"] for unit in units)
    clutter = max(unit.env_kwargs["clutter_rate"] for unit in units)
    curves: dict[str, dict[str, np.ndarray]] = {}
    for scenario in sorted({unit.env_kwargs["scenario"] for unit in units}):
        for tracker in ERROR_CURVE_TRACKERS:
            chosen = sorted(
                (
                    unit
                    for unit in units
                    if unit.tracker == tracker
                    and unit.env_kwargs["scenario"] == scenario
                    and unit.env_kwargs["noise_std"] == noise
                    and unit.env_kwargs["clutter_rate"] == clutter
                ),
                key=lambda unit: unit.seed,
            )[:ERROR_CURVE_RUNS]
            if not chosen:
                continue
            results = episode_results(chosen)
            curves.setdefault(scenario, {})[tracker] = np.array(
                [np.linalg.norm(result.mean - result.truth, axis=1) for result in results]
            )
    return curves, f"sigma_z {noise:g} m, clutter rate {clutter:g}"


def write_outputs(
    grids: list[Grid],
    out: str | Path,
    report_dir: str | Path | None = None,
    command: str = "",
    training_time_csv: str | Path | None = None,
) -> list[Path]:
    """Regenerate every output of the sweep ``grids`` from the store at ``out`` into
    ``report_dir`` (default ``out``). Returns the files written."""
    grids = list(grids)
    report_dir = Path(report_dir if report_dir is not None else out)
    figures = report_dir / "figures"
    figures.mkdir(parents=True, exist_ok=True)
    summaries, failures = summarize_store(grids, out)
    written: list[Path] = []
    if not summaries:
        raise ValueError(f"the store at {out} holds no finished run of this sweep")
    add_floor_ratios(summaries, floor=baseline_report.FLOOR)
    written.append(write_cells_csv(summaries, report_dir / "results_cells.csv"))

    baselines = report_dir / "results_baselines.md"
    baselines.write_text(baselines_markdown(summaries, command, per_run_nrmse(grids, out)))
    written.append(baselines)

    paper_rows = [
        row for row in summaries if row["tracker"] in PAPER_GP_TRACKERS + PAPER_AS_PRINTED_TRACKERS
    ]
    if paper_rows:
        tables = report_dir / "results_tables.md"
        report.write_paper_tables(paper_rows, tables, command)
        written += [tables, tables.with_suffix(".md.csv")]

    fig8 = [
        row
        for row in summaries
        if row["tracker"] in report.HYBRID_COMPARISON_TRACKERS
        and row["noise_std"] == 1.0
        and row["clutter_rate"] == 5.0
    ]
    if len({row["tracker"] for row in fig8}) >= 2:
        hybrid = report_dir / "results_hybrid.md"
        written.append(report.plot_hybrid_comparison(fig8, figures / "hybrid_comparison.png"))
        hybrid.write_text(report.hybrid_comparison_markdown(fig8, command))
        written.append(hybrid)

    units = sweep_units(grids)
    unit = _figure_run(units, summaries)
    if unit is not None:
        (result,) = episode_results([unit])
        settings = ", ".join(f"{key} {value}" for key, value in unit.env_kwargs.items())
        figure = plot_ucb_vs_ci(
            result, figures / "ucb_vs_ci.png", f"{unit.tracker}, {settings}, seed {unit.seed}"
        )
        uncertainty = report_dir / "results_uncertainty.md"
        uncertainty.write_text(uncertainty_markdown(summaries, command, "figures/ucb_vs_ci.png"))
        written += [figure, uncertainty]

    curves, settings = error_curves(units)
    if curves:
        written.append(plot_error_against_time(curves, figures / "error_vs_time.png", settings))
    written.append(plot_scenarios(figures / "scenarios.png"))
    if training_time_csv is not None and Path(training_time_csv).exists():
        rows = read_training_time(training_time_csv)
        written.append(plot_training_time(rows, figures / "training_time.png"))

    links = [
        f"[{path.relative_to(report_dir)}]({path.relative_to(report_dir)})" for path in written
    ]
    if (report_dir / "analysis.md").exists():  # a hand-written reading of these numbers
        links.insert(0, "[analysis.md](analysis.md): what these numbers mean")
    results = report_dir / "results.md"
    results.write_text(results_markdown(summaries, failures, len(units), command, links))
    return [results, *written]
