"""Kalman filtering and probabilistic data association (PDA), as pure numpy functions.

The model-based baselines (:mod:`baselines.pda`, :mod:`baselines.clairvoyant`) compose
these. Every function takes a state ``mean`` of shape (..., n) and ``cov`` (..., n, n) with
any leading batch shape (IMM modes, lockstep episodes) and works on all of it at once.
Positions are measured directly: ``measurement_matrix`` H (2, n) picks them from the state.

Two association models for a scan of measurements with clutter:

- :func:`pda_update`, the textbook PDA (Bar-Shalom, Daum and Huang, "The probabilistic data
  association filter", IEEE Control Systems Magazine 2009): at most one measurement is the
  target's; a missed detection with probability 1 - P_D P_G; clutter of spatial density
  lambda. Equal to Stone Soup's ``PDAHypothesiser`` + ``PDAUpdater`` (tests check 1e-9).
- :func:`multi_detection_update`, derived for this environment, where every sensor that
  senses the target reports one or more target measurements (a zero-truncated Poisson
  count) among Poisson clutter uniform in its own sensing disc. Given the reporting sensor
  of each measurement, the scan likelihood is the paper's eq. (42) per measurement,

      l(x) = prod_i (c + lambda_T N(z_i; H x, R)),   c = lambda_c / A_sen,

  a sum over which measurements are the target's. It is evaluated as a Gaussian mixture
  with one component per *anchor* j ("z_j is a target measurement"): the component is the
  Kalman update with z_j, refined by every other measurement i weighted with its
  probability beta_ji of being the target's under that update, and weighted by the
  anchor's evidence times the support of the others, prod_i (1 + rho_ji). The mixture is
  reduced to one Gaussian (moment matching). Clusters of mutually consistent measurements,
  which only the target produces, outweigh isolated clutter, and the posterior uses every
  target measurement, not one.
"""

from __future__ import annotations

import numpy as np
from scipy import spatial, stats

__all__ = [
    "constant_velocity_model",
    "kalman_predict",
    "kalman_update",
    "gaussian_log_pdf",
    "reduce_mixture",
    "pda_update",
    "multi_detection_update",
    "imm_mix",
    "inverse_2x2",
    "POSITION_MATRIX",
]

POSITION_MATRIX = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
"""H for the state [x, vx, y, vy] (Stone Soup's order for two constant-velocity axes)."""


_EYE2 = np.eye(2)


def constant_velocity_model(dt: float, noise_diff_coeff: float) -> tuple[np.ndarray, np.ndarray]:
    """(F, Q) of the nearly-constant-velocity model for the state [x, vx, y, vy]: continuous
    white acceleration noise of spectral density q per axis,
    Q_axis = q [[dt^3 / 3, dt^2 / 2], [dt^2 / 2, dt]] (Stone Soup's ``ConstantVelocity``)."""
    axis_f = np.array([[1.0, dt], [0.0, 1.0]])
    axis_q = noise_diff_coeff * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    zero = np.zeros((2, 2))
    return np.block([[axis_f, zero], [zero, axis_f]]), np.block([[axis_q, zero], [zero, axis_q]])


def kalman_predict(mean, cov, transition, process_noise):
    """Prediction x' = F x, P' = F P F^T + Q, batched over leading dimensions (F and Q may
    carry them too, e.g. one per IMM mode)."""
    mean = np.einsum("...ij,...j->...i", transition, mean)
    cov = transition @ cov @ np.swapaxes(transition, -1, -2) + process_noise
    return mean, cov


def _symmetric(matrix):
    return 0.5 * (matrix + np.swapaxes(matrix, -1, -2))


SPARSE_SUPPORT_MIN_POINTS = 64
"""From this many measurements in a scan, :func:`multi_detection_update` finds the pairs
that support each other with a KD-tree instead of forming all m^2 of them."""

SUPPORT_LOG_RHO_CUTOFF = -50.0
"""The sparse pairing drops the pairs with log rho_ji below this: each would add at most
rho ~ 2e-22 to an anchor's log-support and expected count, so an anchor loses at most
(m - 1) x 2e-22 of each, far below the rounding of the values they are added to."""


