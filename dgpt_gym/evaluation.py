"""The evaluation loop: one episode of a tracker in an environment, and Monte Carlo runs.

``run_episode`` feeds each observation to ``tracker.update`` and steps the environment with
the estimate; the truth comes from ``info`` and never reaches the tracker.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from tqdm.auto import tqdm

from dgpt_gym import metrics

__all__ = ["EpisodeResult", "run_episode", "run_monte_carlo", "summarize_runs"]


@dataclass(frozen=True)
class EpisodeResult:
    """Per-step record of one episode; arrays have n_steps rows.

    ``ucb`` is NaN where the tracker gives no upper confidence bound.
    """

    truth: np.ndarray
    mean: np.ndarray
    var: np.ndarray
    ucb: np.ndarray
    step_time: np.ndarray
    n_measurements: np.ndarray
    n_detecting: np.ndarray

    def metrics(self) -> dict[str, float]:
        """The episode's metrics (module :mod:`dgpt_gym.metrics`), flattened per axis."""
        std = np.sqrt(np.maximum(self.var, 0.0))
        ci = metrics.CI_SIGMAS * std
        values = {
            "nrmse": metrics.nrmse(self.mean, self.truth),
            "rmse": metrics.rmse(self.mean, self.truth),
            "ci_coverage": metrics.coverage(self.mean, self.truth, ci),
            "ci_width": metrics.mean_width(ci),
            "ucb_coverage": metrics.coverage(self.mean, self.truth, self.ucb),
            "ucb_width": metrics.mean_width(self.ucb),
        }
        flat = {
            f"{key}_{axis}": float(value[i])
            for key, value in values.items()
            for i, axis in enumerate("xy")
        }
        has_ucb = bool(np.all(np.isfinite(self.ucb)))
        if not has_ucb:
            for key in ("ucb_coverage_x", "ucb_coverage_y", "ucb_width_x", "ucb_width_y"):
                flat[key] = float("nan")
        flat["step_time_ms"] = float(1e3 * np.median(self.step_time))
        flat["no_detection_fraction"] = float(np.mean(self.n_detecting == 0))
        return flat


def run_episode(env: gym.Env, tracker, seed: int | None) -> EpisodeResult:
    """Run ``tracker`` (a :class:`agents.base.Tracker`) for one episode of ``env``.

    The tracker is reset with the ``ProblemSpec`` from the env's reset info and the same
    seed, so the result is a function of ``seed``.
    """
    observation, info = env.reset(seed=seed)
    tracker.reset(info["problem_spec"], seed=seed)
    truth, mean, var, ucb, step_time, n_measurements, n_detecting = ([] for _ in range(7))
    truncated = terminated = False
    while not (truncated or terminated):
        started = time.perf_counter()
        estimate = tracker.update(observation)
        step_time.append(time.perf_counter() - started)
        mean.append(estimate.mean)
        var.append(estimate.var)
        ucb.append(np.full(2, np.nan) if estimate.ucb is None else estimate.ucb)
        n_measurements.append(int(np.sum(observation["mask"])))
        observation, _, terminated, truncated, info = env.step(estimate.mean)
        truth.append(info["position"])
        n_detecting.append(len(info["active_sensors"]))
    return EpisodeResult(
        truth=np.asarray(truth),
        mean=np.asarray(mean, dtype=float),
        var=np.asarray(var, dtype=float),
        ucb=np.asarray(ucb, dtype=float),
        step_time=np.asarray(step_time),
        n_measurements=np.asarray(n_measurements),
        n_detecting=np.asarray(n_detecting),
    )


def run_monte_carlo(
    make_env: Callable[[], gym.Env],
    make_tracker: Callable[[], object],
    seeds: Iterable[int],
    progress: bool = True,
    description: str | None = None,
) -> list[dict[str, float]]:
    """Per-run metrics of a tracker over Monte Carlo seeds (one fresh env and tracker).

    Returns one dict per seed: ``seed`` and :meth:`EpisodeResult.metrics`.
    """
    seeds = list(seeds)
    env, tracker = make_env(), make_tracker()
    rows = []
    try:
        for seed in tqdm(seeds, desc=description, disable=not progress, leave=False):
            result = run_episode(env, tracker, seed)
            rows.append({"seed": seed, **result.metrics()})
    finally:
        env.close()
    return rows


def summarize_runs(rows: list[dict[str, float]]) -> dict[str, float]:
    """Mean of every metric over runs, and the STD of the RMSE over runs (``rmse_std_*``)."""
    keys = [key for key in rows[0] if key != "seed"]
    with warnings.catch_warnings():  # a metric NaN in every run (no UCB) stays NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        summary = {key: float(np.nanmean([row[key] for row in rows])) for key in keys}
    rmse_runs = np.array([[row["rmse_x"], row["rmse_y"]] for row in rows])
    summary["rmse_std_x"], summary["rmse_std_y"] = map(float, metrics.std_over_runs(rmse_runs))
    summary["n_runs"] = len(rows)
    return summary


def format_nrmse_table(rows: list[dict]) -> str:
    """Markdown table of mean NRMSE (percent) per cell and axis, the paper's unit."""
    header = "| tracker | scenario | noise_std | clutter_rate | NRMSE X % | NRMSE Y % | runs |"
    lines = [header, "|---|---|---|---|---|---|---|"]
    for row in rows:
        lines.append(
            f"| {row['tracker']} | {row['scenario']} | {row['noise_std']:g} | "
            f"{row['clutter_rate']:g} | {100 * row['nrmse_x']:.2f} | {100 * row['nrmse_y']:.2f} | "
            f"{row['n_runs']} |"
        )
    return "\n".join(lines)
