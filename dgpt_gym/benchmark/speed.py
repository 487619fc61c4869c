"""``dgpt-bench`` (also ``python scripts/bench.py``), the speed benchmarks of dgpt-gym; prints ratios taken in one run (see docs/performance.md).

- env: step cost of ``DGPTrack-v0`` versus ``CartPole-v1``, both through ``gymnasium.make``
  (so both carry Gymnasium's default wrappers), resets included as episodes end. Goal <= 3.
- dgpt-step: median time of one DGPT-RBCM update, the default (the state-space NCV GP,
  learning window 4) and the pooled SE trend's (TGP, window 10), both axes, steps with 2-3
  reporting sensors, warm-started learning. Goal <= 1 ms.
- cpf: median CPF step with 2000 particles and ~10 measurements (S3, clutter rate 5). Goal
  <= 1 ms.
- standard: median step of the KF-PDA (``pda``, goal <= 0.2 ms), the IMM-PDA (``imm-pda``,
  goal <= 0.5 ms) and the clairvoyant floor, one episode at a time (S3, clutter rate 5).
- hybrid: median hybrid-filter step (``hybrid``, ``hybrid-trend``, ``hybrid-paper``) over the
  median step of the DGPT it wraps, on the same episodes. Goal: at most 10 % over.
- sklearn: full-GP log marginal likelihood + gradient versus scikit-learn's
  ``GaussianProcessRegressor.log_marginal_likelihood(theta, eval_gradient=True)`` on the same
  data and kernel, N = 1000, 2000, 4000. Goal: ratio <= 1.
- clutter-all: median step (ms) of the GP trackers (``dgpt-rbcm``, ``gp``, ``dgpt-gpoe``,
  ``hybrid``) with clutter at every sensor (``clutter_sensors="all"``, clutter rate 1), one
  episode at a time, in each scenario on its reference path and on random paths. Goal
  <= 3 ms in every cell for the GP trackers (issue 12); the KF-PDA, IMM-PDA and CPF beside
  them.
- lockstep: seconds per episode of the GP trackers run one episode at a time
  (``run_episode``) and in a lockstep block (``run_episodes``, the sweep's way), on the same
  seeds, checking that the numbers are identical; the ratio is the sweep's speed-up.
- vector-env: steps per second of every RL environment with 8 sub-environments, Gymnasium's
  sync vector env against the batched one (``vectorization_mode="vector_entry_point"``, the
  trackers stepped through one ``update_batch``), checking the returns are equal. Goal >= 5.
- training-time: the paper's Sec. VII-A experiment (Fig. 2): f(x) = 5 x1^2 + sin(12 x2),
  sigma_z = 0.5; likelihood + gradient of the full GP and of DGP with M = 2, 5, 10, 20
  experts, N = 500 .. 10000; writes docs/training_time.csv and docs/figures/training_time.png.
"""

from __future__ import annotations

import argparse
import csv
import platform
import time
from functools import partial
from pathlib import Path

import gymnasium as gym
import numpy as np

import dgpt_gym
from agents import gp
from dgpt_gym.benchmark.episodes import run_episode, run_episodes
from dgpt_gym.benchmark.plots import plot_training_time
from dgpt_gym.registry import load_table, make_tracker

DOCS = Path("docs")
SECTIONS = [
    "env",
    "dgpt-step",
    "cpf-hybrid",
    "standard",
    "ncv-step",
    "clutter-all",
    "lockstep",
    "vector-env",
    "sklearn",
    "training-time",
]


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