def _pairwise_support_dense(measurements, anchor_position, support_cov, log_rho_scale):
    """Every anchor's support from every other measurement, all m^2 pairs formed.

    With log rho_ji = ``log_rho_scale`` - (z_i - p_j)^T S^-1 (z_i - p_j) / 2 for the anchor
    positions p_j (..., m, 2) and the support covariance S (..., 2, 2), returns per anchor
    the log-support sum_{i != j} log(1 + rho_ji), the expected number of other target
    measurements t_j = sum_{i != j} beta_ji and the weighted sum sum_{i != j} beta_ji z_i,
    with beta_ji = rho_ji / (1 + rho_ji).
    """
    m = measurements.shape[0]
    dx = measurements[:, 0] - anchor_position[..., :, None, 0]  # (..., m_anchor, m)
    dy = measurements[:, 1] - anchor_position[..., :, None, 1]
    a, b, d = (support_cov[..., i, j, None, None] for i, j in ((0, 0), (0, 1), (1, 1)))
    quad = (d * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / (a * d - b * b)
    log_rho = log_rho_scale[..., None, None] - 0.5 * quad
    log_one_plus = np.logaddexp(0.0, log_rho)
    log_one_plus[..., np.arange(m), np.arange(m)] = 0.0  # an anchor does not support itself
    beta = np.exp(log_rho - log_one_plus)
    beta[..., np.arange(m), np.arange(m)] = 0.0
    return log_one_plus.sum(axis=-1), beta.sum(axis=-1), beta @ measurements


def _pairwise_support_sparse(measurements, anchor_position, support_cov, log_rho_scale):
    """:func:`_pairwise_support_dense` from the pairs with log rho_ji above
    :data:`SUPPORT_LOG_RHO_CUTOFF` only, found with a KD-tree in coordinates whitened by S.

    S <= 2 R (the anchor's update with R bounds H P_a H^T by R), so the radius does not
    grow with the prior's spread: about 11-15 sigma_z at the paper's rates. The pairs then
    grow with the scan's local density, not with m^2, and a scan of clutter at every sensor
    of a large network stays cheap.
    """
    m = measurements.shape[0]
    batch = anchor_position.shape[:-2]
    flat_positions = anchor_position.reshape(-1, m, 2)
    flat_support = np.broadcast_to(support_cov, batch + (2, 2)).reshape(-1, 2, 2)
    flat_scale = np.broadcast_to(log_rho_scale, batch).reshape(-1)
    log_support = np.zeros(flat_positions.shape[:2])
    expected_others = np.zeros(flat_positions.shape[:2])
    weighted_sum = np.zeros(flat_positions.shape)
    for k, (positions, cov, scale) in enumerate(zip(flat_positions, flat_support, flat_scale)):
        squared_radius = 2.0 * (scale - SUPPORT_LOG_RHO_CUTOFF)
        if squared_radius <= 0.0:
            continue
        # whiten: with S = L L^T, (z - p)^T S^-1 (z - p) = |L^-1 z - L^-1 p|^2
        whiten = np.linalg.inv(np.linalg.cholesky(cov)).T
        pairs = spatial.KDTree(positions @ whiten).sparse_distance_matrix(
            spatial.KDTree(measurements @ whiten), np.sqrt(squared_radius), output_type="ndarray"
        )
        anchor, other = pairs["i"], pairs["j"]
        keep = anchor != other  # an anchor does not support itself
        anchor, other = anchor[keep], other[keep]
        log_rho = scale - 0.5 * pairs["v"][keep] ** 2
        log_one_plus = np.logaddexp(0.0, log_rho)
        beta = np.exp(log_rho - log_one_plus)
        log_support[k] = np.bincount(anchor, log_one_plus, minlength=m)
        expected_others[k] = np.bincount(anchor, beta, minlength=m)
        for axis in range(2):
            weighted_sum[k, :, axis] = np.bincount(
                anchor, beta * measurements[other, axis], minlength=m
            )
    return (
        log_support.reshape(batch + (m,)),
        expected_others.reshape(batch + (m,)),
        weighted_sum.reshape(batch + (m, 2)),
    )


def inverse_2x2(matrix):
    """Inverse of symmetric 2 x 2 matrices (..., 2, 2) in closed form (the innovation
    covariances of 2-D position measurements; cheaper than a LAPACK call per batch)."""
    a, b, d = matrix[..., 0, 0], matrix[..., 0, 1], matrix[..., 1, 1]
    det = a * d - b * b
    inverse = np.empty(matrix.shape)
    inverse[..., 0, 0] = d / det
    inverse[..., 1, 1] = a / det
    inverse[..., 0, 1] = inverse[..., 1, 0] = -b / det
    return inverse


def kalman_update(mean, cov, measurement, measurement_matrix, measurement_noise):
    """Kalman update with one 2-D measurement z (..., 2) of covariance R (..., 2, 2).

    Returns the posterior mean and covariance (standard form, symmetrised), the predicted
    measurement H x and the innovation covariance S = H P H^T + R.
    """
    h = measurement_matrix
    predicted = np.einsum("ij,...j->...i", h, mean)
    cross = cov @ h.T  # P H^T, (..., n, 2)
    innovation_cov = h @ cross + measurement_noise
    gain = cross @ inverse_2x2(innovation_cov)
    innovation = measurement - predicted
    mean = mean + np.einsum("...ij,...j->...i", gain, innovation)
    cov = _symmetric(cov - gain @ np.swapaxes(cross, -1, -2))
    cov = np.broadcast_to(cov, mean.shape + mean.shape[-1:])
    return mean, cov, predicted, innovation_cov


def gaussian_log_pdf(points, mean, cov):
    """log N(points; mean, cov) for 2-D points (..., m, 2), mean (..., 2), cov (..., 2, 2)."""
    offset = points - mean[..., None, :]
    a, b, d = cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]
    det = a * d - b * b
    quad = (
        d[..., None] * offset[..., 0] ** 2
        - 2 * b[..., None] * offset[..., 0] * offset[..., 1]
        + a[..., None] * offset[..., 1] ** 2
    ) / det[..., None]
    return -0.5 * quad - np.log(2.0 * np.pi) - 0.5 * np.log(det)[..., None]


