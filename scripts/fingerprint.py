"""A SHA-256 over every number the state-space GP trackers and the sensor environments
produce on a fixed set of episodes: run it before and after a change meant to be a pure
speed-up; the same hash means the same numbers to the last bit.

It covers the estimates, variances and UCBs of ``dgpt-rbcm``, ``dgpt-bcm``, ``dgpt-gpoe``,
``dgpt-poe``, ``gp`` and ``hybrid`` on five configurations (the reference and random
paths, clutter at the detecting sensors and at every sensor, sigma_z 1 and 4), each
episode alone and ``dgpt-rbcm``'s also in a lockstep block (one ``update_batch`` call per
step), and the rewards, errors and observations of the batched ``DGPTrackSensors-v1``,
``-v2``, ``DGPTrackWindow-v0`` and ``DGPTrackGating-v0`` vector environments under seeded
random actions (the RL tasks with committed agents).
``--quick`` runs two seeds per configuration, no blocks and shorter environment runs (a
different hash). One line per episode, then the total. About 40 s on one core.

A change meant to move some of these numbers changes the total too; ``--compare`` with the
output of a run before the change lists the lines that moved, so that one can check that
only those meant to move did (the trackers changed, not an environment that pins an older
model).

    python scripts/fingerprint.py > before.txt
    python scripts/fingerprint.py --compare before.txt
"""

from __future__ import annotations

import argparse
import hashlib
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np

import dgpt_gym  # noqa: F401  (registers the environments)
from dgpt_gym.benchmark.episodes import run_episode, run_episodes
from dgpt_gym.registry import make_tracker

CONFIGURATIONS = (
    ("S1", 1.0, {}),
    ("S3", 5.0, {}),
    ("S4", 5.0, {"trajectory": "random"}),
    ("S2", 1.0, {"clutter_sensors": "all"}),
    ("S2", 5.0, {"noise_std": 4.0}),
)
TRACKERS = ("dgpt-rbcm", "dgpt-bcm", "dgpt-gpoe", "dgpt-poe", "gp", "hybrid")
VECTOR_ENVS = ("DGPTrackSensors-v2", "DGPTrackSensors-v1", "DGPTrackWindow-v0", "DGPTrackGating-v0")


def episode_digest(result) -> bytes:
    """The SHA-256 of an episode's estimates, variances and UCBs."""
    digest = hashlib.sha256()
    for array in (result.mean, result.var, result.ucb):
        digest.update(np.ascontiguousarray(array, dtype=float).tobytes())
    return digest.digest()


def vector_env_digest(env_id: str, steps: int) -> bytes:
    """The SHA-256 of ``steps`` steps of 4 batched sub-environments under seeded random
    actions: rewards, errors and flattened observations."""
    envs = gym.make_vec(env_id, num_envs=4, vectorization_mode="vector_entry_point")
    envs.action_space.seed(0)
    envs.reset(seed=0)
    digest = hashlib.sha256()
    for _ in range(steps):
        observation, reward, _, _, info = envs.step(envs.action_space.sample())
        if isinstance(observation, dict):
            observation = np.concatenate([np.ravel(value) for value in observation.values()])
        digest.update(np.asarray(reward, dtype=float).tobytes())
        digest.update(np.asarray(info["error"], dtype=float).tobytes())
        digest.update(np.ascontiguousarray(observation).tobytes())
    envs.close()
    return digest.digest()


def moved_lines(before: str, after: str) -> list[str]:
    """The labels of the lines of ``after`` (this script's output) whose digest differs from
    the line of the same label in ``before``, or that ``before`` lacks, in ``after``'s
    order."""

    def digests(text: str) -> dict[str, str]:
        return dict(line.rsplit(" ", 1) for line in text.splitlines() if " " in line.strip())

    old = digests(before)
    return [label for label, digest in digests(after).items() if old.get(label) != digest]


def main(argv=None) -> str:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer episodes, a different hash")
    parser.add_argument(
        "--compare",
        type=Path,
        metavar="FILE",
        help="a previous run's output: list the lines whose digest moved",
    )
    args = parser.parse_args(argv)
    if args.compare is not None and not args.compare.is_file():
        parser.error(f"--compare: no such file {str(args.compare)!r}")
    printed: list[str] = []
    seeds = list(range(2 if args.quick else 3))
    total = hashlib.sha256()

    def add(label: str, digest: bytes) -> None:
        total.update(digest)
        printed.append(f"{label} {digest.hex()[:12]}")
        print(printed[-1], flush=True)

    for scenario, clutter_rate, kwargs in CONFIGURATIONS:
        env = gym.make("DGPTrack-v0", scenario=scenario, clutter_rate=clutter_rate, **kwargs)
        label = f"{scenario} clutter {clutter_rate:g} {kwargs or ''}"
        for tracker_id in TRACKERS:
            for seed in seeds:
                result = run_episode(env, make_tracker(tracker_id), seed)
                add(f"{label} {tracker_id} seed {seed}", episode_digest(result))
        if args.quick:
            continue
        envs = [
            gym.make("DGPTrack-v0", scenario=scenario, clutter_rate=clutter_rate, **kwargs)
            for _ in seeds
        ]
        trackers = [make_tracker("dgpt-rbcm") for _ in seeds]  # one class: update_batch
        for seed, result in zip(seeds, run_episodes(envs, trackers, seeds)):
            add(f"{label} lockstep block, seed {seed}", episode_digest(result))
    for env_id in VECTOR_ENVS:
        add(env_id, vector_env_digest(env_id, 60 if args.quick else 150))
    printed.append(f"ALL {total.hexdigest()}")
    print(printed[-1])
    if args.compare is not None:
        moved = moved_lines(args.compare.read_text(), "\n".join(printed))
        print(f"moved against {args.compare}: {len(moved)} of {len(printed)} lines")
        for label in moved:
            print("  moved:", label)
    return total.hexdigest()


if __name__ == "__main__":
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the retired v1 environment's deprecation warning
        main()