def bench_dgpt_step(episodes: int) -> dict:
    """Median update time over steps with 2-3 reporting sensors (S1, clutter rate 1): the
    default DGPT-RBCM (the NCV GP in state-space form, learning window 4) and the pooled SE
    trend's (TGP, window 10)."""
    env = gym.make("DGPTrack-v0", scenario="S1", clutter_rate=1.0)
    results = {}
    for tracker_id, kwargs in (("dgpt-rbcm", {}), ("dgpt-rbcm-trend", {"window": 10})):
        times = []
        for seed in range(episodes):
            tracker = make_tracker(tracker_id, **kwargs)
            observation, info = env.reset(seed=seed)
            tracker.reset(info["problem_spec"])
            truncated = False
            while not truncated:
                reporting = np.unique(observation["sensor"][observation["mask"].astype(bool)])
                started = time.perf_counter()
                estimate = tracker.update(observation)
                elapsed = time.perf_counter() - started
                if 2 <= reporting.size <= 3:
                    times.append(elapsed)
                observation, _, _, truncated, _ = env.step(estimate.mean)
        label = tracker_id + (f" (window {kwargs['window']})" if kwargs else "")
        results[f"{label} step, median (ms, goal <= 1)"] = 1e3 * float(np.median(times))
        results[f"{tracker_id} step, 90th percentile (ms)"] = 1e3 * float(np.percentile(times, 90))
        results[f"{tracker_id}: steps measured"] = len(times)
    return results


def median_step_ms(
    tracker_id: str,
    episodes: int,
    scenario: str = "S3",
    env_kwargs: dict | None = None,
    **kwargs,
) -> float:
    """Median ``update`` time of a registered tracker (made with ``kwargs``) over episodes
    (seeds 0, 1, ...) of ``scenario`` at clutter rate 5, or with ``env_kwargs`` instead."""
    env = gym.make("DGPTrack-v0", scenario=scenario, **(env_kwargs or {"clutter_rate": 5.0}))
    times = []
    for seed in range(episodes):
        times.extend(run_episode(env, make_tracker(tracker_id, **kwargs), seed).step_time)
    return 1e3 * float(np.median(times))


def bench_cpf_and_hybrid(episodes: int) -> dict:
    env = gym.make("DGPTrack-v0", scenario="S3", clutter_rate=5.0)
    counts = [
        run_episode(env, make_tracker("centroid"), seed).n_measurements for seed in range(episodes)
    ]
    results = {
        "measurements per step, median": float(np.median(np.concatenate(counts))),
        "CPF step, 2000 particles, median (ms, goal <= 1)": median_step_ms("cpf", episodes),
    }
    for dgpt_id, hybrids, kwargs in (
        ("dgpt-rbcm", ("hybrid",), {}),
        ("dgpt-rbcm-trend", ("hybrid-trend", "hybrid-paper"), {"window": 3}),
    ):
        dgpt = median_step_ms(dgpt_id, episodes, **kwargs)
        for variant in hybrids:
            hybrid = median_step_ms(variant, episodes, **kwargs)
            results[f"{variant} / {dgpt_id} step (goal <= 1.10)"] = hybrid / dgpt
        results[f"{dgpt_id} step, median (ms)"] = dgpt
    return results


def bench_standard(episodes: int) -> dict:
    """Median steps of the standard trackers and the floor (S3, clutter rate 5)."""
    return {
        "KF-PDA step, median (ms, goal <= 0.2)": median_step_ms("pda", episodes),
        "IMM-PDA step, median (ms, goal <= 0.5)": median_step_ms("imm-pda", episodes),
        "clairvoyant step, median (ms)": median_step_ms("clairvoyant", episodes),
    }


def bench_ncv_step(episodes: int) -> dict:
    """Median steps of the default DGPT-RBCM (the state-space NCV GP) and of the pooled SE
    trend's (window 3) in one run, and their ratio (S3, clutter rate 5)."""
    ncv = median_step_ms("dgpt-rbcm", episodes)
    trend = median_step_ms("dgpt-rbcm-trend", episodes, window=3)
    return {
        "dgpt-rbcm step, median (ms)": ncv,
        "dgpt-rbcm-trend step, window 3, median (ms)": trend,
        "dgpt-rbcm / dgpt-rbcm-trend": ncv / trend,
    }


CLUTTER_ALL_TRACKERS = ("dgpt-rbcm", "gp", "dgpt-gpoe", "hybrid", "pda", "imm-pda", "cpf")


