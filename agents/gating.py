"""DGP-based data association (paper Sec. IV-C, eqs. (27)-(28)).

Each sensor weighs its measurements of the step by their predictive likelihood under the
previous step's model, ``w_j = p(z_j | X_t, theta_{t-1}) / sum_j p(z_j | ...)``, eq. (27),
and reports the weighted mean ``z_bar = sum_j w_j z_j``, eq. (28), as its single training
point for the step. The likelihood is the joint x-y one: the product of the two axes'
Gaussian predictive densities N(z; mu, sigma_*^2 + sigma_n^2).

Eq. (27) weighs a sensor's measurements with its own data alone: when the prediction is
wide (after a coverage gap or a manoeuvre), the weights cannot tell the target's point from
clutter a few metres off, and the summary blends them. :func:`target_probabilities` gives
the weights that use the other reporting sensors' measurements too: the target's points of
different sensors lie within a few sigma_z of each other, clutter is spread over each disc.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GatedSummaries", "gate_measurements", "group_starts", "target_probabilities"]


@dataclass(frozen=True)
class GatedSummaries:
    """One weighted-mean summary per reporting sensor: ``sensors`` (k,) ascending,
    ``summaries`` (..., k, 2); ``weights`` (..., n) of the measurements in sensor-sorted
    order; ``spread`` (..., k, 2) the weighted variance sum_j w_j (z_j - z_bar)^2 of each
    sensor's measurements about its summary, per axis (0 for a single measurement): how far
    the summary can be from the target when the weights are unsure which measurement is it;
    ``weight_squares`` (..., k) the sum of each sensor's squared weights, sum_j w_j^2: the
    summary's noise variance is sigma_n^2 times it when all its measurements are the
    target's. The leading axes are those of the predictions the weights came from."""

    sensors: np.ndarray
    summaries: np.ndarray
    weights: np.ndarray
    spread: np.ndarray
    weight_squares: np.ndarray


def group_starts(sorted_keys: np.ndarray) -> np.ndarray:
    """Start index of every run of equal values in a sorted 1-D array."""
    # np.concatenate, not np.r_: this runs on every step, and np.r_ costs several us a call
    return np.flatnonzero(np.concatenate(([True], sorted_keys[1:] != sorted_keys[:-1])))


def gate_measurements(
    points: np.ndarray,
    sensors: np.ndarray,
    predicted_mean: np.ndarray,
    predicted_var: np.ndarray,
    log_weights: np.ndarray | None = None,
) -> GatedSummaries:
    """Weighted mean of each sensor's measurements, eqs. (27)-(28).

    Args:
        points: (n, 2) measurements of one step.
        sensors: (n,) reporting sensor of each measurement.
        predicted_mean: (..., n, 2) predictive mean of the target position used for each
            measurement (its sensor's local prediction, or the aggregate for a sensor
            without history); leading axes weigh the same measurements for several
            predictions at once.
        predicted_var: (..., n, 2) predictive variance of a measurement, sigma_*^2 +
            sigma_n^2.
        log_weights: (..., n) unnormalised log weights to use instead of eq. (27)'s
            predictive log likelihoods (e.g. the log of :func:`target_probabilities`); each
            sensor's are normalised as eq. (27)'s are.

    The weights are normalised per sensor in log space, so a sensor whose measurements are
    all far from the prediction still gets a finite summary (its most likely measurement
    dominates).
    """
    order = np.argsort(sensors, kind="stable")
    points, sensors = points[order], sensors[order]
    if log_weights is None:
        residual = points - predicted_mean[..., order, :]
        variance = predicted_var[..., order, :]
        log_likelihood = -0.5 * np.sum(residual**2 / variance + np.log(variance), axis=-1)
    else:
        log_likelihood = np.asarray(log_weights, dtype=float)[..., order]
    starts = group_starts(sensors)
    group_max = np.maximum.reduceat(log_likelihood, starts, axis=-1)
    counts = np.diff(np.append(starts, sensors.size))
    unnormalised = np.exp(log_likelihood - np.repeat(group_max, counts, axis=-1))
    totals = np.add.reduceat(unnormalised, starts, axis=-1)
    weights = unnormalised / np.repeat(totals, counts, axis=-1)
    summaries = np.add.reduceat(weights[..., None] * points, starts, axis=-2)
    deviation = points - np.repeat(summaries, counts, axis=-2)
    spread = np.add.reduceat(weights[..., None] * deviation**2, starts, axis=-2)
    weight_squares = np.add.reduceat(weights**2, starts, axis=-1)
    return GatedSummaries(sensors[starts], summaries, weights, spread, weight_squares)


