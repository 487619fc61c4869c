"""What trained agents choose, by situation, on held-out seeds.

Each agent folder (``scripts/train_rl.py`` output) is loaded with its frozen normaliser and
run on the evaluation seeds of the environment it was trained on; what it set each step
(the environment's knob: window C, gate threshold or sensors woken) is tabulated by what the
observation says:

- ``DGPTrackSensors-v1`` / ``-v2``: the prediction's larger standard deviation (below 10 m,
  10-30 m, above 30 m) while sensors report, and the steps after a step without any report;
- ``DGPTrackWindow-v0`` / ``DGPTrackGating-v0``: after a step without measurements; a
  surprise (the gated summaries lie more than 10 m, a fifth of the sensing range, from
  their predictions on average); otherwise 1-2 experts or 3 and more.

With ``--clairvoyant SETTING`` a second table does the same for the greedy clairvoyant
policy of :mod:`agents.rl.clairvoyant` (it tries every fixed setting each step and keeps
the one that scores best, ``SETTING`` where several tie): what adapting with hindsight of
each step's error would choose.

    python scripts/agent_actions.py models/sensors-v1-ppo-seed*
    python scripts/agent_actions.py --clairvoyant "fixed C=3" models/window-ppo-seed*
"""

from __future__ import annotations

import argparse
import collections
import sys
from functools import partial
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import gymnasium as gym  # noqa: E402

import dgpt_gym  # noqa: E402, F401  (registers the environments)
from agents.rl.clairvoyant import GreedyClairvoyantPolicy  # noqa: E402
from agents.rl.evaluation import ModelPolicy  # noqa: E402
from agents.rl.features import decode_features  # noqa: E402
from agents.rl.sensors_v1 import DGPTrackSensorsV1Env, decode_observation  # noqa: E402
from agents.rl.training import load_agent  # noqa: E402

SENSOR_SITUATIONS = ("sigma < 10 m", "sigma 10-30 m", "sigma > 30 m", "after a silent step")
TUNING_SITUATIONS = (
    "1-2 experts",
    "3+ experts",
    "surprise (innovation > 10 m)",
    "after a silent step",
)


def sensor_situation(observation: np.ndarray) -> str:
    seen = decode_observation(observation)
    if seen.silent_steps >= 1:
        return SENSOR_SITUATIONS[3]
    return (
        SENSOR_SITUATIONS[0]
        if seen.sigma < 10
        else SENSOR_SITUATIONS[1]
        if seen.sigma < 30
        else SENSOR_SITUATIONS[2]
    )


def tuning_situation(observation: np.ndarray, sensing_range: float) -> str:
    """The situation of a tuning task's step; the innovation is observed in sensing ranges."""
    seen = decode_features(observation)
    if seen.silent_steps >= 1:
        return TUNING_SITUATIONS[3]
    if seen.innovation * sensing_range > 10.0:
        return TUNING_SITUATIONS[2]
    return TUNING_SITUATIONS[0] if seen.n_experts <= 2 else TUNING_SITUATIONS[1]


def tally(env: gym.Env, policy, seeds: range, counts: dict) -> tuple[str, ...]:
    """Add to ``counts`` (situation -> Counter of knob values) what ``policy`` sets on every
    step of ``seeds``; returns the environment's situations in table order."""
    sensors = isinstance(env.unwrapped, DGPTrackSensorsV1Env)
    sensing_range = env.unwrapped.inner.sensing_range
    classify = (
        sensor_situation if sensors else partial(tuning_situation, sensing_range=sensing_range)
    )
    for seed in seeds:
        observation, _ = env.reset(seed=seed)
        done = False
        while not done:
            name = classify(observation)
            observation, _, terminated, truncated, info = env.step(policy.predict(observation))
            counts[name][round(float(info[env.unwrapped.knob]), 1)] += 1
            done = terminated or truncated
    return SENSOR_SITUATIONS if sensors else TUNING_SITUATIONS


def print_table(title: str, knob: str, situations: tuple[str, ...], counts: dict) -> None:
    print(f"{title}: {knob} per step, by situation\n")
    print(f"| situation | steps | mean {knob} | most frequent values (share) |")
    print("|---|---|---|---|")
    for name in situations:
        total = sum(counts[name].values())
        if not total:
            continue
        mean = sum(value * n for value, n in counts[name].items()) / total
        shares = ", ".join(
            f"{value:g}: {100 * n / total:.0f} %" for value, n in counts[name].most_common(4)
        )
        print(f"| {name} | {total} | {mean:.2f} | {shares} |")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="+", type=Path)
    parser.add_argument("--seeds", type=int, default=20, help="evaluation seeds 0..N-1")
    parser.add_argument(
        "--clairvoyant",
        metavar="SETTING",
        help="also tabulate the greedy clairvoyant policy in the agents' environment, keeping "
        "this fixed setting (a name of the environment's fixed_actions(), e.g. 'fixed C=3') "
        "where several tie",
    )
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error(f"--seeds must be >= 1; got {args.seeds}")
    seeds = range(args.seeds)
    counts = collections.defaultdict(collections.Counter)
    configs = {}
    first = load_agent(args.models[0])[1]
    if args.clairvoyant is not None:
        settings = gym.make(first["env"], **first["env_kwargs"]).unwrapped.fixed_actions()[0]
        if args.clairvoyant not in settings:
            parser.error(f"--clairvoyant must be one of {list(settings)}; got {args.clairvoyant!r}")
    for folder in args.models:
        model, config = load_agent(folder)
        configs[(config["env"], repr(sorted(config["env_kwargs"].items())))] = config
        env = gym.make(config["env"], **config["env_kwargs"])
        situations = tally(env, ModelPolicy(model, config["normalizer"]), seeds, counts)
    if len(configs) != 1:
        parser.error(f"the agents must share one environment; got {sorted(configs)}")
    config = next(iter(configs.values()))
    env = gym.make(config["env"], **config["env_kwargs"])
    knob = env.unwrapped.knob
    print_table(f"{len(args.models)} agent(s), seeds 0-{args.seeds - 1}", knob, situations, counts)
    if args.clairvoyant is not None:
        settings, _ = env.unwrapped.fixed_actions()
        policy = GreedyClairvoyantPolicy(env, prefer=settings[args.clairvoyant])
        counts = collections.defaultdict(collections.Counter)
        tally(env, policy, seeds, counts)
        print()
        print_table(
            f"the greedy clairvoyant policy, seeds 0-{args.seeds - 1}", knob, situations, counts
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
