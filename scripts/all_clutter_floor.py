"""How close trackers can come, with clutter at every sensor, to their error with clutter at
the detecting sensors: the shape-known floor (:mod:`baselines.shape_floor`) beside a
registered tracker in both clutter modes, on the same episodes.

For each cell (S1-S4, reference and random paths, sigma_z = 1) and seed, the floor's
posterior over the start is computed for the first ``--horizon`` steps (its error after
them is left out, so its RMSE here is at most its whole episode's), and the tracker runs
the episode with ``clutter_sensors="all"`` and ``"detecting"``. Printed per cell: the
floor's 2-D RMSE over the 150 steps (root mean square over the episodes of each episode's
RMSE, like the trackers'), the first step at which its error is below 3 m (median over
episodes), its largest posterior standard deviation at the horizon (m; small means the
horizon was long enough), the least effective number of its draws on the steps where its
posterior's standard deviation exceeds 3 m (the ambiguous ones), the tracker's RMSE in
both modes, their ratio, the floor's RMSE over the tracker's detecting one, and where the
tracker's squared error with clutter at every sensor lies (:func:`error_parts`: before its
track first holds, in or just after a coverage gap, elsewhere). Where the floor's ratio
exceeds 2, no tracker can be expected to meet the goal "all at most twice detecting" (on
random paths the floor is the least mean-squared error given the shape and the scans);
where it does not, the goal is not ruled out. The floor's prior on the start is the
scenario's law given the shape (:func:`baselines.shape_floor.start_box`).

    python scripts/all_clutter_floor.py                        # seeds 0-29, clutter 1
    python scripts/all_clutter_floor.py --seeds 4 --tracker gp --first-seed 1000
    python scripts/all_clutter_floor.py --first-seed 1000 --seeds 12 --no-floor
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import gymnasium
import numpy as np
from tqdm import tqdm

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import dgpt_gym  # noqa: E402, F401  (registers the environments)
from baselines.shape_floor import shape_known_posteriors, start_box  # noqa: E402
from dgpt_gym.benchmark.episodes import root_mean_square, run_episodes  # noqa: E402
from dgpt_gym.registry import make_tracker, tracker_ids  # noqa: E402

SCENARIOS = ["S1", "S2", "S3", "S4"]
TRAJECTORIES = ["fixed", "random"]

FLOOR_DRAWS = 60000
"""Importance draws of the start per episode; the least effective number is printed."""


AMBIGUOUS_SD = 3.0
"""m: a step whose posterior has a larger standard deviation is one where the start is
still ambiguous; the effective number of draws printed is the least over such steps (where
the posterior has collapsed onto the target, one draw carries it and its error is a metre
or two)."""


def floor_errors(env, seed: int, horizon: int, draws: int) -> tuple[np.ndarray, float, float]:
    """The floor's squared 2-D errors (horizon,) on the episode ``seed`` of ``env`` (reset
    here), its posterior's largest standard deviation at the horizon and the least
    effective number of its draws on the steps where the start is still ambiguous (NaN if
    none is)."""
    env.reset(seed=seed)
    base = env.unwrapped
    positions = base.trajectory_.positions
    scans = base.scans_
    horizon = min(horizon, positions.shape[0])
    steps = [
        (scans.measurements[scans.rows(t)], scans.sensor[scans.rows(t)]) for t in range(horizon)
    ]
    displacements = positions[:horizon] - positions[0]
    box = start_box(positions - positions[0], base.scenario.area, base.scenario.boundary_margin)
    means, covs, ess = shape_known_posteriors(
        steps, displacements, base.problem_spec, draws, np.random.default_rng(seed), box
    )
    errors = np.sum((means + displacements - positions[:horizon]) ** 2, axis=1)
    spread = np.sqrt(np.linalg.eigvalsh(covs)[:, -1])  # the posterior's largest sd per step
    ambiguous = spread > AMBIGUOUS_SD
    least_ess = float(ess[ambiguous].min()) if ambiguous.any() else float("nan")
    return errors, float(spread[-1]), least_ess


HELD_M, HELD_STEPS, AFTER_GAP_STEPS = 10.0, 3, 10
"""The track first holds at the first of ``HELD_STEPS`` steps in a row with an error below
``HELD_M``; a step is near a gap if some sensor-less step (no sensor senses the target) is
among it and the ``AFTER_GAP_STEPS`` steps before it."""


def error_parts(result) -> np.ndarray:
    """An episode's squared 2-D errors summed over three sets of steps: before the track
    first holds, near a coverage gap after that, and the rest (:data:`HELD_M`,
    :data:`HELD_STEPS`, :data:`AFTER_GAP_STEPS`)."""
    squared = np.sum((result.mean - result.truth) ** 2, axis=1)
    below = (np.sqrt(squared) < HELD_M).astype(int)
    held = np.convolve(below, np.ones(HELD_STEPS, dtype=int), "valid") == HELD_STEPS
    first_held = int(np.argmax(held)) if held.any() else squared.size
    gap = (result.n_detecting == 0).astype(int)
    near_gap = np.convolve(gap, np.ones(AFTER_GAP_STEPS + 1, dtype=int))[: gap.size] > 0
    before = np.arange(squared.size) < first_held
    return np.array(
        [
            squared[before].sum(),
            squared[~before & near_gap].sum(),
            squared[~before & ~near_gap].sum(),
        ]
    )


def make_env(scenario: str, trajectory: str, clutter_rate: float, clutter_sensors: str):
    return gymnasium.make(
        "DGPTrack-v0",
        scenario=scenario,
        trajectory=trajectory,
        clutter_rate=clutter_rate,
        clutter_sensors=clutter_sensors,
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--seeds", type=int, default=30)
    parser.add_argument("--clutter-rate", type=float, default=1.0)
    parser.add_argument("--horizon", type=int, default=30, help="steps of the floor's posterior")
    parser.add_argument("--draws", type=int, default=FLOOR_DRAWS)
    parser.add_argument("--tracker", default="dgpt-rbcm", choices=tracker_ids())
    parser.add_argument(
        "--scenarios", nargs="+", default=SCENARIOS, choices=SCENARIOS, metavar="SCENARIO"
    )
    parser.add_argument(
        "--trajectories", nargs="+", default=TRAJECTORIES, choices=TRAJECTORIES, metavar="PATH"
    )
    parser.add_argument(
        "--no-floor", action="store_true", help="run the tracker alone (the floor's columns: -)"
    )
    parser.add_argument("--no-progress", action="store_true")
    args = parser.parse_args(argv)
    if args.seeds < 1 or args.horizon < 1 or args.draws < 3:
        parser.error("--seeds and --horizon must be at least 1, --draws at least 3")
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    floor_setting = (
        "no floor" if args.no_floor else f"floor horizon {args.horizon} steps, {args.draws} draws"
    )
    print(
        f"seeds {seeds[0]}-{seeds[-1]}, clutter rate {args.clutter_rate:g}, sigma_z 1, "
        f"{floor_setting}; tracker {args.tracker}"
    )
    print(
        "cell          floor RMSE  floor <3 m at  floor sd  min ESS   all RMSE  detecting"
        "  all/det  floor/det  all: % of squared error before the track holds / near gaps"
        " / elsewhere"
    )
    cells = [(s, p) for s in args.scenarios for p in args.trajectories]
    bar = tqdm(total=len(cells) * len(seeds), disable=args.no_progress, desc="episodes")
    for scenario, trajectory in cells:
        floor_env = make_env(scenario, trajectory, args.clutter_rate, "all")
        floor_rmse, resolved, spread, least_ess = [], [], [], []
        for seed in [] if args.no_floor else seeds:
            errors, sd, ess = floor_errors(floor_env, seed, args.horizon, args.draws)
            n_steps = floor_env.unwrapped.n_steps
            floor_rmse.append(np.sqrt(errors.sum() / n_steps))
            below = np.flatnonzero(np.sqrt(errors) < 3.0)
            resolved.append(below[0] if below.size else errors.size)
            spread.append(sd)
            least_ess.append(ess)
            bar.update()
        tracker_rmse = {}
        for mode in ("all", "detecting"):
            envs = [make_env(scenario, trajectory, args.clutter_rate, mode) for _ in seeds]
            trackers = [make_tracker(args.tracker) for _ in seeds]
            results = run_episodes(envs, trackers, seeds)
            tracker_rmse[mode] = np.array([r.metrics()["rmse_2d"] for r in results])
            if mode == "all":
                parts = sum(error_parts(result) for result in results)
                shares = " / ".join(f"{share:.0f}" for share in 100 * parts / parts.sum())
            if args.no_floor and mode == "detecting":  # the bar counts a cell's seeds
                bar.update(len(seeds))

        all_, detecting = (
            root_mean_square(tracker_rmse["all"]),
            root_mean_square(tracker_rmse["detecting"]),
        )
        if args.no_floor:
            floor_columns = f"{'-':>10s}  {'-':>13s}  {'-':>8s}  {'-':>7s}"
            floor_ratio = f"{'-':>9s}"
        else:
            floor = root_mean_square(floor_rmse)
            ambiguous = [value for value in least_ess if not np.isnan(value)]
            least = f"{min(ambiguous):7.0f}" if ambiguous else "      -"
            floor_columns = (
                f"{floor:10.2f}  {np.median(resolved):13.1f}  {max(spread):8.2f}  {least}"
            )
            floor_ratio = f"{floor / detecting:9.2f}"
        print(
            f"{scenario} {trajectory:6s}  {floor_columns}  {all_:9.2f}  {detecting:9.2f}"
            f"  {all_ / detecting:7.2f}  {floor_ratio}  {shares}",
            flush=True,
        )
    bar.close()


if __name__ == "__main__":
    main()