def reduce_mixture(log_weights, means, covs):
    """Moment-matched single Gaussian of a mixture, reducing the component axis (-1 of the
    weights, -2 of the means, -3 of the covariances): mean = sum w_j m_j, cov = sum w_j
    (P_j + (m_j - mean)(m_j - mean)^T), with weights normalised from their logs."""
    weights = np.exp(log_weights - np.max(log_weights, axis=-1, keepdims=True))
    weights /= weights.sum(axis=-1, keepdims=True)
    mean = np.einsum("...j,...ji->...i", weights, means)
    spread = means - mean[..., None, :]
    cov = np.einsum("...j,...jkl->...kl", weights, covs) + np.einsum(
        "...j,...jk,...jl->...kl", weights, spread, spread
    )
    return mean, _symmetric(cov)


def pda_update(
    mean,
    cov,
    measurements,
    measurement_matrix,
    measurement_noise,
    detection_probability: float,
    clutter_density: float,
    gate_probability: float = 1.0,
):
    """Textbook PDA update with one scan of measurements (m, 2).

    beta_i is proportional to P_D N(z_i; H x, S) / lambda for the measurements inside the
    gate (squared Mahalanobis distance below the chi-square(2) quantile of P_G; P_G = 1
    keeps all), beta_0 to 1 - P_D P_G; the posterior is the Gaussian reduction of the
    missed-detection and per-measurement Kalman updates.

    Returns the posterior mean and covariance and the log-likelihood of the scan relative
    to the all-clutter hypothesis, log(1 - P_D P_G + sum_i P_D N_i / lambda), per batch
    element (the IMM mode likelihood).
    """
    measurements = np.asarray(measurements, dtype=float).reshape(-1, 2)
    m = measurements.shape[0]
    batch = mean.shape[:-1]
    log_miss = np.log(max(1.0 - detection_probability * gate_probability, 1e-300))
    if m == 0:
        return mean, cov, np.full(batch, log_miss)
    # one Kalman update per measurement: broadcast a measurement axis before the state axis
    post_mean, post_cov, predicted, innovation_cov = kalman_update(
        mean[..., None, :],
        cov[..., None, :, :],
        measurements,
        measurement_matrix,
        measurement_noise,
    )
    log_pdf = gaussian_log_pdf(measurements, predicted[..., 0, :], innovation_cov[..., 0, :, :])
    log_detect = log_pdf + np.log(detection_probability) - np.log(clutter_density)
    if gate_probability < 1.0:
        threshold = stats.chi2.ppf(gate_probability, 2)
        offset = measurements - predicted[..., 0:1, :]
        mahalanobis = np.einsum(
            "...mi,...ij,...mj->...m", offset, inverse_2x2(innovation_cov[..., 0, :, :]), offset
        )
        log_detect = np.where(mahalanobis <= threshold, log_detect, -np.inf)
    log_weights = np.concatenate([np.broadcast_to(log_miss, batch + (1,)), log_detect], axis=-1)
    means = np.concatenate([mean[..., None, :], post_mean], axis=-2)
    covs = np.concatenate([cov[..., None, :, :], post_cov], axis=-3)
    new_mean, new_cov = reduce_mixture(log_weights, means, covs)
    return new_mean, new_cov, np.logaddexp.reduce(log_weights, axis=-1)


