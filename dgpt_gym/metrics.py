"""Accuracy and uncertainty metrics, per axis (paper Sec. VII-E and VII-G).

All functions take arrays of shape (n_steps, 2) (x and y columns) and return one value per
axis.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "rmse",
    "nrmse",
    "coverage",
    "mean_width",
    "std_over_runs",
    "CI_SIGMAS",
]

CI_SIGMAS = 3.0
"""Half-width of the confidence interval in standard deviations (the paper's 99.7 %)."""


def rmse(estimates: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Root mean square error over the episode, per axis, m."""
    return np.sqrt(np.mean((np.asarray(estimates) - np.asarray(truth)) ** 2, axis=0))


def nrmse(estimates: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Normalised RMSE exactly as the paper defines it (Sec. VII-E): the RMSE over the
    episode divided by ``max - min`` of the true coordinate. A fraction (the paper prints
    percent). NaN for an axis along which the target never moves (range 0)."""
    truth = np.asarray(truth)
    value_range = truth.max(axis=0) - truth.min(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(value_range > 0, rmse(estimates, truth) / value_range, np.nan)


def coverage(estimates: np.ndarray, truth: np.ndarray, half_width: np.ndarray) -> np.ndarray:
    """Fraction of steps with ``|estimate - truth| <= half_width``, per axis (UCB or CI coverage)."""
    return np.mean(np.abs(np.asarray(estimates) - np.asarray(truth)) <= half_width, axis=0)


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
