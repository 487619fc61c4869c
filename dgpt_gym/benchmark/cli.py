"""``dgpt-evaluate`` (also ``python scripts/evaluate.py``), the baseline evaluation: Monte Carlo runs of registered trackers on the paper's scenarios.

With no options it runs the quick grid (S1-S4, clutter rates 1 and 5, sigma_z = 1, 10 runs of
the trackers of :data:`dgpt_gym.benchmark.sweep.QUICK_SWEEP`: the standard GP, DGPT-RBCM and
DGPT-GPoE, the pooled-trend DGPT-RBCM, the hybrid
filter around each DGPT-RBCM, the CPF, the IMM-PDA and the clairvoyant floor; 1-2 minutes
on 2 cores) and prints a table per cell: NRMSE with its 95 %
interval over runs beside the paper's value, RMSE, the ratio to the clairvoyant floor, ANEES,
3-sigma coverage and track loss. --trajectory random and --layout per_episode run the grid
off the paper's setting: a random path per seed, and seed s in sensor layout s (every
setting was chosen in layout 0). --paper runs the paper's full grid. Every
finished run is stored at once in OUT/results.sqlite: re-running the same command resumes
an interrupted sweep. The tables and figures are then regenerated from the database.
--verify N re-runs N of the stored runs and checks that the installed code reproduces them.
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace
from pathlib import Path

import dgpt_gym  # registers the env and the trackers
from dgpt_gym.benchmark.episodes import add_floor_ratios, format_summary_table
from dgpt_gym.benchmark.outputs import write_outputs
from dgpt_gym.benchmark.protocol import WINDOWED_TRACKERS
from dgpt_gym.benchmark.sweep import (
    DEFAULT_BATCH_SIZE,
    PAPER_SWEEP,
    QUICK_SWEEP,
    Grid,
    run_sweep,
    summarize_store,
    verify_store,
)
from dgpt_gym.benchmark.tuning import (
    BASELINE_CANDIDATES,
    baseline_tuning_markdown,
    grid_search,
    tune_windows,
)
from dgpt_gym.benchmark.windows import save_tuned_windows
from dgpt_gym.env import LAYOUT_MODES, TRAJECTORY_MODES
from dgpt_gym.naming import MODEL_SUFFIXES, split_tracker_id, tracker_id
from dgpt_gym.registry import tracker_spec

DOCS = Path("docs")
"""Where ``--tune-baselines`` writes and the training-time table is read: the ``docs`` folder
of the working directory (the repository root when run as the README says)."""
QUICK = QUICK_SWEEP[0]


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    grid = parser.add_argument_group("the grid (ignored with --paper, but for --runs)")
    grid.add_argument(
        "--trackers",
        nargs="+",
        default=list(QUICK.trackers),
        metavar="ID",
        help=f"registered tracker ids (default: {' '.join(QUICK.trackers)}); "
        f"known: {' '.join(dgpt_gym.tracker_ids())}",
    )
    grid.add_argument(
        "--inputs",
        nargs="+",
        choices=["tgp", "stgp"],
        default=["tgp"],
        help="input types of the GP trackers: tgp runs the ids as given, stgp their "
        "'-stgp' variants, which the -trend and -paper ids have and the default "
        "state-space ids do not (default: tgp)",
    )
    grid.add_argument(
        "--scenarios", nargs="+", default=list(QUICK.scenarios), help="S1..S4 (default: all)"
    )
    grid.add_argument(
        "--noise-std",
        nargs="+",
        type=float,
        default=list(QUICK.noise_levels),
        help="sigma_z levels, m (default: 1; the paper's: 1 2 4)",
    )
    grid.add_argument(
        "--clutter-rates",
        nargs="+",
        type=float,
        default=list(QUICK.clutter_rates),
        help="clutter rates lambda_c (default: 1 5)",
    )
    grid.add_argument(
        "--runs",
        type=int,
        default=None,
        help="Monte Carlo runs per cell (default: 10, with --paper 100; this option applies "
        "to --paper too)",
    )
    grid.add_argument(
        "--trajectory",
        choices=TRAJECTORY_MODES,
        default="fixed",
        help="fixed: the scenarios' reference paths (the paper's); random: a new path of the "
        "scenario's kind per seed (default: fixed)",
    )
    grid.add_argument(
        "--layout",
        choices=LAYOUT_MODES,
        default="fixed",
        help="fixed: the sensor layout of layout_seed 0, in which every setting was chosen; "
        "per_episode: seed s in layout s (default: fixed)",
    )
    grid.add_argument(
        "--no-tuned-windows",
        action="store_true",
        help="use the trackers' default window instead of the one tuned per scenario",
    )
    parser.add_argument(
        "--paper",
        action="store_true",
        help="the paper's full grid: S1-S4, sigma_z 1 2 4, clutter 1 5, standard GP, "
        "DGPT-RBCM and DGPT-GPoE with the default model and with the pooled trend (TGP and "
        "STGP inputs), KF-PDA, IMM-PDA and the clairvoyant floor; the "
        "-paper trackers, the hybrid filters and the CPF at sigma_z 1 (clutter 5 is Fig. 8); "
        "100 runs each",
    )
    parser.add_argument("--seed", type=int, default=0, help="first seed (default: 0)")
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output folder holding results.sqlite (default: results/quick, or results/paper "
        "with --paper)",
    )
    parser.add_argument(
        "--report-dir",
        type=Path,
        default=None,
        help="folder for the tables and figures (default: OUT)",
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count() or 1,
        help="local worker processes (default: all cores; 1 runs in this process)",
    )
    parser.add_argument(
        "--batch-size",
        type=int,
        default=DEFAULT_BATCH_SIZE,
        help="runs of one tracker on one cell stepped in lockstep per task (default: "
        f"{DEFAULT_BATCH_SIZE}); changes the speed, never the numbers",
    )
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        default=None,
        help="run on the Dask cluster of this scheduler (e.g. tcp://10.0.0.5:8786) instead of "
        "local processes; needs the 'cluster' extra",
    )
    parser.add_argument(
        "--report-only",
        action="store_true",
        help="regenerate the tables and figures from the database without running anything",
    )
    parser.add_argument(
        "--verify",
        metavar="N",
        type=int,
        default=None,
        help="re-run N of the grid's runs that this version stored, chosen at random, check "
        "that every metric (step times aside) equals the stored one to the last bit, and exit "
        "(1 if any differs); runs nothing else, on local processes",
    )
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    parser.add_argument(
        "--tune-windows",
        action="store_true",
        help="grid-search the window of the -trend and -paper GP trackers on "
        "training seeds, fixed and random paths, "
        "rewrite dgpt_gym/benchmark/tuned_windows.json and exit",
    )
    parser.add_argument(
        "--tune-baselines",
        action="store_true",
        help="grid-search the settings of pda and imm-pda on training seeds (fixed and random "
        "paths), write docs/baseline_tuning.md and exit; the winners are the classes' defaults",
    )
    return parser.parse_args(argv)


def with_inputs(trackers: list[str], inputs: list[str]) -> list[str]:
    """The tracker ids for the requested input types ('-stgp' variants for stgp); trackers
    without a GP input type (pda, imm-pda, clairvoyant, cpf, ...) are kept as given, and so
    are the default state-space GP trackers, which have temporal inputs only, unless stgp
    alone is asked for them (a ValueError naming their STGP forms)."""
    ids = []
    known = dgpt_gym.tracker_ids()
    for tracker in trackers:
        tracker_spec(tracker)  # unknown ids fail here, with the list of known ones
        approach, _, suffix = split_tracker_id(tracker)
        if tracker_id(approach, "stgp", suffix) in known:
            ids += [tracker_id(approach, kind, suffix) for kind in inputs]
            continue
        stgp_forms = [
            tracker_id(approach, "stgp", other)
            for other in MODEL_SUFFIXES
            if tracker_id(approach, "stgp", other) in known
        ]
        if stgp_forms and "tgp" not in inputs:
            raise ValueError(
                f"{tracker!r} has temporal inputs only (--inputs tgp); the STGP forms of "
                f"{approach!r} are {stgp_forms}"
            )
        ids.append(tracker)
    return list(dict.fromkeys(ids))


OPTION_OF_ARGUMENT = {
    "scenario": "--scenarios",
    "noise_std": "--noise-std",
    "clutter_rate": "--clutter-rates",
    "runs": "--runs",
    "first_seed": "--seed",
    "workers": "--workers",
    "batch_size": "--batch-size",
    "count": "--verify",
    "scheduler": "--scheduler",
}
"""The command-line option behind each argument name that the library's errors use."""


