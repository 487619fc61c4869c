"""The nearly-constant-velocity GP in state-space form, distributed over experts.

Per axis the target coordinate is a GP with the integrated Wiener-velocity kernel (the GP
form of the nearly-constant-velocity model, :class:`agents.gp.NCVPrior`). Its state
s = [position, velocity] makes the GP Markov (Hartikainen & Sarkka 2010): the posterior of
s_(t-1) given every earlier measurement, carried one step forward, is the exact GP prior of
s_t given the past, and a step's summaries are independent given s_t. With that prior
shared by every expert (it is the network's broadcast estimate):

- each expert's local posterior of s_t from its own summary is a Kalman update of the
  shared prior (:func:`expert_posteriors`);
- every expert's information gain over the shared prior is the rank-one matrix
  e1 e1^T / sigma_i^2, so each aggregation of eqs. (8)-(20), applied to the state in
  information form, is one Kalman update of the prior with a weighted pseudo-summary
  (:func:`fused_update`); for BCM it is the exact posterior given all summaries (the
  information filter);
- the marginal likelihood of a step's summaries is exact in closed form from network-wide
  sums over the experts (:func:`step_log_likelihood`);
- a manoeuvre component of the process noise (:class:`Manoeuvre`) makes each step's
  posterior a likelihood-weighted mixture of two such updates; :func:`filter_window` runs a
  window of steps through either model.

Every function is pure and vectorized over leading axes; states are (..., 2) and
covariances (..., 2, 2), with the position first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agents.aggregation import AGGREGATIONS
from baselines.kalman import reduce_mixture

__all__ = [
    "ncv_predict",
    "expert_posteriors",
    "expert_weights",
    "fused_update",
    "step_log_likelihood",
    "WindowStep",
    "Manoeuvre",
    "process_noise_components",
    "filter_window",
]

_LOG_2PI = np.log(2.0 * np.pi)


def ncv_predict(mean: np.ndarray, cov: np.ndarray, dt: float, q: np.ndarray):
    """Carry the state N(mean, cov) ``dt`` seconds forward under the NCV model with
    white-acceleration intensity ``q`` (...,): F = [[1, dt], [0, 1]],
    Q = q [[dt^3/3, dt^2/2], [dt^2/2, dt]] (the integrated Wiener-velocity kernel's
    increments). Returns the predicted mean (..., 2) and covariance (..., 2, 2)."""
    q = np.asarray(q, dtype=float)
    p, v = mean[..., 0], mean[..., 1]
    a, b, d = cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]
    new_mean = np.stack([p + dt * v, v], axis=-1)
    new_a = a + 2.0 * dt * b + dt * dt * d + q * dt**3 / 3.0
    new_b = b + dt * d + q * dt**2 / 2.0
    new_d = d + q * dt
    new_cov = np.stack([np.stack([new_a, new_b], -1), np.stack([new_b, new_d], -1)], -2)
    return new_mean, new_cov


def _kalman_update(mean, cov, summary, noise_var):
    """Update N(mean, cov) (..., 2), (..., 2, 2) with a position summary (...,) of variance
    ``noise_var`` (...,)."""
    innovation_var = cov[..., 0, 0] + noise_var
    gain = cov[..., :, 0] / innovation_var[..., None]
    new_mean = mean + (summary - mean[..., 0])[..., None] * gain
    new_cov = cov - innovation_var[..., None, None] * gain[..., :, None] * gain[..., None, :]
    return new_mean, new_cov


def expert_posteriors(mean: np.ndarray, cov: np.ndarray, summaries: np.ndarray, noise_var):
    """Each expert's local posterior of the state from its own summary alone: the Kalman
    update of the shared prior ``mean`` (..., 2), ``cov`` (..., 2, 2) with ``summaries``
    (..., M) of variances ``noise_var`` (..., M). Returns ``means`` (..., M, 2) and ``covs``
    (..., M, 2, 2)."""
    return _kalman_update(mean[..., None, :], cov[..., None, :, :], summaries, noise_var)


def expert_weights(method: str, prior_var: np.ndarray, noise_var: np.ndarray) -> np.ndarray:
    """beta_i (..., M) of experts that share the prior (position variance ``prior_var``
    (...,)) and report summaries of variance ``noise_var`` (..., M): 1 for PoE and BCM; for
    GPoE and RBCM eq. (11), 1/2 log(det P0 / det P_i) = 1/2 log(1 + sigma_pp^2 / sigma_i^2)
    (the Kalman update of a position changes the determinant by that factor)."""
    if method not in AGGREGATIONS:
        raise ValueError(f"aggregation must be one of {list(AGGREGATIONS)}; got {method!r}")
    noise_var = np.asarray(noise_var, dtype=float)
    if method in ("poe", "bcm"):
        return np.ones(noise_var.shape)
    return 0.5 * np.log1p(np.asarray(prior_var)[..., None] / noise_var)


def fused_update(method, mean, cov, summaries, noise_var):
    """Aggregate the experts' local posteriors (eqs. (8)-(20) on the state, information form).

    Every expert's information gain is e1 e1^T / sigma_i^2 over the shared prior P0, so the
    aggregate precision is a P0^-1 + sum_i (beta_i / sigma_i^2) e1 e1^T with a = sum_i beta_i
    for PoE and GPoE (no prior term) and a = 1 for BCM and RBCM (the prior weighted by
    1 - sum beta_i): one Kalman update of N(mean, cov / a) with the pseudo-summary
    sum (beta_i z_i / sigma_i^2) / sum (beta_i / sigma_i^2) of variance
    1 / sum (beta_i / sigma_i^2). For BCM it is the exact posterior given every summary (the
    information filter). One expert gives its own posterior, as
    :func:`agents.aggregation.aggregate` does.

    ``mean`` (..., 2), ``cov`` (..., 2, 2), ``summaries`` (..., M) with M >= 1,
    ``noise_var`` (..., M). Returns the aggregated mean (..., 2) and covariance (..., 2, 2).
    """
    beta = expert_weights(method, cov[..., 0, 0], noise_var)
    if summaries.shape[-1] == 1:
        beta = np.ones(beta.shape)
    gain = beta / noise_var
    total_gain = gain.sum(axis=-1)
    a = beta.sum(axis=-1) if method in ("poe", "gpoe") and summaries.shape[-1] > 1 else 1.0
    pseudo = (gain * summaries).sum(axis=-1) / total_gain
    a = np.asarray(a, dtype=float)[..., None, None]
    return _kalman_update(mean, cov / a, pseudo, 1.0 / total_gain)


def step_log_likelihood(prior_mean, prior_var, summaries, noise_var):
    """log p(z_1..z_M) of one step's summaries (..., M), z_i = x + e_i with x ~
    N(``prior_mean``, ``prior_var``) and e_i ~ N(0, ``noise_var`` (..., M)) independent:
    the exact marginal likelihood of the step under the broadcast prediction,

        -1/2 [M log 2 pi + sum log s_i + log(1 + p G) + sum e_i^2 / s_i - p H^2 / (1 + p G)],

    with p = ``prior_var``, e_i = z_i - mu, G = sum 1 / s_i, H = sum e_i / s_i: sums over the
    experts, which the network forms as it forms eq. (22)'s."""
    m = summaries.shape[-1]
    innovation = summaries - prior_mean[..., None]
    g = (1.0 / noise_var).sum(axis=-1)
    h = (innovation / noise_var).sum(axis=-1)
    shrink = 1.0 + prior_var * g
    return -0.5 * (
        m * _LOG_2PI
        + np.log(noise_var).sum(axis=-1)
        + np.log(shrink)
        + (innovation**2 / noise_var).sum(axis=-1)
        - prior_var * h**2 / shrink
    )


