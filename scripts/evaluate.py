#!/usr/bin/env python
"""Baseline evaluation: Monte Carlo NRMSE of registered trackers on the paper's scenarios.

With no options it runs the quick grid (all four scenarios, clutter rates 1 and 5,
sigma_z = 1, a few runs of the standard GP, DGPT-RBCM and DGPT-GPoE) and prints a Markdown
table of NRMSE per scenario and axis.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import dgpt_gym  # registers the env and the trackers
from dgpt_gym.evaluation import evaluate_grid, format_nrmse_table
from dgpt_gym.plots import plot_scenarios
from dgpt_gym.report import (
    HYBRID_COMPARISON_TRACKERS,
    hybrid_comparison_markdown,
    plot_hybrid_comparison,
    write_paper_tables,
)
from dgpt_gym.tuning import save_tuned_windows, tune_windows

PAPER_TRACKERS = ["gp", "gp-stgp", "dgpt-rbcm", "dgpt-rbcm-stgp", "dgpt-gpoe", "dgpt-gpoe-stgp"]


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--trackers",
        nargs="+",
        default=["gp", "dgpt-rbcm", "dgpt-gpoe"],
        help=f"registered tracker ids (default: gp dgpt-rbcm dgpt-gpoe); known: {dgpt_gym.tracker_ids()}",
    )
    parser.add_argument(
        "--scenarios",
        nargs="+",
        default=["S1", "S2", "S3", "S4"],
        help="scenarios S1..S4 (default: all)",
    )
    parser.add_argument(
        "--noise-std",
        nargs="+",
        type=float,
        default=[1.0],
        help="sigma_z levels, m (default: 1; the paper: 1 2 4)",
    )
    parser.add_argument(
        "--clutter-rates",
        nargs="+",
        type=float,
        default=[1.0, 5.0],
        help="clutter rates lambda_c (default: 1 5)",
    )
    parser.add_argument(
        "--runs", type=int, default=5, help="Monte Carlo runs per cell (default: 5)"
    )
    parser.add_argument("--seed", type=int, default=0, help="first seed (default: 0)")
    parser.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count() or 1,
        help="worker processes (default: all cores)",
    )
    parser.add_argument(
        "--no-tuned-windows",
        action="store_true",
        help="use the trackers' default window instead of the per-scenario tuned one",
    )
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    parser.add_argument(
        "--plot-scenarios",
        metavar="PNG",
        default=None,
        help="write the trajectories figure (paper Fig. 3) to PNG and exit",
    )
    parser.add_argument(
        "--paper-tables",
        metavar="MARKDOWN",
        default=None,
        help="run the grid of the paper's Tables II-IX for the given --noise-std, "
        "--clutter-rates and --runs with the six GP trackers and write the "
        "tables (ours beside the paper's) to MARKDOWN, rows to MARKDOWN.csv",
    )
    parser.add_argument(
        "--hybrid-comparison",
        metavar="MARKDOWN",
        default=None,
        help="run the paper's Fig. 8 comparison (sigma_z = 1, clutter rate 5; gp, dgpt-rbcm, "
        "hybrid, hybrid-paper, cpf) with --runs runs, write its table to MARKDOWN and its "
        "figure to figures/hybrid_comparison.png beside it",
    )
    parser.add_argument(
        "--tune-windows",
        action="store_true",
        help=f"grid-search the window of {PAPER_TRACKERS} on training seeds, "
        "rewrite dgpt_gym/tuned_windows.json and exit",
    )
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.plot_scenarios:
        print(f"wrote {plot_scenarios(args.plot_scenarios)}")
        return 0
    try:
        if args.tune_windows:
            best, rows = tune_windows(
                PAPER_TRACKERS, args.scenarios, workers=args.workers, progress=not args.no_progress
            )
            save_tuned_windows(best, rows)
            for tracker, by_scenario in best.items():
                print(tracker, by_scenario)
            return 0
        trackers = PAPER_TRACKERS if args.paper_tables else args.trackers
        if args.hybrid_comparison:
            trackers = list(HYBRID_COMPARISON_TRACKERS)
            args.noise_std, args.clutter_rates = [1.0], [5.0]
        rows = evaluate_grid(
            trackers,
            args.scenarios,
            args.noise_std,
            args.clutter_rates,
            runs=args.runs,
            first_seed=args.seed,
            progress=not args.no_progress,
            workers=args.workers,
            tuned_windows=not args.no_tuned_windows,
        )
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    command = "python scripts/evaluate.py " + " ".join(argv if argv is not None else sys.argv[1:])
    if args.hybrid_comparison:
        target = Path(args.hybrid_comparison)
        figure = plot_hybrid_comparison(rows, target.parent / "figures" / "hybrid_comparison.png")
        target.write_text(hybrid_comparison_markdown(rows, command))
        print(f"wrote {target} and {figure}")
    if args.paper_tables:
        write_paper_tables(rows, args.paper_tables, command)
        print(f"wrote {args.paper_tables} and {args.paper_tables}.csv")
    print(format_nrmse_table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