def bench_clutter_all(
    episodes: int,
    trackers: tuple[str, ...] = CLUTTER_ALL_TRACKERS,
    scenarios: tuple[str, ...] = ("S1", "S2", "S3", "S4"),
) -> list[str]:
    """Markdown rows: the median step (ms) of each of ``trackers`` over ``episodes``
    episodes (seeds 0, 1, ...) per cell, each of ``scenarios`` on its reference path and on
    random paths, clutter rate 1 at every sensor, one episode at a time."""
    cells = [(s, path) for s in scenarios for path in ("fixed", "random")]
    rows = [
        "| tracker | " + " | ".join(f"{s} {path}" for s, path in cells) + " |",
        "|---" * (len(cells) + 1) + "|",
    ]
    for tracker_id in trackers:
        medians = [
            median_step_ms(
                tracker_id,
                episodes,
                scenario,
                {"trajectory": path, "clutter_rate": 1.0, "clutter_sensors": "all"},
            )
            for scenario, path in cells
        ]
        rows.append(f"| `{tracker_id}` | " + " | ".join(f"{m:.2f}" for m in medians) + " |")
    return rows


def bench_lockstep(episodes: int) -> dict:
    """Seconds per episode alone and in one lockstep block of ``episodes`` (S3, sigma_z 2,
    clutter rate 5, window 3 for the SE trackers and the default for the state-space ones:
    a cell of the paper's grid), on the same seeds."""
    env_kwargs = {"scenario": "S3", "noise_std": 2.0, "clutter_rate": 5.0}
    seeds = list(range(episodes))
    results = {}
    for tracker_id, kwargs in (
        ("dgpt-rbcm-trend", {"window": 3}),
        ("dgpt-gpoe-stgp-trend", {"window": 3}),
        ("gp-trend", {"window": 3}),
        ("dgpt-rbcm", {}),
        ("gp", {}),
    ):
        env = gym.make("DGPTrack-v0", **env_kwargs)
        started = time.perf_counter()
        alone = [run_episode(env, make_tracker(tracker_id, **kwargs), seed) for seed in seeds]
        alone_time = (time.perf_counter() - started) / episodes
        envs = [gym.make("DGPTrack-v0", **env_kwargs) for _ in seeds]
        trackers = [make_tracker(tracker_id, **kwargs) for _ in seeds]
        started = time.perf_counter()
        together = run_episodes(envs, trackers, seeds)
        block_time = (time.perf_counter() - started) / episodes
        assert all(
            np.array_equal(a.mean, b.mean) and np.array_equal(a.var, b.var)
            for a, b in zip(alone, together)
        ), "a lockstep block changed the numbers"
        results[f"{tracker_id}: alone (s/episode) / block (s/episode) = speed-up"] = (
            f"{alone_time:.3f} / {block_time:.3f} = {alone_time / block_time:.1f}"
        )
    return results


def bench_vector_envs(num_envs: int, n_steps: int, env_ids: list[str]) -> dict:
    """Steps per second of ``num_envs`` sub-environments, Gymnasium's sync vector env against
    the batched one (``vectorization_mode="vector_entry_point"``), the same random actions
    and seeds, each timed after one warm-up step; the returns are checked to be equal."""
    results = {}
    for env_id in env_ids:
        rates, returns = {}, {}
        for mode in ("sync", "vector_entry_point"):
            envs = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode=mode)
            envs.action_space.seed(0)
            actions = [envs.action_space.sample() for _ in range(n_steps + 1)]
            envs.reset(seed=0)
            total = envs.step(actions[0])[1].sum()
            started = time.perf_counter()
            for action in actions[1:]:
                total += envs.step(action)[1].sum()
            rates[mode] = num_envs * n_steps / (time.perf_counter() - started)
            returns[mode] = total
            envs.close()
        assert returns["sync"] == returns["vector_entry_point"], (
            "the batched env changed the numbers"
        )
        results[f"{env_id}: sync / batched steps/s = speed-up"] = (
            f"{rates['sync']:.0f} / {rates['vector_entry_point']:.0f} = "
            f"{rates['vector_entry_point'] / rates['sync']:.2f}"
        )
    return results