def target_probabilities(
    points: np.ndarray,
    predicted_mean: np.ndarray,
    predicted_var: np.ndarray,
    noise_var: float,
    detection_rate: float,
    clutter_density: float,
) -> np.ndarray:
    """P(measurement i is the target's | every measurement of the step) (n,), under the
    paper's measurement model (Sec. VI, A1-A3) in the form the IMM-PDA's update uses
    (:func:`baselines.kalman.multi_detection_update`): Poisson(lambda_T) target points
    N(s, sigma_n^2 I) and clutter of density ``clutter_density`` = lambda_c / A_sen uniform
    in each reporting sensor's disc, s ~ N(``predicted_mean``, diag(``predicted_var``))
    (..., 2) each (leading axes: several predictions of the same points at once, giving
    (..., n)), and at least one target point in the step (every reporting sensor senses the
    target, so the all-clutter subset is left out). The environment's count is a
    zero-truncated Poisson per sensor; neither the truncation nor "at least one target point
    per sensor" is imposed, and sensor labels do not enter.

    The posterior sums over every subset of target points; this is the anchored evaluation:
    anchor a conditions s on z_a (weight e_a = lambda_T N(z_a; mu, P + sigma_n^2) / c),
    every other point i is the target's with probability beta_ai = rho_ai / (1 + rho_ai),
    rho_ai = lambda_T N(z_i; mu_a, P_a + sigma_n^2) / c, and the anchor weighs
    e_a prod_{i != a} (1 + rho_ai). Then P(i) = sum_a W_a (1 if a = i else beta_ai) with W
    the normalised anchor weights. A subset of k points is reached from each of its k
    anchors, so the probabilities of points in clusters lean towards 1: with two points,
    (w_1 + 2 w_12) / (w_1 + w_2 + 2 w_12) against (w_1 + w_12) / (w_1 + w_2 + w_12) without
    the double count (w_S: the weight of subset S). On simulated scans their sum exceeds the
    number of target points by about 1.6 % (tested). Without clutter every point is the
    target's (all ones); no points give an empty array.

    In a network every reporting sensor senses the target, so all lie within twice the
    sensing range of each other: the computation needs one exchange of measurements among
    them, before each sensor forms its own summary (eq. (28) with these weights).
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    predicted_mean = np.asarray(predicted_mean, dtype=float)[..., None, :]  # (..., 1, 2)
    predicted_var = np.asarray(predicted_var, dtype=float)[..., None, :]
    batch = np.broadcast_shapes(predicted_mean.shape, predicted_var.shape)[:-2]
    if clutter_density <= 0.0 or points.shape[0] == 0:
        return np.ones(batch + (points.shape[0],))
    log_scale = np.log(detection_rate) - np.log(clutter_density)
    innovation_var = predicted_var + noise_var
    log_evidence = log_scale + _log_normal(points - predicted_mean, innovation_var)
    anchor_mean = predicted_mean + predicted_var / innovation_var * (points - predicted_mean)
    support_var = predicted_var * noise_var / innovation_var + noise_var  # P_a + sigma_n^2
    log_rho = log_scale + _log_normal(
        points[None, :, :] - anchor_mean[..., :, None, :], support_var[..., None, :]
    )  # (..., anchor, point)
    diagonal = np.eye(points.shape[0], dtype=bool)
    log_one_plus = np.where(diagonal, 0.0, np.logaddexp(0.0, log_rho))
    log_anchor = log_evidence + log_one_plus.sum(axis=-1)
    anchor_weight = np.exp(log_anchor - log_anchor.max(axis=-1, keepdims=True))
    beta = np.where(diagonal, 1.0, np.exp(log_rho - log_one_plus))
    probabilities = (anchor_weight[..., None, :] @ beta)[..., 0, :]
    probabilities = probabilities / anchor_weight.sum(axis=-1, keepdims=True)
    return np.minimum(np.maximum(probabilities, 0.0), 1.0)  # np.clip's result, faster


def _log_normal(offset: np.ndarray, var: np.ndarray) -> np.ndarray:
    """log N(offset; 0, diag(var)) over the last axis (2)."""
    return -0.5 * np.sum(offset**2 / var + np.log(2.0 * np.pi * var), axis=-1)
