"""Accuracy and uncertainty metrics (paper Sec. VII-E and VII-G, and the field's standard
consistency measures).

All functions take arrays of shape (n_steps, 2) (x and y columns): estimates, truth and the
per-axis predictive variances the trackers report. Per-axis metrics return one value per
axis; 2-D metrics a scalar or one value per step.

Consistency. A tracker that reports variances var_x, var_y is consistent when its errors
have them: then the 2-D normalised estimation error squared (NEES) e_x^2 / var_x +
e_y^2 / var_y is chi-square with 2 degrees of freedom (mean 2, the ANEES; median 2 ln 2 =
1.39), and |e| <= k sigma holds per axis with probability erf(k / sqrt 2) (68.3, 95.4 and
99.7 % for k = 1, 2, 3). Trackers report only the diagonal of their covariance, so the NEES
uses the diagonal (exact for independent axes).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "rmse",
    "rmse_2d",
    "nrmse",
    "nees",
    "sigma_coverage",
    "coverage",
    "mean_width",
    "std_over_runs",
    "track_loss",
    "CI_SIGMAS",
    "NOMINAL_ANEES",
    "NOMINAL_MEDIAN_NEES",
    "NOMINAL_COVERAGE",
    "TRACK_LOSS_RANGES",
    "TRACK_LOSS_STEPS",
    "VARIANCE_FLOOR",
]

NOMINAL_ANEES = 2.0
"""Mean of chi-square(2): the ANEES of a consistent 2-D tracker."""
NOMINAL_MEDIAN_NEES = 2.0 * math.log(2.0)
"""Median of chi-square(2)."""
NOMINAL_COVERAGE = {k: math.erf(k / math.sqrt(2.0)) for k in (1, 2, 3)}
"""P(|e| <= k sigma) for a Gaussian error: 0.683, 0.954, 0.997."""
TRACK_LOSS_RANGES = 2.0
"""A step can count as lost when its error exceeds this many sensing ranges."""
TRACK_LOSS_STEPS = 10
"""... for at least this many consecutive steps (:func:`track_loss`)."""
VARIANCE_FLOOR = 1e-12
"""Reported variances are floored here so that a NEES is always finite."""

CI_SIGMAS = 3.0
"""Half-width of the confidence interval in standard deviations (the paper's 99.7 %)."""


def rmse(estimates: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Root mean square error over the episode, per axis, m."""
    return np.sqrt(np.mean((np.asarray(estimates) - np.asarray(truth)) ** 2, axis=0))


def rmse_2d(estimates: np.ndarray, truth: np.ndarray) -> float:
    """sqrt(mean over steps of the squared Euclidean error), m."""
    error = np.asarray(estimates) - np.asarray(truth)
    return float(np.sqrt(np.mean(np.sum(error**2, axis=1))))


def nees(estimates: np.ndarray, truth: np.ndarray, var: np.ndarray) -> np.ndarray:
    """Per-step 2-D NEES with the reported diagonal covariance: e_x^2 / var_x + e_y^2 / var_y
    (variances floored at :data:`VARIANCE_FLOOR`). Nominal mean 2, median 1.39."""
    error = np.asarray(estimates) - np.asarray(truth)
    return np.sum(error**2 / np.maximum(np.asarray(var), VARIANCE_FLOOR), axis=1)


def sigma_coverage(
    estimates: np.ndarray, truth: np.ndarray, var: np.ndarray, k: float
) -> np.ndarray:
    """Per-axis share of steps with |error| <= k sigma; nominal :data:`NOMINAL_COVERAGE`."""
    sigma = np.sqrt(np.maximum(np.asarray(var), 0.0))
    return coverage(estimates, truth, k * sigma)


def track_loss(
    estimates: np.ndarray,
    truth: np.ndarray,
    threshold: float,
    consecutive: int = TRACK_LOSS_STEPS,
) -> np.ndarray:
    """Per-step flags of a lost track: the step belongs to a run of at least ``consecutive``
    consecutive steps whose Euclidean error exceeds ``threshold`` (the evaluation uses
    :data:`TRACK_LOSS_RANGES` sensing ranges, 100 m). An episode has lost its track when any
    step is flagged."""
    error = np.linalg.norm(np.asarray(estimates) - np.asarray(truth), axis=1)
    above = np.r_[False, error > threshold, False].astype(np.int8)
    edges = np.diff(above)
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    long_runs = (stops - starts) >= consecutive
    marks = np.zeros(error.size + 1, dtype=np.int64)
    np.add.at(marks, starts[long_runs], 1)
    np.add.at(marks, stops[long_runs], -1)
    return np.cumsum(marks[:-1]) > 0


def nrmse(estimates: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Normalised RMSE exactly as the paper defines it (Sec. VII-E): the RMSE over the
    episode divided by ``max - min`` of the true coordinate. A fraction (the paper prints
    percent). NaN for an axis along which the target never moves (range 0)."""
    truth = np.asarray(truth)
    value_range = truth.max(axis=0) - truth.min(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(value_range > 0, rmse(estimates, truth) / value_range, np.nan)


def coverage(estimates: np.ndarray, truth: np.ndarray, half_width: np.ndarray) -> np.ndarray:
    """Fraction of steps with ``|estimate - truth| <= half_width``, per axis (UCB or CI
    coverage), over the steps with a half-width: a NaN one (from a NaN variance, a tracker
    that reports none) is left out, and an axis without any is NaN, not 0."""
    inside = np.abs(np.asarray(estimates) - np.asarray(truth)) <= half_width
    reported = np.broadcast_to(~np.isnan(half_width), inside.shape)
    if reported.all():
        return np.mean(inside, axis=0)
    with np.errstate(invalid="ignore"):  # 0 / 0: no step reported one
        return np.sum(inside & reported, axis=0) / np.sum(reported, axis=0)


def mean_width(half_width: np.ndarray) -> np.ndarray:
    """Mean full width ``2 * half_width`` of a bound over the episode, per axis, m."""
    return 2.0 * np.mean(half_width, axis=0)


def std_over_runs(per_run: np.ndarray) -> np.ndarray:
    """Sample standard deviation (ddof = 1) over Monte Carlo runs, e.g. of the per-run RMSE
    (n_runs, 2); 0 for a single run."""
    per_run = np.asarray(per_run, dtype=float)
    if per_run.shape[0] < 2:
        return np.zeros(per_run.shape[1:])
    return np.std(per_run, axis=0, ddof=1)
