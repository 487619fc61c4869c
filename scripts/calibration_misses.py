"""Where a tracker's 3-sigma intervals miss the truth on detected steps (steps on which
some sensor senses the target), tallied by what the step was: how many steps since the
last coverage gap (0: the first detected step after it, or the episode's first), how many
target-originated points the step's observation holds, and whether the target is turning.
Per group: steps, the share of axes outside +-3 sigma (nominal 0.27 %), and the median and
mean of the squared errors over the variances summed over the axes (a 2-D NEES without the
cross-covariance; nominal median 1.39, mean 2). Runs on the training seeds by default.

    python scripts/calibration_misses.py --scenario S1 --clutter-rate 5
    python scripts/calibration_misses.py --scenario S3 --clutter-rate 5 --noise-std 4
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
from dgpt_gym.registry import make_tracker, tracker_ids  # noqa: E402

SINCE_GAP_GROUPS = ((0, 0), (1, 1), (2, 4), (5, 9), (10, None))
"""Steps since the last coverage gap, inclusive ranges (None: no upper end)."""


def episode_steps(env, tracker, seed: int) -> np.ndarray:
    """One episode's detected steps as rows (z_x, z_y, steps since the last gap, target
    points in the observation, turning 0/1): z the error over the standard deviation."""
    observation, info = env.reset(seed=seed)
    tracker.reset(info["problem_spec"], seed=seed)
    rows, since_gap, truncated = [], 0, False
    while not truncated:
        origin, turn_rate = info["target_origin"], info["turn_rate"]
        estimate = tracker.update(observation)
        mask = np.asarray(observation["mask"], dtype=bool)
        observation, _, _, truncated, info = env.step(estimate.mean)
        if len(info["active_sensors"]) == 0:
            since_gap = 0
            continue
        z = (estimate.mean - info["position"]) / np.sqrt(np.maximum(estimate.var, 1e-300))
        turning = float(turn_rate is not None and turn_rate != 0.0)
        rows.append((z[0], z[1], since_gap, float(np.sum(origin[mask])), turning))
        since_gap += 1
    return np.array(rows, dtype=float).reshape(-1, 5)


def group_rows(steps: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """The groups of :data:`SINCE_GAP_GROUPS`, by target points (1, 2 or more) and by
    turning, each as (label, boolean mask over the rows)."""
    since, points, turning = steps[:, 2], steps[:, 3], steps[:, 4] == 1.0
    groups = [("all detected steps", np.ones(len(steps), dtype=bool))]
    for low, high in SINCE_GAP_GROUPS:
        if high is None:
            label = f"{low}+ steps since a gap"
        elif low == high:
            label = f"{low} step{'s' if low != 1 else ''} since a gap"
        else:
            label = f"{low}-{high} steps since a gap"
        groups.append((label, (since >= low) & (since <= (np.inf if high is None else high))))
    groups.append(("1 target point", points == 1))
    groups.append(("2+ target points", points >= 2))
    groups.append(("turning", turning))
    groups.append(("not turning", ~turning))
    return groups


def miss_table(steps: np.ndarray) -> list[tuple[str, int, float, float, float]]:
    """Per group of :func:`group_rows`: (label, steps, share of axes outside 3 sigma,
    median and mean of z_x^2 + z_y^2); NaN for an empty group."""
    table = []
    for label, mask in group_rows(steps):
        z = steps[mask, :2]
        squared = np.sum(z**2, axis=1)
        if not len(z):
            table.append((label, 0, np.nan, np.nan, np.nan))
            continue
        outside = float(np.mean(np.abs(z) > 3.0))
        table.append((label, len(z), outside, float(np.median(squared)), float(squared.mean())))
    return table


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tracker", default="dgpt-rbcm", choices=tracker_ids())
    parser.add_argument("--scenario", default="S1", choices=["S1", "S2", "S3", "S4"])
    parser.add_argument("--trajectory", default="fixed", choices=["fixed", "random"])
    parser.add_argument("--clutter-rate", type=float, default=5.0)
    parser.add_argument("--noise-std", type=float, default=1.0)
    parser.add_argument("--seeds", type=int, default=100, help="seeds FIRST .. FIRST+N-1")
    parser.add_argument(
        "--first-seed", type=int, default=1000, help="default 1000: the training seeds"
    )
    parser.add_argument("--no-progress", action="store_true")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error(f"--seeds must be at least 1; got {args.seeds}")
    env = gymnasium.make(
        "DGPTrack-v0",
        scenario=args.scenario,
        clutter_rate=args.clutter_rate,
        noise_std=args.noise_std,
        trajectory=args.trajectory,
    )
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    steps = np.concatenate(
        [
            episode_steps(env, make_tracker(args.tracker), seed)
            for seed in tqdm(seeds, disable=args.no_progress, desc="episodes")
        ]
    )
    print(
        f"{args.tracker}, {args.scenario} {args.trajectory} path, clutter {args.clutter_rate:g}, "
        f"sigma_z {args.noise_std:g}, seeds {seeds.start}-{seeds.stop - 1}\n"
    )
    print("| steps | count | outside 3 sigma, % of axes | median NEES | mean NEES |")
    print("|---|---|---|---|---|")
    for label, count, outside, median, mean in miss_table(steps):
        print(f"| {label} | {count} | {100 * outside:.2f} | {median:.2f} | {mean:.2f} |")


if __name__ == "__main__":
    main()
