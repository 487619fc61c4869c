"""Aggregation of the experts' predictions (paper Sec. III-B) and the upper confidence
bounds of Sec. V.

Every function is pure and vectorized: ``mean`` and ``var`` have the experts on the last
axis, shape (..., M); ``prior_var`` is the prior variance sigma_**^2 = k(x*, x*), shape (...)
or broadcastable. Expert variances are clipped into ``[tiny, prior_var]`` (a GP posterior
variance never exceeds the prior's), which keeps every aggregate precision positive:

- PoE and BCM: sum 1/sigma_i^2 >= M / sigma_**^2, so the BCM precision is >= 1/sigma_**^2;
- GPoE and RBCM: beta_i >= 0; the RBCM precision is 1/sigma_**^2 + sum beta_i (1/sigma_i^2
  - 1/sigma_**^2) >= 1/sigma_**^2; GPoE falls back to the prior when every beta_i is 0
  (all experts at the prior).

Experts can be switched off with ``valid`` (..., M) (False for padding).

With a single expert there is nothing to aggregate and every method returns that expert's
prediction; applied literally, eqs. (11)-(20) would divide its variance by beta (GPoE) or
mix it with the prior (RBCM).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "AGGREGATIONS",
    "Aggregate",
    "entropy_weights",
    "aggregate",
    "gamma_one_step",
    "gamma_anytime",
    "affine_combination_bound",
    "mixture_half_width",
    "mean_coefficients",
    "ucb_half_width",
    "cumulative_bound",
]

AGGREGATIONS = ("poe", "gpoe", "bcm", "rbcm")
_TINY = 1e-300


@dataclass(frozen=True)
class Aggregate:
    """Aggregated prediction: ``mean``, ``var`` (...), and the weights w_i (..., M) of the
    experts' means in the numerator, ``mean = var * sum w_i mu_i``."""

    mean: np.ndarray
    var: np.ndarray
    weights: np.ndarray


def _prepare(mean, var, prior_var, valid):
    mean = np.asarray(mean, dtype=float)
    prior_var = np.asarray(prior_var, dtype=float)[..., None]
    var = np.clip(np.asarray(var, dtype=float), 1e-12 * prior_var, prior_var)
    valid = np.ones(mean.shape, bool) if valid is None else np.broadcast_to(valid, mean.shape)
    return mean, var, prior_var, valid


def entropy_weights(var: np.ndarray, prior_var: np.ndarray) -> np.ndarray:
    """beta_i = 1/2 (log sigma_**^2 - log sigma_i^2), eq. (11): the differential-entropy
    difference between prior and expert posterior (>= 0 for a posterior variance)."""
    prior_var = np.asarray(prior_var, dtype=float)
    return 0.5 * (np.log(prior_var) - np.log(np.asarray(var, dtype=float)))


def _expert_weights(method: str, var, prior_var, valid) -> np.ndarray:
    """beta_i of each expert: eq. (11) for GPoE and RBCM, 1 for PoE and BCM, 0 when invalid."""
    if method in ("gpoe", "rbcm"):
        return np.where(valid, entropy_weights(var, prior_var), 0.0)
    if method in ("poe", "bcm"):
        return valid.astype(float)
    raise ValueError(f"aggregation must be one of {list(AGGREGATIONS)}; got {method!r}")


def aggregate(
    method: str,
    mean: np.ndarray,
    var: np.ndarray,
    prior_var: np.ndarray,
    valid: np.ndarray | None = None,
) -> Aggregate:
    """Aggregate expert predictions with PoE (8)-(10), GPoE (11)-(14), BCM (15)-(17) or
    RBCM (18)-(20). The prior mean is 0 (outputs are centred before the GP sees them)."""
    mean, var, prior_var, valid = _prepare(mean, var, prior_var, valid)
    precision_i = np.where(valid, 1.0 / var, 0.0)
    beta = _expert_weights(method, var, prior_var, valid)
    weights = beta * precision_i
    precision = weights.sum(axis=-1)
    prior_precision = 1.0 / prior_var[..., 0]
    if method in ("bcm", "rbcm"):
        # correction by the prior: (1 - M) / sigma_**^2 for BCM, (1 - sum beta) for RBCM
        precision = precision + (1.0 - beta.sum(axis=-1)) * prior_precision
    else:
        # GPoE with every beta_i = 0 (all experts at the prior) and PoE without experts
        weights = np.where((precision > 0)[..., None], weights, 0.0)
        precision = np.where(precision > 0, precision, prior_precision)
    aggregate_var = 1.0 / np.maximum(precision, _TINY)
    aggregate_mean = aggregate_var * np.sum(weights * np.where(valid, mean, 0.0), axis=-1)
    single = valid.sum(axis=-1) == 1
    if np.any(single):
        aggregate_mean = np.where(
            single, np.sum(np.where(valid, mean, 0.0), axis=-1), aggregate_mean
        )
        aggregate_var = np.where(single, np.sum(np.where(valid, var, 0.0), axis=-1), aggregate_var)
        weights = np.where(single[..., None], precision_i, weights)
    return Aggregate(aggregate_mean, aggregate_var, weights)


