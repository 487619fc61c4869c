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
    "convex_combination_bound",
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


def convex_combination_bound(std: np.ndarray, gamma: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """sum_i w_i gamma_i^(1/2) sigma_i / sum_i w_i: the bound on |f - mu| of a mean that is the
    convex combination sum w_i mu_i / sum w_i, when every |f - mu_i| <= gamma_i^(1/2) sigma_i.

    With w_i = sigma_i^-2 it is eq. (31) as printed (PoE weights); with w_i = beta_i
    sigma_i^-2 it is the last line of Theorem 1's proof (GPoE) and Appendix A's bound for
    RBCM (eq. (37) with the beta weights).
    """
    total = weights.sum(axis=-1)
    bound = np.sum(weights * np.sqrt(gamma) * std, axis=-1) / np.maximum(total, _TINY)
    return np.where(total > 0, bound, np.nan)


def ucb_half_width(
    method: str,
    var: np.ndarray,
    prior_var: np.ndarray,
    delta: float,
    valid: np.ndarray | None = None,
    step: int | None = None,
) -> np.ndarray:
    """The UCB half-width of the aggregated mean (Theorems 1-2), holding with probability at
    least 1 - ``delta``; with ``step`` given, the anytime gamma of Lemma 2 (each step's term
    of Theorem 3's cumulative bound). Where no expert carries weight (all at the prior), the
    bound is the prior's, gamma^(1/2) sigma_**.
    """
    _, var, prior_var_expanded, valid = _prepare(np.zeros_like(var), var, prior_var, valid)
    n_experts = valid.sum(axis=-1)
    gamma = (
        gamma_one_step(n_experts, delta) if step is None else gamma_anytime(step, n_experts, delta)
    )
    gamma = np.asarray(gamma)[..., None]
    weights = _expert_weights(method, var, prior_var_expanded, valid) / var
    bound = convex_combination_bound(np.sqrt(var), gamma, weights)
    fallback = np.sqrt(gamma[..., 0] * prior_var_expanded[..., 0])
    return np.where(np.isfinite(bound), bound, fallback)


def cumulative_bound(one_step_bounds: np.ndarray) -> np.ndarray:
    """Theorem 3, eq. (38): the bound on sum_t |f(x_t) - mu(x_t)| up to each step is the
    running sum of the per-step bounds computed with the anytime gamma
    (``ucb_half_width(..., step=t)``). ``one_step_bounds`` (T, ...) -> (T, ...)."""
    return np.cumsum(one_step_bounds, axis=0)