def paper_function_data(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Sec. VII-A: x uniform in [0, 1]^2, z = 5 x1^2 + sin(12 x2) + N(0, 0.5^2)."""
    x = rng.uniform(size=(n, 2))
    return x, 5 * x[:, 0] ** 2 + np.sin(12 * x[:, 1]) + 0.5 * rng.normal(size=n)


def best_time(function, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        function()
        times.append(time.perf_counter() - started)
    return min(times)


def bench_sklearn(sizes: list[int], repeats: int) -> dict:
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

    rng = np.random.default_rng(0)
    results = {}
    for n in sizes:
        x, z = paper_function_data(n, rng)
        kernel = ConstantKernel(1.0) * RBF([0.3, 0.3]) + WhiteKernel(0.25)
        model = GaussianProcessRegressor(kernel, alpha=0.0, optimizer=None).fit(x, z)
        theta = model.kernel_.theta  # log constant, log length scales, log noise: our order
        ours_value, _ = gp.log_marginal_likelihood(theta[None], x[None, None], z[None, None])
        theirs_value, _ = model.log_marginal_likelihood(theta, eval_gradient=True)
        assert abs(ours_value[0] - theirs_value) <= 1e-6 * abs(theirs_value), (
            "implementations disagree"
        )
        ours = best_time(
            partial(gp.log_marginal_likelihood, theta[None], x[None, None], z[None, None]), repeats
        )
        theirs = best_time(
            partial(model.log_marginal_likelihood, theta, eval_gradient=True), repeats
        )
        results[f"N={n}: ours (s) / scikit-learn (s) = ratio (goal <= 1)"] = (
            f"{ours:.3f} / {theirs:.3f} = {ours / theirs:.2f}"
        )
    return results


def bench_training_time(
    sizes: list[int], experts: list[int], repeats: int, full_gp_max: int
) -> list[dict]:
    """Time of the (factorized) log marginal likelihood and gradient; one row per (N, M)."""
    rng = np.random.default_rng(1)
    log_params = np.log([[1.0, 0.3, 0.3, 0.25]])
    rows = []
    for n in sizes:
        x, z = paper_function_data(n, rng)
        for m in [1, *experts]:
            if m == 1 and n > full_gp_max:
                continue
            size = n // m
            X = x[: m * size].reshape(1, m, size, 2)
            Z = z[: m * size].reshape(1, m, size)
            seconds = best_time(partial(gp.log_marginal_likelihood, log_params, X, Z), repeats)
            rows.append({"N": n, "M": m, "seconds": seconds})
    return rows


def write_training_time(rows: list[dict]) -> None:
    with (DOCS / "training_time.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=["N", "M", "seconds"])
        writer.writeheader()
        writer.writerows(rows)
    plot_training_time(rows, DOCS / "figures" / "training_time.png")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--only",
        nargs="+",
        default=SECTIONS,
        choices=SECTIONS,
        help="sections to run",
    )
    parser.add_argument("--steps", type=int, default=20000, help="env steps per repeat")
    parser.add_argument("--repeats", type=int, default=5, help="interleaved repeats")
    parser.add_argument("--scenario", default="S2")
    parser.add_argument("--clutter-rate", type=float, default=5.0)
    parser.add_argument(
        "--episodes", type=int, default=10, help="episodes of the DGPT step benchmark"
    )
    parser.add_argument(
        "--clutter-all-episodes",
        type=int,
        default=3,
        help="episodes per cell of the clutter-all section",
    )
    parser.add_argument(
        "--vector-steps", type=int, default=300, help="vector steps of the vector-env section"
    )
    parser.add_argument(
        "--full-gp-max", type=int, default=10000, help="largest N of the full GP in training-time"
    )
    args = parser.parse_args(argv)
    print(
        f"dgpt-gym {dgpt_gym.__version__}, Python {platform.python_version()}, "
        f"numpy {np.__version__}, gymnasium {gym.__version__}, {platform.machine()}"
    )
    if "env" in args.only:
        env_kwargs = {"scenario": args.scenario, "clutter_rate": args.clutter_rate}
        print(f"\n## env step cost ({env_kwargs}, {args.steps} steps x {args.repeats} repeats)")
        for key, value in bench_env(args.steps, args.repeats, env_kwargs).items():
            print(f"{key}: {value:.2f}")
    if "dgpt-step" in args.only:
        print(f"\n## DGPT-RBCM step (2-3 reporting sensors, {args.episodes} episodes of S1)")
        for key, value in bench_dgpt_step(args.episodes).items():
            print(f"{key}: {value:.3f}" if isinstance(value, float) else f"{key}: {value}")
    if "cpf-hybrid" in args.only:
        print(f"\n## CPF and hybrid filter steps ({args.episodes} episodes of S3, clutter rate 5)")
        for key, value in bench_cpf_and_hybrid(args.episodes).items():
            print(f"{key}: {value:.3f}")
    if "standard" in args.only:
        print(f"\n## standard trackers ({args.episodes} episodes of S3, clutter rate 5)")
        for key, value in bench_standard(args.episodes).items():
            print(f"{key}: {value:.3f}")
    if "ncv-step" in args.only:
        print(
            f"\n## default against pooled-trend DGPT-RBCM step ({args.episodes} episodes of S3, clutter rate 5)"
        )
        for key, value in bench_ncv_step(args.episodes).items():
            print(f"{key}: {value:.3f}")
    if "clutter-all" in args.only:
        print(
            "\n## median step (ms) with clutter at every sensor, clutter rate 1, goal <= 3 for "
            f"the GP trackers ({args.clutter_all_episodes} episodes per cell, one at a time)"
        )
        print("\n".join(bench_clutter_all(args.clutter_all_episodes)))
    if "lockstep" in args.only:
        blocks = args.episodes * 5
        print(
            f"\n## lockstep blocks of {blocks} episodes (S3, sigma_z 2, clutter rate 5, window 3; the state-space trackers their default)"
        )
        for key, value in bench_lockstep(blocks).items():
            print(f"{key}: {value}")
    if "vector-env" in args.only:
        env_ids = [environment.id for environment in load_table(dgpt_gym.RL_ENVIRONMENT_TABLE)]
        print(f"\n## RL vector environments, 8 sub-environments, {args.vector_steps} steps")
        for key, value in bench_vector_envs(8, args.vector_steps, env_ids).items():
            print(f"{key}: {value}")
    if "sklearn" in args.only:
        print("\n## full-GP log marginal likelihood + gradient versus scikit-learn")
        for key, value in bench_sklearn([1000, 2000, 4000], repeats=3).items():
            print(f"{key}")
            print(f"  {value}")
    if "training-time" in args.only:
        print("\n## training time (paper Sec. VII-A): seconds per likelihood + gradient")
        sizes, experts = [500, 1000, 2000, 5000, 10000], [2, 5, 10, 20]
        rows = bench_training_time(sizes, experts, repeats=2, full_gp_max=args.full_gp_max)
        write_training_time(rows)
        header = (
            "| N | full GP | " + " | ".join(f"M = {m}" for m in experts) + " | speed-up M = 20 |"
        )
        print(header)
        print("|---" * (len(experts) + 3) + "|")
        for n in sizes:
            by_m = {row["M"]: row["seconds"] for row in rows if row["N"] == n}
            cells = [f"{by_m[1]:.4f}" if 1 in by_m else "-"] + [f"{by_m[m]:.4f}" for m in experts]
            speedup = f"{by_m[1] / by_m[20]:.0f}x" if 1 in by_m else "-"
            print(f"| {n} | " + " | ".join(cells) + f" | {speedup} |")
        print("wrote docs/training_time.csv and docs/figures/training_time.png")
    return 0