def gamma_one_step(n_experts: np.ndarray | int, delta: float) -> np.ndarray:
    """gamma_i of Theorems 1-2 with the total failure probability ``delta`` split equally
    over the M experts: sum_i e^(-gamma_i / 2) = delta, so gamma_i = 2 log(M / delta)."""
    return 2.0 * np.log(np.maximum(np.asarray(n_experts, dtype=float), 1.0) / delta)


def gamma_anytime(step: np.ndarray | int, n_experts: np.ndarray | int, delta: float) -> np.ndarray:
    """gamma_{t,i} of Lemma 2 and Theorem 3 for step t >= 1: 2 log(pi_t / delta_i) with
    pi_t = pi^2 t^2 / 6 and delta_i = delta / M, so that the bound holds at every step at
    once with probability at least 1 - delta."""
    step = np.maximum(np.asarray(step, dtype=float), 1.0)
    pi_t = np.pi**2 * step**2 / 6.0
    return 2.0 * np.log(pi_t * np.maximum(np.asarray(n_experts, dtype=float), 1.0) / delta)


def affine_combination_bound(std: np.ndarray, gamma: np.ndarray, coefficients: np.ndarray):
    """sum_i |a_i| gamma_i^(1/2) sigma_i: the bound on |f - mu| of a mean that is the affine
    combination mu = sum_i a_i mu_i with sum_i a_i = 1, when every |f - mu_i| <=
    gamma_i^(1/2) sigma_i (then f - mu = sum_i a_i (f - mu_i)). With a_i >= 0 it is the
    convex-combination bound of eq. (31) and of Theorem 1's and Appendix A's proofs."""
    return np.sum(np.abs(coefficients) * np.sqrt(gamma) * std, axis=-1)


def mixture_half_width(
    weights: np.ndarray, offsets: np.ndarray, std: np.ndarray, delta: float
) -> np.ndarray:
    """A half-width u with P(|f - mu| > u) <= ``delta`` when f follows the Gaussian mixture
    sum_k w_k N(mu + offset_k, std_k^2) (``weights`` (K,) summing to one, ``offsets`` and
    ``std`` (K, ...)): Lemma 1 on each component, with its share of ``delta`` scaled by its
    weight. Component k contributes |offset_k| + gamma_k^(1/2) std_k with
    gamma_k = 2 log(K w_k / delta), so that w_k e^(-gamma_k / 2) = delta / K and the
    union over the components fails with probability at most delta; a component with
    w_k <= delta / K can fail outright and contributes nothing. u is the largest
    contribution (0 if there is none). One component of weight 1 gives Lemma 1's
    |offset| + (2 log(1 / delta))^(1/2) std."""
    std = np.asarray(std, dtype=float)
    weights = np.asarray(weights, dtype=float).reshape((-1,) + (1,) * (std.ndim - 1))
    share = weights.shape[0] * weights / delta
    gamma = 2.0 * np.log(np.maximum(share, 1.0))
    contributions = np.where(share > 1.0, np.abs(offsets) + np.sqrt(gamma) * std, 0.0)
    return np.max(contributions, axis=0)


