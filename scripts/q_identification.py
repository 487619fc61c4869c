"""Does the window identify the process noise q of ``dgpt-bcm`` when q ends on its floor?

At every learning step of the NCV GP in state-space form (:mod:`agents.state_space_dgpt`),
the last C steps' exact log marginal likelihood is evaluated again at a grid of q (per axis)
and compared with its value at the floor of :data:`PROCESS_NOISE_BOUNDS`. A fit that ends on
the floor is *identified* there when the likelihood falls clearly as q grows (the window says
q is about 0: constant velocity between the manoeuvre component's bursts), and unidentified
when it is flat. Printed per scenario and path mode (both clutter rates): the number of
fits (one per axis per learning step) and the share that end on the floor, and, of those, the median log likelihood ratio
log L(floor) - log L(q) at each q of the grid and the share with a ratio of at least 2 (a
factor e^2 = 7.4) against q = 1 m^2/s^3. Training seeds 1000 onwards.

    python scripts/q_identification.py --seeds 4
"""

from __future__ import annotations

import argparse
import collections
import itertools
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import dgpt_gym  # noqa: E402,F401  (registers the environment)
from agents.state_space import filter_window  # noqa: E402
from agents.state_space_dgpt import (  # noqa: E402
    LEARNING_FILTER,
    PROCESS_NOISE_BOUNDS,
    StateSpaceDGPT,
)
from dgpt_gym.benchmark.episodes import run_episodes  # noqa: E402

Q_GRID = (0.01, 0.1, 1.0, 10.0)
"""q (m^2/s^3) at which the window's likelihood is compared with the floor's."""

CLEAR_RATIO = 2.0
"""A log likelihood ratio of at least this against q = 1 counts as the window preferring
the floor clearly."""


class RecordingStateSpaceDGPT(StateSpaceDGPT):
    """``dgpt-bcm`` that, after each learning step, records per axis whether q ended on
    its floor and the window's log likelihood at the floor and at :data:`Q_GRID`; its
    estimates are the tracker's."""

    def reset(self, spec, seed=None) -> None:
        super().reset(spec, seed)
        self.records_: list[tuple[np.ndarray, np.ndarray]] = []

    def _climb(self, log_likelihood: np.ndarray) -> None:
        super()._climb(log_likelihood)
        floor = PROCESS_NOISE_BOUNDS[0]
        grid = np.array((floor, *Q_GRID))[:, None] * np.ones(2)
        values, _, _ = filter_window(
            LEARNING_FILTER, list(self.steps_), grid, np.full(2, self.noise_var_), self.manoeuvre
        )
        on_floor = self.log_q_ - np.log(floor) < 1e-6
        self.records_.append((on_floor, values[0] - values[1:]))  # (2,), (len(Q_GRID), 2)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=4, help="training seeds 1000 .. 1000+N-1")
    parser.add_argument("--first-seed", type=int, default=1000)
    args = parser.parse_args(argv)
    if args.seeds < 1:
        print("error: --seeds must be at least 1", file=sys.stderr)
        return 2
    print(
        "scenario paths        axis fits  on floor %  "
        + "  ".join(f"median logLR q={q:g}" for q in Q_GRID)
        + f"  logLR(q=1) >= {CLEAR_RATIO:g} %"
    )
    rows = collections.defaultdict(list)
    for scenario, trajectory in itertools.product(("S1", "S2", "S3", "S4"), ("fixed", "random")):
        envs, trackers, seeds = [], [], []
        for clutter, seed in itertools.product(
            (1.0, 5.0), range(args.first_seed, args.first_seed + args.seeds)
        ):
            envs.append(
                gym.make(
                    "DGPTrack-v0", scenario=scenario, clutter_rate=clutter, trajectory=trajectory
                )
            )
            trackers.append(RecordingStateSpaceDGPT())
            seeds.append(seed)
        run_episodes(envs, trackers, seeds)
        on_floor = np.concatenate([[r[0] for r in t.records_] for t in trackers]).ravel()
        ratios = np.concatenate([[r[1].T for r in t.records_] for t in trackers])  # (n, 2, q)
        ratios = ratios.reshape(-1, len(Q_GRID))[on_floor]
        clear = 100 * np.mean(ratios[:, Q_GRID.index(1.0)] >= CLEAR_RATIO)
        medians = np.median(ratios, axis=0)
        rows["all"].append((on_floor, ratios))
        print(
            f"{scenario:8s} {trajectory:6s} {on_floor.size:15d} {100 * on_floor.mean():11.1f}  "
            + "  ".join(f"{m:17.2f}" for m in medians)
            + f"  {clear:20.1f}"
        )
    on_floor = np.concatenate([r[0] for r in rows["all"]])
    ratios = np.concatenate([r[1] for r in rows["all"]])
    print(
        f"all             {on_floor.size:15d} {100 * on_floor.mean():11.1f}  "
        + "  ".join(f"{m:17.2f}" for m in np.median(ratios, axis=0))
        + f"  {100 * np.mean(ratios[:, Q_GRID.index(1.0)] >= CLEAR_RATIO):20.1f}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
