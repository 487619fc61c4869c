"""What trained DGPTrackSensors-v1 agents choose, by situation, on held-out seeds.

Each agent folder (``scripts/train_rl.py`` output) is loaded with its frozen normaliser and
run on the evaluation seeds; its actions (sensors woken) are tabulated by what the
observation says: the prediction's larger standard deviation (below 10 m, 10-30 m, above
30 m) while sensors report, and the steps after a step without any report.

    python scripts/sensors_agent_actions.py models/sensors-v1-ppo-seed*
"""

from __future__ import annotations

import argparse
import collections
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import gymnasium as gym  # noqa: E402

import dgpt_gym  # noqa: E402, F401  (registers the environments)
from agents.rl.evaluation import ModelPolicy  # noqa: E402
from agents.rl.sensors_v1 import OBSERVED_CANDIDATES, WAKE_COUNTS  # noqa: E402
from agents.rl.training import load_agent  # noqa: E402

SITUATIONS = ("sigma < 10 m", "sigma 10-30 m", "sigma > 30 m", "after a silent step")


def situation(observation: np.ndarray) -> str:
    tail = observation[3 * OBSERVED_CANDIDATES :]
    if round(float(tail[5]) * 10) >= 1:
        return SITUATIONS[3]
    sigma = float(np.max(np.expm1(6.0 * tail[0:2])))
    return SITUATIONS[0] if sigma < 10 else SITUATIONS[1] if sigma < 30 else SITUATIONS[2]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="+", type=Path)
    parser.add_argument("--seeds", type=int, default=20, help="evaluation seeds 0..N-1")
    args = parser.parse_args(argv)
    counts = collections.defaultdict(collections.Counter)
    for folder in args.models:
        model, config = load_agent(folder)
        policy = ModelPolicy(model, config["normalizer"])
        env = gym.make(config["env"], **config["env_kwargs"])
        for seed in range(args.seeds):
            observation, _ = env.reset(seed=seed)
            done = False
            while not done:
                action = int(policy.predict(observation))
                woken = WAKE_COUNTS[action]
                counts[situation(observation)]["all" if woken is None else woken] += 1
                observation, _, terminated, truncated, _ = env.step(action)
                done = terminated or truncated
    print(f"{len(args.models)} agents, seeds 0-{args.seeds - 1}: share of steps per choice\n")
    print("| situation | steps | most frequent choices (sensors woken: share) |")
    print("|---|---|---|")
    for name in SITUATIONS:
        total = sum(counts[name].values())
        top = counts[name].most_common(5)
        shares = ", ".join(f"{key}: {100 * value / total:.0f} %" for key, value in top)
        print(f"| {name} | {total} | {shares} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
