#!/usr/bin/env python
"""Baseline evaluation: Monte Carlo NRMSE of registered trackers on the paper's scenarios.

With no options it runs the quick grid (all four scenarios, clutter rates 1 and 5,
sigma_z = 1, a few runs) and prints a Markdown table of NRMSE per scenario and axis.
"""

from __future__ import annotations

import argparse
import sys

import dgpt_gym  # registers the env and the trackers
from dgpt_gym.evaluation import evaluate_grid, format_nrmse_table
from dgpt_gym.plots import plot_scenarios


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--trackers",
        nargs="+",
        default=["centroid"],
        help=f"registered tracker ids (default: centroid); known: {dgpt_gym.tracker_ids()}",
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
        "--runs", type=int, default=10, help="Monte Carlo runs per cell (default: 10)"
    )
    parser.add_argument("--seed", type=int, default=0, help="first seed (default: 0)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    parser.add_argument(
        "--plot-scenarios",
        metavar="PNG",
        default=None,
        help="write the trajectories figure (paper Fig. 3) to PNG and exit",
    )
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.plot_scenarios:
        print(f"wrote {plot_scenarios(args.plot_scenarios)}")
        return 0
    try:
        rows = evaluate_grid(
            args.trackers,
            args.scenarios,
            args.noise_std,
            args.clutter_rates,
            runs=args.runs,
            first_seed=args.seed,
            progress=not args.no_progress,
        )
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(format_nrmse_table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
