"""DGP-based data association (paper Sec. IV-C, eqs. (27)-(28)).

Each sensor weighs its measurements of the step by their predictive likelihood under the
previous step's model, ``w_j = p(z_j | X_t, theta_{t-1}) / sum_j p(z_j | ...)``, eq. (27),
and reports the weighted mean ``z_bar = sum_j w_j z_j``, eq. (28), as its single training
point for the step. The likelihood is the joint x-y one: the product of the two axes'
Gaussian predictive densities N(z; mu, sigma_*^2 + sigma_n^2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GatedSummaries", "gate_measurements", "group_starts"]


@dataclass(frozen=True)
class GatedSummaries:
    """One weighted-mean summary per reporting sensor: ``sensors`` (k,) ascending,
    ``summaries`` (k, 2); ``weights`` (n,) of the measurements in sensor-sorted order;
    ``spread`` (k, 2) the weighted variance sum_j w_j (z_j - z_bar)^2 of each sensor's
    measurements about its summary, per axis (0 for a single measurement): how far the
    summary can be from the target when the weights are unsure which measurement is it."""

    sensors: np.ndarray
    summaries: np.ndarray
    weights: np.ndarray
    spread: np.ndarray


def group_starts(sorted_keys: np.ndarray) -> np.ndarray:
    """Start index of every run of equal values in a sorted 1-D array."""
    return np.flatnonzero(np.r_[True, sorted_keys[1:] != sorted_keys[:-1]])


def gate_measurements(
    points: np.ndarray,
    sensors: np.ndarray,
    predicted_mean: np.ndarray,
    predicted_var: np.ndarray,
) -> GatedSummaries:
    """Weighted mean of each sensor's measurements, eqs. (27)-(28).

    Args:
        points: (n, 2) measurements of one step.
        sensors: (n,) reporting sensor of each measurement.
        predicted_mean: (n, 2) predictive mean of the target position used for each
            measurement (its sensor's local prediction, or the aggregate for a sensor
            without history).
        predicted_var: (n, 2) predictive variance of a measurement, sigma_*^2 + sigma_n^2.

    The weights are normalised per sensor in log space, so a sensor whose measurements are
    all far from the prediction still gets a finite summary (its most likely measurement
    dominates).
    """
    order = np.argsort(sensors, kind="stable")
    points, sensors = points[order], sensors[order]
    residual = points - predicted_mean[order]
    variance = predicted_var[order]
    log_likelihood = -0.5 * np.sum(residual**2 / variance + np.log(variance), axis=1)
    starts = group_starts(sensors)
    group_max = np.maximum.reduceat(log_likelihood, starts)
    counts = np.diff(np.r_[starts, sensors.size])
    unnormalised = np.exp(log_likelihood - np.repeat(group_max, counts))
    totals = np.add.reduceat(unnormalised, starts)
    weights = unnormalised / np.repeat(totals, counts)
    summaries = np.add.reduceat(weights[:, None] * points, starts, axis=0)
    deviation = points - np.repeat(summaries, counts, axis=0)
    spread = np.add.reduceat(weights[:, None] * deviation**2, starts, axis=0)
    return GatedSummaries(sensors[starts], summaries, weights, spread)