def with_option(error: Exception) -> str:
    """The error's message, naming the option too when it starts with an argument's name
    (the library's checks name ``clutter_rate``; the user typed ``--clutter-rates``)."""
    message = str(error)
    name = message.split(" ", 1)[0]
    option = OPTION_OF_ARGUMENT.get(name)
    return message if option is None else f"{message} (option {option})"


def build_grids(args: argparse.Namespace) -> list[Grid]:
    if args.paper and (args.trajectory, args.layout) != ("fixed", "fixed"):
        raise ValueError(
            "--trajectory and --layout apply to the grid of --trackers; --paper reports the "
            "paper's reference paths in layout 0 (scripts/random_paths.py runs every tracker "
            "off them)"
        )
    if args.paper:
        runs = {} if args.runs is None else {"runs": args.runs}
        return [replace(grid, first_seed=args.seed, **runs) for grid in PAPER_SWEEP]
    return [
        Grid(
            trackers=tuple(with_inputs(args.trackers, args.inputs)),
            scenarios=tuple(args.scenarios),
            noise_levels=tuple(args.noise_std),
            clutter_rates=tuple(args.clutter_rates),
            runs=QUICK.runs if args.runs is None else args.runs,
            first_seed=args.seed,
            tuned_windows=not args.no_tuned_windows,
            trajectory=args.trajectory,
            layout=args.layout,
        )
    ]


