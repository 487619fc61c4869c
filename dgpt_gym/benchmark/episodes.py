"""The evaluation loop: one episode of a tracker in an environment, and Monte Carlo runs.

``run_episode`` feeds each observation to ``tracker.update`` and steps the environment with
the estimate; the truth comes from ``info`` and never reaches the tracker, unless the
tracker declares itself an oracle (:func:`is_oracle`).

Oracles. A tracker whose class sets ``oracle = True`` (the clairvoyant accuracy floor,
:class:`baselines.clairvoyant.ClairvoyantFilter`) is reset with ``reset(spec, seed=seed,
truth=info)`` and stepped with ``update(obs, truth=info)``, ``info`` being the environment's
info returned with ``obs`` (its ``target_origin`` rows and manoeuvre, see
:class:`dgpt_gym.env.DGPTrackEnv`). Every other tracker is called as ``reset(spec, seed)``
and ``update(obs)`` and never receives ``info``.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np
from scipy import stats
from tqdm.auto import tqdm

from dgpt_gym.benchmark import metrics
from dgpt_gym.benchmark.report import paper_value
from dgpt_gym.tracker import check_estimate, check_reset_signature

__all__ = [
    "EpisodeResult",
    "is_oracle",
    "run_episode",
    "run_episodes",
    "run_monte_carlo",
    "summarize_runs",
    "add_floor_ratios",
    "format_summary_table",
    "interval_half_width",
    "stratified_difference",
    "signed_interval",
    "root_mean_square",
]


def is_oracle(tracker) -> bool:
    """True for a tracker that declares itself an oracle (``oracle = True`` on its class):
    only such trackers are handed the environment's ``info``, which holds the truth."""
    return getattr(type(tracker), "oracle", False) is True


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
    sensing_range: float = 50.0
    diagnostics: dict = field(default_factory=dict)

    def metrics(self) -> dict[str, float]:
        """The episode's metrics (module :mod:`dgpt_gym.benchmark.metrics`), flat, as plain floats.

        Per axis (suffix ``_x`` / ``_y``): ``nrmse``, ``rmse``, ``ci_coverage`` and
        ``ci_width`` (3 sigma), ``ucb_coverage`` and ``ucb_width`` (NaN without a UCB),
        ``coverage_{1,2,3}sigma``. In 2-D: ``rmse_2d``, ``anees`` and ``nees_median``.
        ``rmse_2d``, ``anees``, ``nees_median``, the sigma coverages and, per axis,
        ``rmse``, ``ucb_coverage`` and ``ucb_width`` also on the steps where some sensor
        senses the target (suffix ``_detected``, e.g. ``ucb_coverage_x_detected``: the
        steps of :data:`dgpt_gym.benchmark.baseline_report.CALIBRATION_GOALS`) and on
        coverage-gap steps (``_gap``; NaN when the episode has none). ``track_lost`` (0 or 1) and
        ``lost_step_fraction`` (:func:`dgpt_gym.benchmark.metrics.track_loss` at twice the sensing
        range), ``step_time_ms`` (median) and ``no_detection_fraction``. Then the tracker's
        own :meth:`~dgpt_gym.tracker.TrackerBase.diagnostics` at the end of the episode
        (e.g. DGPT's ``share_at_bound``).
        """
        std = np.sqrt(np.maximum(self.var, 0.0))
        ci = metrics.CI_SIGMAS * std
        values = {
            "nrmse": metrics.nrmse(self.mean, self.truth),
            "ci_coverage": metrics.coverage(self.mean, self.truth, ci),
            "ci_width": metrics.mean_width(ci),
        }
        flat = {
            f"{key}_{axis}": float(value[i])
            for key, value in values.items()
            for i, axis in enumerate("xy")
        }
        has_ucb = bool(np.all(np.isfinite(self.ucb)))
        detected = self.n_detecting > 0
        for suffix, steps in (("", slice(None)), ("_detected", detected), ("_gap", ~detected)):
            flat.update(self._consistency(steps, suffix, has_ucb))
        lost = metrics.track_loss(
            self.mean, self.truth, metrics.TRACK_LOSS_RANGES * self.sensing_range
        )
        flat["track_lost"] = float(np.any(lost))
        flat["lost_step_fraction"] = float(np.mean(lost))
        flat["step_time_ms"] = float(1e3 * np.median(self.step_time))
        flat["no_detection_fraction"] = float(np.mean(self.n_detecting == 0))
        flat.update({key: float(value) for key, value in self.diagnostics.items()})
        return flat

    def _consistency(self, steps, suffix: str, has_ucb: bool) -> dict[str, float]:
        """RMSE (2-D and per axis), NEES, sigma coverage and the UCB's coverage and width
        (NaN unless ``has_ucb``) over ``steps`` (NaN when there are none)."""
        mean, truth, var = self.mean[steps], self.truth[steps], self.var[steps]
        per_axis_keys = ("coverage_1sigma", "coverage_2sigma", "coverage_3sigma", "rmse")
        per_axis_keys += ("ucb_coverage", "ucb_width")
        keys = ["rmse_2d", "anees", "nees_median"]
        keys += [f"{key}_{axis}" for key in per_axis_keys for axis in "xy"]
        if mean.shape[0] == 0:
            return {key + suffix: float("nan") for key in keys}
        errors = metrics.nees(mean, truth, var)
        values = {
            "rmse_2d": metrics.rmse_2d(mean, truth),
            "anees": float(np.mean(errors)),
            "nees_median": float(np.median(errors)),
        }
        for k in (1, 2, 3):
            covered = metrics.sigma_coverage(mean, truth, var, k)
            values[f"coverage_{k}sigma_x"], values[f"coverage_{k}sigma_y"] = map(float, covered)
        ucb = self.ucb[steps]
        per_axis = {
            "rmse": metrics.rmse(mean, truth),
            "ucb_coverage": metrics.coverage(mean, truth, ucb) if has_ucb else np.full(2, np.nan),
            "ucb_width": metrics.mean_width(ucb) if has_ucb else np.full(2, np.nan),
        }
        for key, value in per_axis.items():
            values[f"{key}_x"], values[f"{key}_y"] = map(float, value)
        return {key + suffix: values[key] for key in keys}


