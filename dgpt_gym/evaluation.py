"""The evaluation loop: one episode of a tracker in an environment, and Monte Carlo runs.

``run_episode`` feeds each observation to ``tracker.update`` and steps the environment with
the estimate; the truth comes from ``info`` and never reaches the tracker.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np
from tqdm.auto import tqdm

from dgpt_gym import metrics

__all__ = ["EpisodeResult", "run_episode", "run_episodes", "run_monte_carlo", "summarize_runs"]


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
    return run_episodes([env], [tracker], [seed])[0]


def run_episodes(
    envs: Sequence[gym.Env], trackers: Sequence, seeds: Sequence[int | None]
) -> list[EpisodeResult]:
    """Run episode i of ``envs[i]`` with ``trackers[i]`` and ``seeds[i]``, all in lockstep.

    Each step, the trackers of the episodes still running take their observations in one
    call of ``update_batch`` when their class has one (:meth:`agents.base.TrackerBase.update_batch`;
    DGPT batches its learning and prediction over the episodes), else one ``update`` each.
    The results equal those of :func:`run_episode` on each episode alone; ``step_time`` is
    the batch's time per step divided by the number of episodes it stepped.
    """
    if not len(envs) == len(trackers) == len(seeds):
        raise ValueError(
            "envs, trackers and seeds must have the same length; got "
            f"{len(envs)}, {len(trackers)} and {len(seeds)}"
        )
    observations = []
    for env, tracker, seed in zip(envs, trackers, seeds):
        observation, info = env.reset(seed=seed)
        tracker.reset(info["problem_spec"], seed=seed)
        observations.append(observation)
    update_batch = getattr(type(trackers[0]), "update_batch", None) if trackers else None
    if update_batch is None or any(type(tracker) is not type(trackers[0]) for tracker in trackers):
        update_batch = _update_each
    records = [_EpisodeRecord() for _ in envs]
    running = list(range(len(envs)))
    while running:
        started = time.perf_counter()
        estimates = update_batch([trackers[i] for i in running], [observations[i] for i in running])
        elapsed = (time.perf_counter() - started) / len(running)
        still_running = []
        for index, estimate in zip(running, estimates):
            record, observation = records[index], observations[index]
            record.step_time.append(elapsed)
            record.mean.append(estimate.mean)
            record.var.append(estimate.var)
            record.ucb.append(np.full(2, np.nan) if estimate.ucb is None else estimate.ucb)
            record.n_measurements.append(int(np.sum(observation["mask"])))
            observation, _, terminated, truncated, info = envs[index].step(estimate.mean)
            observations[index] = observation
            record.truth.append(info["position"])
            record.n_detecting.append(len(info["active_sensors"]))
            if not (terminated or truncated):
                still_running.append(index)
        running = still_running
    return [record.result() for record in records]


def _update_each(trackers, observations):
    return [tracker.update(observation) for tracker, observation in zip(trackers, observations)]


@dataclass
class _EpisodeRecord:
    """The per-step lists of one episode while it runs."""

    truth: list = field(default_factory=list)
    mean: list = field(default_factory=list)
    var: list = field(default_factory=list)
    ucb: list = field(default_factory=list)
    step_time: list = field(default_factory=list)
    n_measurements: list = field(default_factory=list)
    n_detecting: list = field(default_factory=list)

    def result(self) -> EpisodeResult:
        return EpisodeResult(
            truth=np.asarray(self.truth),
            mean=np.asarray(self.mean, dtype=float),
            var=np.asarray(self.var, dtype=float),
            ucb=np.asarray(self.ucb, dtype=float),
            step_time=np.asarray(self.step_time),
            n_measurements=np.asarray(self.n_measurements),
            n_detecting=np.asarray(self.n_detecting),
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