def verify(grids: list[Grid], out: Path, args: argparse.Namespace) -> int:
    """``--verify N``: :func:`verify_store` on the grid's store, with a line per difference."""
    try:
        report = verify_store(
            grids,
            out,
            args.verify,
            args.workers,
            progress=not args.no_progress,
            batch_size=args.batch_size,
        )
    except ValueError as error:  # a bad N or --workers, or an empty store
        print(f"error: {with_option(error)}", file=sys.stderr)
        return 2
    for line in report.mismatches:
        print(f"  differs: {line}")
    skipped = (
        f" ({report.other_versions} runs stored by other versions not checked)"
        if report.other_versions
        else ""
    )
    verdict = (
        "every metric equals the stored one"
        if not report.mismatches
        else f"{len(report.mismatches)} differ"
    )
    print(f"re-ran {report.checked} runs of {out}/results.sqlite: {verdict}{skipped}")
    return 1 if report.mismatches else 0


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    # the outputs quote the command that runs the sweep (--report-only writes the same files)
    arguments = [a for a in (argv if argv is not None else sys.argv[1:]) if a != "--report-only"]
    command = "python scripts/evaluate.py " + " ".join(arguments)
    try:
        if args.tune_windows:
            best, rows = tune_windows(
                WINDOWED_TRACKERS,
                args.scenarios,
                workers=args.workers,
                progress=not args.no_progress,
            )
            save_tuned_windows(best, rows)
            for tracker, by_scenario in best.items():
                print(tracker, by_scenario)
            return 0
        if args.tune_baselines:
            results = {
                tracker: grid_search(
                    tracker,
                    candidates,
                    workers=args.workers,
                    progress=not args.no_progress,
                )
                for tracker, candidates in BASELINE_CANDIDATES.items()
            }
            path = DOCS / "baseline_tuning.md"
            path.write_text(baseline_tuning_markdown(results, command.strip()))
            print(f"wrote {path}")
            return 0
        grids = build_grids(args)
    except ValueError as error:
        print(f"error: {with_option(error)}", file=sys.stderr)
        return 2
    out = args.out or Path("results") / ("paper" if args.paper else "quick")
    if args.verify is not None:
        return verify(grids, out, args)
    if not args.report_only:
        try:
            sweep = run_sweep(
                grids,
                out,
                args.workers,
                args.scheduler,
                progress=not args.no_progress,
                batch_size=args.batch_size,
            )
        except ValueError as error:  # a bad --workers, --batch-size or --out
            print(f"error: {with_option(error)}", file=sys.stderr)
            return 2
        except OSError as error:  # the store's folder is read-only or full
            print(f"error: cannot write to {out}: {error}", file=sys.stderr)
            return 1
        except ImportError as error:  # --scheduler without the cluster extra
            print(f"error: {with_option(error)}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print(
                f"\ninterrupted: every finished run is in {out}/results.sqlite; "
                "run the same command again to resume",
                file=sys.stderr,
            )
            return 130
        print(
            f"{sweep.total} runs: {sweep.already_finished} already in {out}/results.sqlite, "
            f"{sweep.ran} run now, {sweep.failed} failed"
        )
        for error in sweep.errors:
            print(f"  failed: {error}")
    try:
        written = write_outputs(
            grids, out, args.report_dir, command.strip(), DOCS / "training_time.csv"
        )
    except ValueError as error:
        print(f"error: {with_option(error)}", file=sys.stderr)
        return 1
    except OSError as error:  # the report folder is read-only or full
        print(
            f"error: cannot write the outputs to {args.report_dir or out}: {error}", file=sys.stderr
        )
        return 1
    summaries, failures = summarize_store(grids, out)
    print(format_summary_table(add_floor_ratios(summaries)))
    print(f"{len(failures)} failed runs; wrote {written[0]} and {len(written) - 1} more files")
    return 0