def run_episode(env: gym.Env, tracker, seed: int | None) -> EpisodeResult:
    """Run ``tracker`` (a :class:`dgpt_gym.tracker.Tracker`) for one episode of ``env``.

    The tracker is reset with the ``ProblemSpec`` from the env's reset info and the same
    seed, so the result is a function of ``seed``.
    """
    return run_episodes([env], [tracker], [seed])[0]


def run_episodes(
    envs: Sequence[gym.Env], trackers: Sequence, seeds: Sequence[int | None]
) -> list[EpisodeResult]:
    """Run episode i of ``envs[i]`` with ``trackers[i]`` and ``seeds[i]``, all in lockstep.

    Each step, the trackers of the episodes still running take their observations in one
    call of ``update_batch`` when their class has one (:meth:`dgpt_gym.tracker.TrackerBase.update_batch`;
    DGPT batches its learning and prediction over the episodes), else one ``update`` each
    (oracles always: they take ``truth=info`` too, see the module docstring).
    The results equal those of :func:`run_episode` on each episode alone; ``step_time`` is
    the batch's time per step divided by the number of episodes it stepped.
    """
    if not len(envs) == len(trackers) == len(seeds):
        raise ValueError(
            "envs, trackers and seeds must have the same length; got "
            f"{len(envs)}, {len(trackers)} and {len(seeds)}"
        )
    observations, truths, records = [], [], []
    for env, tracker, seed in zip(envs, trackers, seeds):
        check_reset_signature(tracker)
        observation, info = env.reset(seed=seed)
        if is_oracle(tracker):
            tracker.reset(info["problem_spec"], seed=seed, truth=info)
        else:
            tracker.reset(info["problem_spec"], seed=seed)
        observations.append(observation)
        truths.append(info)
        records.append(_EpisodeRecord(sensing_range=info["problem_spec"].sensing_range))
    shared = type(trackers[0]) if trackers else None
    batched = (
        hasattr(shared, "update_batch")
        and all(type(tracker) is shared for tracker in trackers)
        and not is_oracle(trackers[0])
    )
    running = list(range(len(envs)))
    while running:
        started = time.perf_counter()
        stepping = [trackers[i] for i in running]
        current = [observations[i] for i in running]
        if batched:
            estimates = shared.update_batch(stepping, current)
        else:
            estimates = _update_each(stepping, current, [truths[i] for i in running])
        elapsed = (time.perf_counter() - started) / len(running)
        still_running = []
        for index, estimate in zip(running, estimates):
            check_estimate(estimate, trackers[index])
            record, observation = records[index], observations[index]
            record.step_time.append(elapsed)
            record.mean.append(estimate.mean)
            record.var.append(estimate.var)
            record.ucb.append(np.full(2, np.nan) if estimate.ucb is None else estimate.ucb)
            record.n_measurements.append(int(np.sum(observation["mask"])))
            observation, _, terminated, truncated, info = envs[index].step(estimate.mean)
            observations[index], truths[index] = observation, info
            record.truth.append(info["position"])
            record.n_detecting.append(len(info["active_sensors"]))
            if not (terminated or truncated):
                still_running.append(index)
        running = still_running
    for record, tracker in zip(records, trackers):
        diagnostics = getattr(tracker, "diagnostics", None)  # optional for user trackers
        record.diagnostics = dict(diagnostics()) if callable(diagnostics) else {}
    return [record.result() for record in records]