def ucb_half_width(
    method: str,
    var: np.ndarray,
    prior_var: np.ndarray,
    delta: float,
    valid: np.ndarray | None = None,
    step: int | None = None,
    extra_var: np.ndarray | float = 0.0,
) -> np.ndarray:
    """The UCB half-width of the aggregated mean (Theorems 1-2 in a form that holds for every
    aggregation), with probability at least 1 - ``delta``; with ``step`` given, the anytime
    gamma of Lemma 2 (each step's term of Theorem 3's cumulative bound).

    The mean of :func:`aggregate` is the affine combination sum_i a_i mu_i + a_0 mu_0 with
    a_i = beta_i sigma_i^-2 / P (P the aggregate precision) and, for BCM and RBCM,
    a_0 = (1 - sum_i beta_i) sigma_**^-2 / P on the prior mean mu_0; the coefficients sum to
    one. So the half-width is :func:`affine_combination_bound` over the experts and, where
    a_0 != 0, the prior (|f - mu_0| <= gamma^(1/2) sigma_** with the prior's own share of
    ``delta``: delta is split over M + 1 events then). For PoE and GPoE (a_0 = 0) this is
    eq. (31) and Theorem 1. For RBCM it departs from Appendix A, whose
    sum_i w_i gamma^(1/2) sigma_i / sum_i w_i bounds the distance to sum_i w_i mu_i /
    sum_i w_i, which is the RBCM mean only when the beta_i sum to one; when they sum to
    more, a_0 is negative and the prior's term widens the bound. One expert: Lemma 1 on
    its prediction (what :func:`aggregate` returns); none: the prior's bound.

    ``extra_var`` (broadcastable to ``prior_var``): variance that the experts' and the
    prior's means share on top of ``var`` and ``prior_var`` (DGPT's trend estimate): the
    weights come from ``var`` and ``prior_var``, as in the aggregate, and the bounds'
    standard deviations from the sums.
    """
    _, var, prior_var_expanded, valid = _prepare(np.zeros_like(var), var, prior_var, valid)
    coefficients, prior_coefficient = _coefficients(method, var, prior_var_expanded, valid)
    n_valid = valid.sum(axis=-1)
    events = n_valid + (prior_coefficient != 0)
    gamma = gamma_one_step(events, delta) if step is None else gamma_anytime(step, events, delta)
    extra_var = np.asarray(extra_var, dtype=float)
    std = np.sqrt(var + extra_var[..., None])
    prior_std = np.sqrt(prior_var_expanded[..., 0] + extra_var)
    return (
        affine_combination_bound(std, np.asarray(gamma)[..., None], coefficients)
        + np.abs(prior_coefficient) * np.sqrt(gamma) * prior_std
    )


def mean_coefficients(method: str, var, prior_var, valid=None):
    """``(a (..., M), a_0 (...))``: the aggregated mean of :func:`aggregate` as the affine
    combination sum_i a_i mu_i + a_0 mu_0 of the experts' means and the prior mean
    (sum a_i + a_0 = 1): a_i = beta_i sigma_i^-2 / P with P the aggregate precision, a_0 the
    prior's share for BCM and RBCM ((1 - sum beta_i) sigma_**^-2 / P) and for PoE and GPoE
    without a weighted expert (1); one expert: a = 1 on it, a_0 = 0; padding gets 0."""
    _, var, prior_var_expanded, valid = _prepare(np.zeros_like(var), var, prior_var, valid)
    return _coefficients(method, var, prior_var_expanded, valid)


def _coefficients(method, var, prior_var_expanded, valid):
    """:func:`mean_coefficients` on arrays already through :func:`_prepare`."""
    beta = _expert_weights(method, var, prior_var_expanded, valid)
    weights = beta / var
    precision = weights.sum(axis=-1)
    prior_precision = 1.0 / prior_var_expanded[..., 0]
    if method in ("bcm", "rbcm"):
        prior_weight = (1.0 - beta.sum(axis=-1)) * prior_precision
    else:  # PoE and GPoE fall back to the prior only when no expert carries weight
        prior_weight = np.where(precision > 0, 0.0, prior_precision)
    total = precision + prior_weight
    coefficients = weights / total[..., None]
    prior_coefficient = prior_weight / total
    n_valid = valid.sum(axis=-1)
    single = n_valid == 1
    coefficients = np.where(single[..., None], valid.astype(float), coefficients)
    prior_coefficient = np.where(single, 0.0, np.where(n_valid == 0, 1.0, prior_coefficient))
    return np.where(valid, coefficients, 0.0), prior_coefficient


def cumulative_bound(one_step_bounds: np.ndarray) -> np.ndarray:
    """Theorem 3, eq. (38): the bound on sum_t |f(x_t) - mu(x_t)| up to each step is the
    running sum of the per-step bounds computed with the anytime gamma
    (``ucb_half_width(..., step=t)``). ``one_step_bounds`` (T, ...) -> (T, ...)."""
    return np.cumsum(one_step_bounds, axis=0)