def multi_detection_update(
    mean,
    cov,
    measurements,
    measurement_matrix,
    noise_std: float,
    detection_rate: float,
    clutter_density: float,
    miss_probability: float = 0.0,
):
    """Update with a scan in which the target may have produced several measurements
    (module docstring): the anchored Gaussian-mixture evaluation of eq. (42).

    For every anchor j: the Kalman update with z_j (mean m_j, covariance P_j), its evidence
    e_j = lambda_T N(z_j; H x, S) / c, and for every other measurement the ratio
    rho_ji = lambda_T N(z_i; H m_j, H P_j H^T + R) / c and probability beta_ji = rho_ji /
    (1 + rho_ji) of being the target's. The component is the update of (m_j, P_j) with the
    beta-weighted measurements (information sum_i beta_ji R^-1), and its weight
    e_j prod_{i != j} (1 + rho_ji). A missed-detection component (the prediction itself, weight
    ``miss_probability``, relative to P(some target measurement) = 1 - miss_probability)
    covers scans without a target measurement. Without clutter every measurement is the
    target's: one Kalman update with their mean and R / m. From
    :data:`SPARSE_SUPPORT_MIN_POINTS` measurements on, the pairs (j, i) are found with a
    KD-tree and those with rho_ji below exp(:data:`SUPPORT_LOG_RHO_CUTOFF`) are left out,
    so a scan of m points of bounded local density costs O(m log m) rather than O(m^2)
    (clutter at every sensor of a large network).

    Returns the posterior mean and covariance and the log-likelihood of the scan relative
    to the all-clutter hypothesis (the IMM mode likelihood): sum_j w_j / (1 + sum_i beta_ji),
    since anchor j's weight stands for the subsets that contain z_j, each of which the sum
    over anchors meets once per member. (The posterior needs no such correction to first
    order: the anchors of one subset give nearly the same component.)
    """
    measurements = np.asarray(measurements, dtype=float).reshape(-1, 2)
    m = measurements.shape[0]
    batch = mean.shape[:-1]
    variance = noise_std**2
    eye = _EYE2
    if m == 0:
        return mean, cov, np.zeros(batch)
    if clutter_density <= 0.0:
        centroid = measurements.mean(axis=0)
        new_mean, new_cov, predicted, innovation_cov = kalman_update(
            mean, cov, centroid, measurement_matrix, variance / m * eye
        )
        return (
            new_mean,
            new_cov,
            gaussian_log_pdf(centroid[None], predicted, innovation_cov)[..., 0],
        )
    h = measurement_matrix
    log_ratio_scale = np.log(detection_rate) - np.log(clutter_density)
    # Anchors: the Kalman gain and posterior covariance do not depend on the measurement,
    # so one gain serves every anchor of a batch element.
    predicted = np.einsum("ij,...j->...i", h, mean)
    cross = cov @ h.T
    innovation_cov = h @ cross + variance * eye
    gain = cross @ inverse_2x2(innovation_cov)  # (..., n, 2)
    anchor_cov = _symmetric(cov - gain @ np.swapaxes(cross, -1, -2))
    innovation = measurements - predicted[..., None, :]  # (..., m, 2)
    anchor_mean = mean[..., None, :] + np.einsum("...ik,...jk->...ji", gain, innovation)
    log_evidence = log_ratio_scale + gaussian_log_pdf(measurements, predicted, innovation_cov)
    # support of every measurement i under anchor j
    anchor_cross = anchor_cov @ h.T
    support_cov = h @ anchor_cross + variance * eye  # the same for every anchor
    anchor_position = np.einsum("ij,...aj->...ai", h, anchor_mean)
    support_det = support_cov[..., 0, 0] * support_cov[..., 1, 1] - support_cov[..., 0, 1] ** 2
    log_rho_scale = log_ratio_scale - np.log(2.0 * np.pi) - 0.5 * np.log(support_det)
    # A non-finite state (which the dense sums carry along as NaN) would stop the KD-tree.
    sparse = m >= SPARSE_SUPPORT_MIN_POINTS and np.all(np.isfinite(anchor_position))
    pairwise = _pairwise_support_sparse if sparse else _pairwise_support_dense
    log_support, expected_others, weighted_sum = pairwise(
        measurements, anchor_position, support_cov, log_rho_scale
    )
    # Refine each anchor with the beta-weighted other measurements: one update with their
    # weighted mean and R / t_j (t_j = sum_i beta_ji) carries exactly their summed
    # information. The anchors share P_a, so with A = H P_a H^T component j's innovation
    # covariance is S_j = A + R / t_j, and S_j^-1 = t_j (t_j A + R)^-1; written so, the
    # refinement and its shrinkage vanish smoothly as t_j -> 0 (an anchor nothing supports).
    anchor_only = support_cov - variance * eye  # A
    scaled_inverse = inverse_2x2(
        expected_others[..., None, None] * anchor_only[..., None, :, :] + variance * eye
    )  # (t_j A + R)^-1, (..., m, 2, 2)
    correction = np.einsum(
        "...akl,...al->...ak",
        scaled_inverse,
        weighted_sum - expected_others[..., None] * anchor_position,
    )
    refined_mean = anchor_mean + correction @ np.swapaxes(anchor_cross, -1, -2)
    refine_inverse = expected_others[..., None, None] * scaled_inverse  # S_j^-1
    log_weights = log_evidence + log_support + np.log1p(-miss_probability)
    if miss_probability > 0.0:
        log_weights = np.concatenate(
            [np.full(batch + (1,), np.log(miss_probability)), log_weights], axis=-1
        )
    weights = np.exp(log_weights - np.max(log_weights, axis=-1, keepdims=True))
    weights /= weights.sum(axis=-1, keepdims=True)
    anchor_weights = weights[..., -m:]
    means = refined_mean
    if miss_probability > 0.0:
        means = np.concatenate([mean[..., None, :], refined_mean], axis=-2)
    new_mean = np.einsum("...j,...ji->...i", weights, means)
    spread = means - new_mean[..., None, :]
    shrink = np.einsum("...a,...akl->...kl", anchor_weights, refine_inverse)
    anchored = anchor_weights.sum(axis=-1)[..., None, None] * anchor_cov - anchor_cross @ shrink @ (
        np.swapaxes(anchor_cross, -1, -2)
    )
    new_cov = anchored + np.einsum("...j,...jk,...jl->...kl", weights, spread, spread)
    if miss_probability > 0.0:
        new_cov = new_cov + weights[..., 0, None, None] * cov
    # The scan likelihood relative to all clutter sums each subset of target measurements
    # once, but the anchors count a subset of size k once per member: divide each anchor's
    # weight by the expected size of its subset, 1 + sum_i beta_ji.
    log_likelihood_terms = log_weights.copy()
    log_likelihood_terms[..., -m:] -= np.log1p(expected_others)
    return new_mean, _symmetric(new_cov), np.logaddexp.reduce(log_likelihood_terms, axis=-1)


def imm_mix(means, covs, mode_probabilities, mode_transition):
    """IMM interaction (Blom and Bar-Shalom): the mixed initial condition of every mode.

    ``means`` (..., M, n), ``covs`` (..., M, n, n), ``mode_probabilities`` (..., M) and the
    Markov matrix P[i, j] = P(mode j | mode i). Returns the mixed means and covariances and
    the predicted mode probabilities c_j = sum_i P[i, j] mu_i.
    """
    joint = mode_probabilities[..., :, None] * mode_transition  # (..., i, j)
    predicted = joint.sum(axis=-2)
    mixing = joint / np.maximum(predicted[..., None, :], 1e-300)  # mu_{i|j}
    log_mixing = np.log(np.maximum(np.swapaxes(mixing, -1, -2), 1e-300))  # (..., j, i)
    mixed_mean, mixed_cov = reduce_mixture(
        log_mixing, means[..., None, :, :], covs[..., None, :, :, :]
    )
    return mixed_mean, mixed_cov, predicted