def _update_each(trackers, observations, truths):
    """One ``update`` per tracker; only oracles are handed their episode's ``info``."""
    return [
        tracker.update(observation, truth=truth)
        if is_oracle(tracker)
        else tracker.update(observation)
        for tracker, observation, truth in zip(trackers, observations, truths)
    ]


@dataclass
class _EpisodeRecord:
    """The per-step lists of one episode while it runs."""

    sensing_range: float = 50.0
    truth: list = field(default_factory=list)
    mean: list = field(default_factory=list)
    var: list = field(default_factory=list)
    ucb: list = field(default_factory=list)
    step_time: list = field(default_factory=list)
    n_measurements: list = field(default_factory=list)
    n_detecting: list = field(default_factory=list)
    diagnostics: dict = field(default_factory=dict)

    def result(self) -> EpisodeResult:
        return EpisodeResult(
            truth=np.asarray(self.truth),
            mean=np.asarray(self.mean, dtype=float),
            var=np.asarray(self.var, dtype=float),
            ucb=np.asarray(self.ucb, dtype=float),
            step_time=np.asarray(self.step_time),
            n_measurements=np.asarray(self.n_measurements),
            n_detecting=np.asarray(self.n_detecting),
            sensing_range=self.sensing_range,
            diagnostics=self.diagnostics,
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


WALL_CLOCK_METRICS = ("step_time_ms",)
"""Metrics that are wall-clock measurements: they differ between identical runs."""

INTERVAL_KEYS = (
    "nrmse_x",
    "nrmse_y",
    "rmse_2d",
    "coverage_3sigma_x_detected",
    "coverage_3sigma_y_detected",
    "ucb_coverage_x",
    "ucb_coverage_y",
    "ucb_coverage_x_detected",
    "ucb_coverage_y_detected",
)
"""Metrics whose 95 % interval over runs :func:`summarize_runs` reports (``<key>_ci95``)."""


def interval_half_width(values) -> float:
    """Half-width of the 95 % Student-t interval of the mean of ``values`` (NaN ignored);
    NaN for fewer than two values."""
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    if values.size < 2:
        return float("nan")
    quantile = stats.t.ppf(0.975, values.size - 1)
    return float(quantile * np.std(values, ddof=1) / np.sqrt(values.size))


def root_mean_square(values, axis=-1):
    """sqrt(mean(values^2)) along ``axis``: how a cell pools its episodes' RMSEs (the RMS
    over episodes of each episode's RMSE) in the study scripts."""
    return np.sqrt(np.mean(np.square(values), axis=axis))


def stratified_difference(differences: list[np.ndarray]) -> tuple[float, float]:
    """The mean over strata of equal weight (cells) of each stratum's mean paired
    difference, and the half-width of its 95 % normal interval,
    1.96 sqrt(sum_c s_c^2 / n_c) / C."""
    means = [np.mean(values) for values in differences]
    variances = [np.var(values, ddof=1) / len(values) for values in differences]
    scale = stats.norm.ppf(0.975) * np.sqrt(np.sum(variances)) / len(differences)
    return float(np.mean(means)), float(scale)


def signed_interval(mean: float, half: float, digits: int = 2) -> str:
    """``+m ± h`` for a paired difference and its interval's half-width, bold when the
    interval excludes 0."""
    bold = "**" if abs(mean) > half else ""
    return f"{bold}{mean:+.{digits}f} ± {half:.{digits}f}{bold}"


def summarize_runs(rows: list[dict[str, float]]) -> dict[str, float]:
    """Mean of every metric over runs (NaN ignored), the STD of the RMSE over runs
    (``rmse_std_*``), the 95 % interval half-widths of :data:`INTERVAL_KEYS`
    (``<key>_ci95``; NaN for a single run, whose spread cannot be estimated), the
    track-loss rate (``track_loss_rate``, share of runs that lost the track) and ``n_runs``."""
    keys = [key for key in rows[0] if key != "seed"]
    with warnings.catch_warnings():  # a metric NaN in every run (no UCB) stays NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        summary = {key: float(np.nanmean([row.get(key, np.nan) for row in rows])) for key in keys}
    rmse_runs = np.array([[row["rmse_x"], row["rmse_y"]] for row in rows])
    summary["rmse_std_x"], summary["rmse_std_y"] = map(float, metrics.std_over_runs(rmse_runs))
    for key in INTERVAL_KEYS:
        if key in rows[0]:
            summary[f"{key}_ci95"] = interval_half_width([row[key] for row in rows])
    if "track_lost" in rows[0]:
        summary["track_loss_rate"] = summary["track_lost"]
    summary["n_runs"] = len(rows)
    return summary


def add_floor_ratios(summaries: list[dict], floor: str = "clairvoyant") -> list[dict]:
    """Set ``rmse_ratio_to_floor`` on every per-cell summary: its ``rmse_2d`` divided by that
    of the ``floor`` tracker on the same (scenario, noise_std, clutter_rate); NaN where the
    cell has no floor run (or the summary predates ``rmse_2d``)."""
    floors = {
        (row["scenario"], row["noise_std"], row["clutter_rate"]): row.get("rmse_2d", np.nan)
        for row in summaries
        if row["tracker"] == floor
    }
    for row in summaries:
        reference = floors.get((row["scenario"], row["noise_std"], row["clutter_rate"]), np.nan)
        value = row.get("rmse_2d", np.nan)
        row["rmse_ratio_to_floor"] = (
            float(value / reference) if np.isfinite(reference) and reference > 0 else float("nan")
        )
    return summaries


def _cell(value, scale: float = 1.0, digits: int = 2, interval=None) -> str:
    if value is None or not np.isfinite(value):
        return "-"
    text = f"{scale * value:.{digits}f}"
    if interval is not None and np.isfinite(interval):
        text += f" ± {scale * interval:.{digits}f}"
    return text


def format_summary_table(rows: list[dict]) -> str:
    """The printed summary, one Markdown row per cell: NRMSE % per axis with its 95 %
    interval over runs and the paper's value where the paper has one, the 2-D RMSE (m)
    with its interval, its ratio to the clairvoyant floor, ANEES (nominal 2), the 3-sigma
    coverage per axis (nominal 99.7 %), the track-loss rate and the runs."""

    header = (
        "| tracker | scenario | noise_std | clutter_rate | NRMSE X % | paper X | NRMSE Y % |"
        " paper Y | RMSE m | x floor | ANEES | 3 sigma X / Y % | loss % | runs |"
    )
    lines = [header, "|" + "---|" * 14]
    for row in rows:
        paper = [paper_value(row, axis) for axis in "xy"]
        coverage = (
            f"{_cell(row.get('coverage_3sigma_x'), 100, 1)} / "
            f"{_cell(row.get('coverage_3sigma_y'), 100, 1)}"
        )
        lines.append(
            f"| {row['tracker']} | {row['scenario']} | {row['noise_std']:g} | "
            f"{row['clutter_rate']:g} | "
            f"{_cell(row['nrmse_x'], 100, 2, row.get('nrmse_x_ci95'))} | {_cell(paper[0])} | "
            f"{_cell(row['nrmse_y'], 100, 2, row.get('nrmse_y_ci95'))} | {_cell(paper[1])} | "
            f"{_cell(row.get('rmse_2d'), 1, 1, row.get('rmse_2d_ci95'))} | "
            f"{_cell(row.get('rmse_ratio_to_floor'))} | {_cell(row.get('anees'))} | "
            f"{coverage} | {_cell(row.get('track_loss_rate'), 100, 0)} | {row['n_runs']} |"
        )
    return "\n".join(lines)
