#!/usr/bin/env python
"""Benchmarks of dgpt-gym; prints ratios taken in one run (see docs/performance.md).

env: step cost of ``DGPTrack-v0`` versus ``CartPole-v1``, both through ``gymnasium.make``
(so both carry Gymnasium's default wrappers), resets included as episodes end. Goal <= 3.
"""

from __future__ import annotations

import argparse
import platform
import time

import gymnasium as gym
import numpy as np

import dgpt_gym


def step_cost(env: gym.Env, action, n_steps: int, seed: int = 0) -> float:
    """Seconds per ``env.step`` over ``n_steps`` steps, resetting when an episode ends."""
    env.reset(seed=seed)
    started = time.perf_counter()
    for _ in range(n_steps):
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return (time.perf_counter() - started) / n_steps


def bench_env(n_steps: int, repeats: int, env_kwargs: dict) -> dict:
    """Interleaved repeats of both envs; the minimum per env is the least disturbed run."""
    ours = gym.make("DGPTrack-v0", **env_kwargs)
    cartpole = gym.make("CartPole-v1")
    ours_times, cartpole_times = [], []
    for repeat in range(repeats):
        ours_times.append(step_cost(ours, np.array([500.0, 500.0]), n_steps, seed=repeat))
        cartpole_times.append(step_cost(cartpole, 0, n_steps, seed=repeat))
    ours_best, cartpole_best = min(ours_times), min(cartpole_times)
    return {
        "DGPTrack-v0 step (us)": 1e6 * ours_best,
        "CartPole-v1 step (us)": 1e6 * cartpole_best,
        "ratio DGPTrack / CartPole (goal <= 3)": ours_best / cartpole_best,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20000, help="env steps per repeat")
    parser.add_argument("--repeats", type=int, default=5, help="interleaved repeats")
    parser.add_argument("--scenario", default="S2")
    parser.add_argument("--clutter-rate", type=float, default=5.0)
    args = parser.parse_args(argv)
    print(
        f"dgpt-gym {dgpt_gym.__version__}, Python {platform.python_version()}, "
        f"numpy {np.__version__}, gymnasium {gym.__version__}, {platform.machine()}"
    )
    env_kwargs = {"scenario": args.scenario, "clutter_rate": args.clutter_rate}
    print(f"\n## env step cost ({env_kwargs}, {args.steps} steps x {args.repeats} repeats)")
    for key, value in bench_env(args.steps, args.repeats, env_kwargs).items():
        print(f"{key}: {value:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