@dataclass(frozen=True)
class WindowStep:
    """One step with data in the learning window: ``dt`` (s) since the previous step with
    data, ``summaries`` (2, M) of its experts per axis and their ``spread`` (2, M) (the
    summary's variance on top of sigma_n^2, :class:`agents.gating.GatedSummaries`), and the
    broadcast posterior of the state after that previous step, ``mean`` (2, 2) and ``cov``
    (2, 2, 2) with the axes first: the prior the window is filtered from when this step is
    its oldest. Steps without data in between are carried by ``dt``."""

    dt: float
    summaries: np.ndarray
    spread: np.ndarray
    mean: np.ndarray
    cov: np.ndarray


@dataclass(frozen=True)
class Manoeuvre:
    """The second component of the process noise: at each step, with ``probability``, the
    white-acceleration intensity is q + ``intensity`` (m^2/s^3) instead of q. The process is
    then a two-component scale mixture of NCV GPs (a manoeuvre is a burst of acceleration);
    every step's posterior is the moment-matched mixture of the two components' posteriors,
    each weighted by its prior probability times its exact step likelihood
    (:func:`baselines.kalman.reduce_mixture`; the GPB1 algorithm of Bar-Shalom, Li &
    Kirubarajan 2001, ch. 11)."""

    intensity: float
    probability: float


def process_noise_components(q: np.ndarray, manoeuvre: Manoeuvre | None):
    """``[(intensity, prior probability), ...]`` of the process noise: ``[(q, 1)]`` without
    a manoeuvre component, else ``[(q, 1 - p), (q + q_m, p)]``."""
    if manoeuvre is None:
        return [(q, 1.0)]
    return [(q, 1.0 - manoeuvre.probability), (q + manoeuvre.intensity, manoeuvre.probability)]


def filter_window(method, steps, q, noise_var, manoeuvre: Manoeuvre | None = None):
    """Filter a window of steps from its oldest step's prior under ``q`` and ``noise_var``
    (both (..., 2): any leading batch, then the axis; a summary's variance is sigma_n^2 plus
    its spread), aggregating each step's experts with ``method``; with ``manoeuvre``, each
    axis's steps follow its two-component process noise (:class:`Manoeuvre`), the axes
    weighing their components separately (so that they stay separate problems).

    Returns ``(log_likelihood, mean, cov)``: the window's log marginal likelihood, summed
    over its steps (..., 2), and the aggregated posterior after the last step (..., 2, 2)
    and (..., 2, 2, 2)."""
    shape = np.shape(q)
    mean = np.broadcast_to(steps[0].mean, shape + (2,))
    cov = np.broadcast_to(steps[0].cov, shape + (2, 2))
    total = np.zeros(shape)
    components = process_noise_components(q, manoeuvre)
    for step in steps:
        summary_var = noise_var[..., None] + step.spread
        log_weights, means, covs = [], [], []
        for intensity, probability in components:
            prior_mean, prior_cov = ncv_predict(mean, cov, step.dt, intensity)
            log_weights.append(
                np.log(probability)
                + step_log_likelihood(
                    prior_mean[..., 0], prior_cov[..., 0, 0], step.summaries, summary_var
                )
            )
            posterior = fused_update(method, prior_mean, prior_cov, step.summaries, summary_var)
            means.append(posterior[0])
            covs.append(posterior[1])
        log_weights = np.stack(log_weights, axis=-1)
        total = total + np.logaddexp.reduce(log_weights, axis=-1)
        mean, cov = reduce_mixture(log_weights, np.stack(means, axis=-2), np.stack(covs, axis=-3))
    return total, mean, cov
