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
  sums over the experts (:func:`pool_summaries`, :func:`step_log_likelihood`); with BCM and
  PoE those sums also give the aggregate, so a window of steps is filtered from them alone,
  for many episodes at once (:func:`filter_steps`);
- a manoeuvre component of the process noise (:class:`Manoeuvre`) makes each step's
  posterior a likelihood-weighted mixture of two such updates; :func:`filter_window` runs a
  window of steps through either model.

Every function is pure and vectorized over leading axes; states are (..., 2) and
covariances (..., 2, 2), with the position first.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from agents.aggregation import AGGREGATIONS
from baselines.cpf import turn_transition
from baselines.kalman import reduce_mixture

__all__ = [
    "ncv_predict",
    "turn_predict",
    "expert_posteriors",
    "expert_weights",
    "mixture_summaries",
    "fused_update",
    "aggregate_error_var",
    "aggregate_error_cov",
    "step_log_likelihood",
    "PooledSummaries",
    "pool_summaries",
    "pooled_log_likelihood",
    "pooled_update",
    "POOLED_METHODS",
    "WindowStep",
    "Manoeuvre",
    "process_noise_components",
    "condition_on_position",
    "filter_window",
    "filter_steps",
    "bcm_window_log_likelihood",
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
    new_p = p + dt * v
    new_mean = np.empty(new_p.shape + (2,))  # filled in place: np.stack costs more here
    new_mean[..., 0], new_mean[..., 1] = new_p, v
    new_a = a + 2.0 * dt * b + dt * dt * d + q * dt**3 / 3.0
    new_b = b + dt * d + q * dt**2 / 2.0
    new_d = d + q * dt
    # new_a's operands include new_b's and new_d's, so its shape is the broadcast of all three
    new_cov = np.empty(new_a.shape + (2, 2))
    new_cov[..., 0, 0], new_cov[..., 1, 1] = new_a, new_d
    new_cov[..., 0, 1] = new_cov[..., 1, 0] = new_b
    return new_mean, new_cov


def turn_predict(mean: np.ndarray, cov: np.ndarray, dt: float, q, omega: float):
    """Carry the two axes' states N(``mean`` (..., 2 axes, 2), ``cov`` (..., 2, 2, 2)) ``dt``
    seconds forward under a coordinated turn at ``omega`` rad/s (the transition
    :func:`baselines.cpf.turn_transition` of [x, vx, y, vy], which rotates the velocity)
    with each axis's NCV process noise of intensity ``q`` (..., 2) as in
    :func:`ncv_predict`. The turn couples the axes; the prediction keeps each axis's
    2 x 2 block of the joint covariance and drops the cross-axis blocks, so that every
    other step stays per axis (their size relative to the blocks is about |omega dt| / 2
    for equal axis variances; omega = 0 gives :func:`ncv_predict` exactly)."""
    q = np.broadcast_to(np.asarray(q, dtype=float), np.shape(mean)[:-1])
    transition, noise = _turn_matrices(float(omega), float(dt))
    new_mean = np.einsum("aibj,...bj->...ai", transition, mean)
    # the joint covariance is block diagonal over the axes: F P F^T = sum_b F_ab P_b F_cb^T
    blocks = np.einsum("aibj,...bjk,albk->...ail", transition, cov, transition)
    new_cov = blocks + q[..., None, None] * noise
    return new_mean, new_cov


@functools.lru_cache(maxsize=64)
def _turn_matrices(omega: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`turn_predict`'s transition as (axis, entry, axis, entry) and the NCV noise
    shape of one axis, read-only: a tracker asks for the same few (omega, dt) every step."""
    transition = turn_transition(omega, dt).reshape(2, 2, 2, 2)
    noise = np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    transition.flags.writeable = noise.flags.writeable = False
    return transition, noise


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


MIXTURE_SPREAD_SHARE = 0.99
"""The largest spread :func:`mixture_summaries` takes, as a share of the summary's
innovation variance: a spread at or above it would make the sensor's mixture posterior wider
than its prior, which no Gaussian measurement gives."""


def mixture_summaries(prior_mean, prior_var, summaries, noise_var, spread):
    """The pseudo-measurements whose Kalman update gives each sensor's mixture posterior.

    A sensor whose measurements z_j carry association weights w_j (summing to 1) has, as
    its local posterior of the position, the mixture over which z_j is the target's; its
    moments (the PDA update, Bar-Shalom & Tse 1975) are, with innovation variance
    a = p + r (p = ``prior_var``, r = ``noise_var``), gain K = p / a, nu = zbar - mu:

        mean mu + K nu,    variance (1 - K) p + K^2 S,

    S = ``spread`` = sum_j w_j (z_j - zbar)^2. The summary zbar taken as one measurement of
    variance r + S (eq. (28)) gives a smaller gain and the variance p (r + S) / (a + S),
    narrower by p^2 S^2 / (a^2 (a + S)): it uses the prediction twice, once in the weights
    and once as the prior it updates. The Kalman update with the pseudo-measurement

        z' = mu + nu a / (a - S)   of variance   r' = (a r + p S) / (a - S)

    gives the mixture's moments exactly, for the whole state (the update is rank one in
    the position), when S < a; the spread is capped at :data:`MIXTURE_SPREAD_SHARE` of a,
    which keeps the mean and gives a variance just under the prior's. S = 0 returns
    ``summaries`` and ``noise_var`` up to rounding.

    ``prior_mean``, ``prior_var`` (...,); ``summaries``, ``noise_var``, ``spread`` (..., M).
    Returns z' and r' (..., M)."""
    prior_mean = np.asarray(prior_mean, dtype=float)[..., None]
    prior_var = np.asarray(prior_var, dtype=float)[..., None]
    innovation_var = prior_var + noise_var
    spread = np.minimum(spread, MIXTURE_SPREAD_SHARE * innovation_var)
    scale = innovation_var / (innovation_var - spread)
    pseudo = prior_mean + (summaries - prior_mean) * scale
    return pseudo, (innovation_var * noise_var + prior_var * spread) / (innovation_var - spread)


class PooledSummaries(NamedTuple):
    """A step's summaries z_i of variances s_i (per axis), reduced to the network-wide sums
    that the exact step likelihood and a BCM or PoE aggregate need: ``count`` M,
    ``precision`` G = sum 1 / s_i, ``mean`` zbar = sum (z_i / s_i) / G, ``residual``
    R = sum (z_i - zbar)^2 / s_i and ``log_det`` sum log s_i, each (...,)."""

    count: np.ndarray
    precision: np.ndarray
    mean: np.ndarray
    residual: np.ndarray
    log_det: np.ndarray


POOLED_METHODS = ("poe", "bcm")
"""The aggregations whose aggregate depends on the summaries only through
:class:`PooledSummaries` (their weights beta_i do not depend on the prior)."""


def pool_summaries(summaries: np.ndarray, noise_var: np.ndarray) -> PooledSummaries:
    """:class:`PooledSummaries` of ``summaries`` (..., M), M >= 1, of variances
    ``noise_var`` (..., M)."""
    summaries = np.asarray(summaries, dtype=float)
    noise_var = np.broadcast_to(np.asarray(noise_var, dtype=float), summaries.shape)
    precision = (1.0 / noise_var).sum(axis=-1)
    mean = (summaries / noise_var).sum(axis=-1) / precision
    residual = ((summaries - mean[..., None]) ** 2 / noise_var).sum(axis=-1)
    count = np.full(precision.shape, float(summaries.shape[-1]))
    return PooledSummaries(count, precision, mean, residual, np.log(noise_var).sum(axis=-1))


def pooled_log_likelihood(prior_mean, prior_var, pooled: PooledSummaries) -> np.ndarray:
    """log p(z_1..z_M) of one step's summaries, z_i = x + e_i with x ~ N(``prior_mean``,
    ``prior_var``) and e_i ~ N(0, s_i) independent, from their sums (:class:`PooledSummaries`):

        -1/2 [M log 2 pi + sum log s_i + log(1 + p G) + R + (zbar - mu)^2 / (p + 1 / G)],

    with p = ``prior_var`` and mu = ``prior_mean`` (the Gaussian integral over x; the
    Sherman-Morrison form of the dense M x M covariance p 1 1^T + diag(s))."""
    offset = pooled.mean - prior_mean
    return -0.5 * (
        pooled.count * _LOG_2PI
        + pooled.log_det
        + np.log1p(prior_var * pooled.precision)
        + pooled.residual
        + offset**2 / (prior_var + 1.0 / pooled.precision)
    )


def step_log_likelihood(prior_mean, prior_var, summaries, noise_var):
    """log p(z_1..z_M) of one step's summaries (..., M) of variances ``noise_var``
    (..., M) under the broadcast prediction N(``prior_mean``, ``prior_var``) of the
    position: the exact marginal likelihood (:func:`pooled_log_likelihood`), from sums over
    the experts that the network forms as it forms eq. (22)'s."""
    return pooled_log_likelihood(prior_mean, prior_var, pool_summaries(summaries, noise_var))


def pooled_update(method: str, mean, cov, pooled: PooledSummaries):
    """The BCM or PoE aggregate of the experts' local posteriors (:func:`fused_update`) from
    the step's :class:`PooledSummaries`: one Kalman update of N(``mean``, ``cov`` / a) with
    the pseudo-summary zbar of variance 1 / G, a = 1 for BCM and M for PoE."""
    if method not in POOLED_METHODS:
        raise ValueError(f"pooled_update needs method in {list(POOLED_METHODS)}; got {method!r}")
    if method == "poe":
        cov = cov / np.asarray(pooled.count)[..., None, None]
    return _kalman_update(mean, cov, pooled.mean, 1.0 / pooled.precision)


def fused_update(method, mean, cov, summaries, noise_var):
    """Aggregate the experts' local posteriors (eqs. (8)-(20) on the state, information form).

    Every expert's information gain is e1 e1^T / sigma_i^2 over the shared prior P0, so the
    aggregate precision is a P0^-1 + sum_i (beta_i / sigma_i^2) e1 e1^T with a = sum_i beta_i
    for PoE and GPoE (no prior term) and a = 1 for BCM and RBCM (the prior weighted by
    1 - sum beta_i): one Kalman update of N(mean, cov / a) with the pseudo-summary
    sum (beta_i z_i / sigma_i^2) / sum (beta_i / sigma_i^2) of variance
    1 / sum (beta_i / sigma_i^2). For BCM it is the exact posterior given every summary (the
    information filter). One expert gives its own posterior, as
    :func:`agents.aggregation.aggregate` does. BCM and PoE go through
    :func:`pooled_update`.

    ``mean`` (..., 2), ``cov`` (..., 2, 2), ``summaries`` (..., M) with M >= 1,
    ``noise_var`` (..., M). Returns the aggregated mean (..., 2) and covariance (..., 2, 2).
    """
    if method in POOLED_METHODS:
        return pooled_update(method, mean, cov, pool_summaries(summaries, noise_var))
    gain, a = _fusion_weights(method, cov[..., 0, 0], noise_var)
    total_gain = gain.sum(axis=-1)
    pseudo = (gain * summaries).sum(axis=-1) / total_gain
    return _kalman_update(mean, cov / a[..., None, None], pseudo, 1.0 / total_gain)


def _fusion_weights(method, prior_var, noise_var):
    """``(g (..., M), a (...))`` of :func:`fused_update`'s Kalman update of N(mu_0, P_0 / a)
    with the pseudo-summary sum g_i z_i / sum g_i: g_i = beta_i / s_i (beta_i = 1 for a
    single expert), a = M for PoE, sum beta_i for GPoE with more than one expert, else 1."""
    noise_var = np.asarray(noise_var, dtype=float)
    beta = expert_weights(method, prior_var, noise_var)
    if noise_var.shape[-1] == 1:
        beta = np.ones(beta.shape)
    if method == "poe":
        a = np.full(beta.shape[:-1], float(noise_var.shape[-1]))
    elif method == "gpoe" and noise_var.shape[-1] > 1:
        a = beta.sum(axis=-1)
    else:
        a = np.ones(beta.shape[:-1])
    return beta / noise_var, a


def aggregate_error_var(method, prior_var, noise_var):
    """The variance of the aggregated position's error under the model (...,): how far the
    mean of :func:`fused_update` is from the target when the state is drawn from the shared
    prior and each summary is the target's position plus independent noise of variance
    ``noise_var`` (..., M), M >= 1; ``prior_var`` (...,) is the prior's position variance.

    The aggregate is a Kalman update of N(mu_0, P_0 / a) with the pseudo-summary
    z* = sum g_i z_i / G (g_i = beta_i / s_i, G = sum g_i), so with the position gain
    k = (p / a) / (p / a + 1 / G) its position error is (1 - k) (x - mu_0) - k v*, with
    v* = sum g_i v_i / G:

        (1 - k)^2 p + k^2 sum g_i^2 s_i / G^2.

    For BCM (beta_i = 1, a = 1) this is the posterior variance p / (1 + p G): the BCM is the
    exact posterior. The other aggregations' errors are larger (the exact posterior mean has
    the smallest error variance), and may be larger or smaller than the variance they report.
    It is the variance Lemma 1 needs for a bound on the aggregate
    (:class:`agents.state_space_dgpt.StateSpaceDGPT`'s UCB), where Theorem 2's triangle
    inequality over the experts is about sqrt(M) times wider with M experts of equal
    variance."""
    prior_var = np.asarray(prior_var, dtype=float)
    a, total_gain, pseudo_noise_var = _pseudo_summary(method, prior_var, noise_var)
    scaled_prior = prior_var / a
    k = scaled_prior / (scaled_prior + 1.0 / total_gain)
    return (1.0 - k) ** 2 * prior_var + k**2 * pseudo_noise_var


def _pseudo_summary(method, prior_var, noise_var):
    """``(a, G, sum g_i^2 s_i / G^2)`` of :func:`fused_update`'s update of N(mu_0, P_0 / a)
    with the pseudo-summary sum g_i z_i / G (:func:`_fusion_weights`)."""
    noise_var = np.asarray(noise_var, dtype=float)
    gain, a = _fusion_weights(method, prior_var, noise_var)
    total_gain = gain.sum(axis=-1)
    return a, total_gain, (gain**2 * noise_var).sum(axis=-1) / total_gain**2


def aggregate_error_cov(method, prior_cov, error_prior_cov, noise_var):
    """The covariance (..., 2, 2) of the aggregated state's error when the prior mean's
    error has covariance ``error_prior_cov`` (..., 2, 2), which need not be the prior
    covariance ``prior_cov`` the aggregation uses (..., 2, 2), and each summary is the
    target's position plus independent noise of variance ``noise_var`` (..., M).

    :func:`fused_update` is a Kalman update of N(mu_0, P_0 / a) with the pseudo-summary
    z* = sum g_i z_i / G of noise variance sum g_i^2 s_i / G^2 (:func:`aggregate_error_var`),
    with gain K = (P_0 / a) e1 / ((P_0 / a)_11 + 1 / G). Its error is
    (I - K e1^T)(mu_0 - x) - K v*, whose covariance is the Joseph form

        (I - K e1^T) E_0 (I - K e1^T)^T + K K^T sum g_i^2 s_i / G^2

    with E_0 = ``error_prior_cov``. With E_0 = P_0 its position entry is
    :func:`aggregate_error_var`, and for BCM the whole matrix is the posterior covariance.
    PoE and GPoE broadcast a posterior narrower than their error, so carried from step to
    step their E_0 is wider than their P_0 (:class:`agents.state_space_dgpt.StateSpaceDGPT`)."""
    prior_cov = np.asarray(prior_cov, dtype=float)
    error_prior_cov = np.asarray(error_prior_cov, dtype=float)
    a, total_gain, pseudo_noise_var = _pseudo_summary(method, prior_cov[..., 0, 0], noise_var)
    scaled_first_column = prior_cov[..., :, 0] / a[..., None]
    kalman_gain = scaled_first_column / (scaled_first_column[..., :1] + 1.0 / total_gain[..., None])
    keep = np.eye(2) - kalman_gain[..., :, None] * np.array([1.0, 0.0])
    return keep @ error_prior_cov @ np.swapaxes(keep, -1, -2) + pseudo_noise_var[
        ..., None, None
    ] * (kalman_gain[..., :, None] * kalman_gain[..., None, :])


@dataclass(frozen=True)
class WindowStep:
    """One step with data in the learning window: ``dt`` (s) since the previous step with
    data, ``summaries`` (2, M) of its experts per axis and their ``spread`` (2, M) (the
    summary's variance minus sigma_n^2: the weighted spread of its measurements,
    :class:`agents.gating.GatedSummaries`, less sigma_n^2 (1 - sum w_j^2) when the summary's
    variance is its weighted mean's, so it can be negative), and the
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


def condition_on_position(mean, cov, position_mean, position_var):
    """The state's posterior when a position posterior N(``position_mean``,
    ``position_var``) (...,) replaces the prior's position marginal: the prior N(``mean``,
    ``cov``) ((..., 2), (..., 2, 2)) keeps its velocity given the position, linear in it
    with slope g = P_vp / P_pp. Exact for any update whose likelihood depends on the
    position only (the hybrid filter's Poisson likelihood, eq. (42)), moment-matched when the
    position posterior is not Gaussian; a Kalman update's own position marginal gives back
    the Kalman update. Returns the mean (..., 2) and covariance (..., 2, 2)."""
    position_mean = np.asarray(position_mean, dtype=float)
    position_var = np.asarray(position_var, dtype=float)
    slope = cov[..., 1, 0] / cov[..., 0, 0]
    velocity = mean[..., 1] + slope * (position_mean - mean[..., 0])
    cross = slope * position_var
    velocity_var = cov[..., 1, 1] - slope * cov[..., 1, 0] + slope * cross
    new_mean = np.stack([position_mean, velocity], axis=-1)
    new_cov = np.stack(
        [np.stack([position_var, cross], -1), np.stack([cross, velocity_var], -1)], -2
    )
    return new_mean, new_cov


def filter_window(method, steps, q, noise_var, manoeuvre: Manoeuvre | None = None):
    """Filter a window of steps from its oldest step's prior under ``q`` and ``noise_var``
    (both (..., 2): any leading batch, then the axis; a summary's variance is sigma_n^2 plus
    its ``spread``, :class:`WindowStep`), aggregating each step's experts with ``method``;
    with ``manoeuvre``, each axis's steps follow its two-component process noise
    (:class:`Manoeuvre`), the axes weighing their components separately (so that they stay
    separate problems).

    Returns ``(log_likelihood, mean, cov)``: the window's log marginal likelihood, summed
    over its steps (..., 2), and the aggregated posterior after the last step (..., 2, 2)
    and (..., 2, 2, 2)."""
    data = []
    for step in steps:
        summary_var = noise_var[..., None] + step.spread
        if method in POOLED_METHODS:
            data.append((step.dt, True, pool_summaries(step.summaries, summary_var)))
        else:
            data.append((step.dt, True, (step.summaries, summary_var)))
    return filter_steps(method, data, steps[0].mean, steps[0].cov, q, manoeuvre)


def filter_steps(method, steps, mean, cov, q, manoeuvre: Manoeuvre | None = None):
    """The filter of :func:`filter_window` over ``steps``, a sequence of ``(dt, valid,
    data)``: ``data`` is the step's :class:`PooledSummaries` (BCM and PoE) or its
    ``(summaries, summary_var)`` (any method); where ``valid`` is False the step is skipped
    (the state and the likelihood are kept), so that windows of different lengths are
    filtered together, padded at the front. Every argument broadcasts against ``q``
    (..., 2); ``mean`` (..., 2) and ``cov`` (..., 2, 2) are the prior of the first step.
    Returns ``(log_likelihood, mean, cov)`` as :func:`filter_window`."""
    shape = np.shape(q)
    mean = np.broadcast_to(mean, shape + (2,))
    cov = np.broadcast_to(cov, shape + (2, 2))
    total = np.zeros(shape)
    components = process_noise_components(q, manoeuvre)
    # the process-noise components on an axis of their own, before the state's axes, so that
    # one prediction, likelihood and update per step serve them all
    intensities = np.stack([np.broadcast_to(c, shape) for c, _ in components], axis=-1)
    log_priors = np.log([probability for _, probability in components])
    with np.errstate(divide="ignore", invalid="ignore"):  # padded steps hold no summaries
        for dt, valid, data in steps:
            prior_mean, prior_cov = ncv_predict(
                mean[..., None, :], cov[..., None, :, :], np.asarray(dt)[..., None], intensities
            )
            if isinstance(data, PooledSummaries):
                data = PooledSummaries(*(np.asarray(field)[..., None] for field in data))
                log_likelihood = pooled_log_likelihood(
                    prior_mean[..., 0], prior_cov[..., 0, 0], data
                )
                step_means, step_covs = pooled_update(method, prior_mean, prior_cov, data)
            else:
                data = tuple(np.asarray(array)[..., None, :] for array in data)
                log_likelihood = step_log_likelihood(
                    prior_mean[..., 0], prior_cov[..., 0, 0], *data
                )
                step_means, step_covs = fused_update(method, prior_mean, prior_cov, *data)
            log_weights = log_priors + log_likelihood
            step_mean, step_cov = reduce_mixture(log_weights, step_means, step_covs)
            valid = np.asarray(valid)
            total = np.where(valid, total + np.logaddexp.reduce(log_weights, axis=-1), total)
            mean = np.where(valid[..., None], step_mean, mean)
            cov = np.where(valid[..., None, None], step_cov, cov)
    return total, mean, cov


def bcm_window_log_likelihood(
    dt: np.ndarray,
    valid: np.ndarray,
    pooled: PooledSummaries,
    mean: np.ndarray,
    cov: np.ndarray,
    q: np.ndarray,
    manoeuvre: Manoeuvre | None = None,
) -> np.ndarray:
    """The log likelihood of :func:`filter_steps` with BCM over a window of L pooled steps,
    the same numbers to the last bit, faster: the learning of q
    (:func:`agents.state_space_dgpt._learn_pooled`) filters a window at three trial points
    every step, and on arrays of a few dozen entries numpy's per-call overhead is the cost,
    several times higher when a call broadcasts. So the process-noise components lie on a
    leading axis of every array, the filtered state repeated on it; every array has one
    shape (the terms that do not depend on the state computed for all steps at once before
    the loop), and a sum over the two components is the array plus its reverse along that
    axis (x0 + x1 in both rows; a sum of two numbers does not depend on their order); the
    position and velocity terms, and the covariance's four, are stacked so that one call
    computes them all (elementwise, so each entry is still its own operations). Each
    entry is computed by the operations of :func:`ncv_predict`,
    :func:`pooled_log_likelihood`, :func:`pooled_update` and
    :func:`baselines.kalman.reduce_mixture`, in their order, so the result equals theirs
    (checked bit for bit in tests/test_agents/test_state_space.py).

    ``dt`` and ``valid`` (L, ...) and the fields of ``pooled`` (L, ...) are the steps' as
    :func:`filter_steps` takes them (a step where ``valid`` is False is skipped); ``mean``
    (..., 2) and ``cov`` (..., 2, 2) are the first step's prior. Each step's arrays and the
    prior broadcast to ``q``'s shape (..., 2) without extending it; at most two
    process-noise components (:func:`process_noise_components`); computed in float64.
    Returns the log likelihood (...) with ``q``'s shape (zeros for an empty window)."""
    q = np.asarray(q, dtype=float)
    shape = q.shape
    if not len(dt):
        return np.zeros(shape)
    components = process_noise_components(q, manoeuvre)
    count = len(components)
    state_shape = (count,) + shape
    full = (len(dt),) + state_shape

    def both(array):  # the sum over the components, in every component's row (the
        # components' axis is the first of the state's, after any stacked terms' axes)
        if count == 1:
            return array
        flipped = array[(slice(None),) * (array.ndim - len(state_shape)) + (slice(None, None, -1),)]
        return array + flipped

    def aligned(array, lead: int = 0):  # its last axes on q's, a component axis after lead
        array = np.asarray(array)
        missing = len(shape) + lead - array.ndim
        if missing < 0:
            raise ValueError(f"arrays must broadcast to q's shape {shape}; got {array.shape}")
        if missing:
            array = array.reshape(array.shape[:lead] + (1,) * missing + array.shape[lead:])
        return array[:, None] if lead else array[None]

    # the steps' data and dt, each on the full shape (one copy)
    data = np.empty((6,) + full)
    for row, array in enumerate((*pooled, dt)):  # assignments broadcast: no copies made first
        data[row] = aligned(array, 1)
    counts, precision, summary, residual, log_det, dt = data
    # the first step's prior: the filtered position and velocity stacked on a leading axis
    moments, covariance = np.empty((2,) + state_shape), np.empty((3,) + state_shape)
    for row, entry in enumerate((mean[..., 0], mean[..., 1])):
        moments[row] = aligned(entry)
    for row, entry in enumerate((cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1])):
        covariance[row] = aligned(entry)
    a, b, d = covariance
    valid = aligned(np.asarray(valid, dtype=bool), 1)
    every_valid = valid.reshape(len(valid), -1).all(axis=1)
    if not every_valid.all():
        valid = np.broadcast_to(valid, full)
    two_dt, dt_squared = 2.0 * dt, dt * dt
    # ncv_predict's process-noise terms, each component's intensity in its row
    intensity = np.empty(state_shape)
    for row, (component, _) in enumerate(components):
        intensity[row] = component
    var_noise, cross_noise = intensity * dt**3 / 3.0, intensity * dt**2 / 2.0
    velocity_noise = intensity * dt
    log_priors = np.zeros(state_shape) + np.log(
        [probability for _, probability in components]
    ).reshape((count,) + (1,) * len(shape))
    # the position and velocity terms stacked on a leading axis (and the covariance's on
    # two), so that one call computes both (or all four) entries with their own operations
    base, gains = np.empty((2,) + state_shape), np.empty((2,) + state_shape)
    block = np.empty((2, 2) + state_shape)  # the predicted covariance, then its update
    with np.errstate(divide="ignore", invalid="ignore"):  # padded steps hold no summaries
        summary_var = 1.0 / precision
        constant = counts * _LOG_2PI + log_det
        total = np.zeros(state_shape)
        for index in range(full[0]):
            step_dt = dt[index]
            position, velocity = moments
            predicted = np.add(position, step_dt * velocity, out=base[0])
            base[1] = velocity
            var = np.add(
                a + two_dt[index] * b + dt_squared[index] * d, var_noise[index], out=block[0, 0]
            )
            cross = np.add(b + step_dt * d, cross_noise[index], out=block[0, 1])
            block[1, 0] = cross
            np.add(d, velocity_noise[index], out=block[1, 1])
            innovation_var = var + summary_var[index]
            offset = summary[index] - predicted
            log_weights = log_priors + -0.5 * (
                constant[index]
                + np.log1p(var * precision[index])
                + residual[index]
                + offset**2 / innovation_var
            )
            if count == 2:
                step_log_likelihood = np.logaddexp(log_weights, log_weights[::-1])
            else:
                step_log_likelihood = log_weights
            weights = np.exp(log_weights - np.maximum(log_weights, log_weights[::-1]))
            weights = weights / both(weights)
            np.divide(block[0], innovation_var, out=gains)  # var and cross over it
            scaled = innovation_var * gains
            new = base + offset * gains
            weighed_new = weights * new
            mixed = both(weighed_new)
            spread = new - mixed
            weighed = weights * spread
            updated = weights * (block - scaled[:, None] * gains[None, :])
            spreads = weighed[:, None] * spread[None, :]
            cov_sum = both(updated) + both(spreads)
            cov_sum = 0.5 * (cov_sum + cov_sum.swapaxes(0, 1))
            if every_valid[index]:
                total = total + step_log_likelihood
                moments = mixed
                a, b, d = cov_sum[0, 0], cov_sum[0, 1], cov_sum[1, 1]
            else:
                keep = valid[index]
                total = np.where(keep, total + step_log_likelihood, total)
                moments = np.where(keep, mixed, moments)
                a, b, d = (
                    np.where(keep, cov_sum[0, 0], a),
                    np.where(keep, cov_sum[0, 1], b),
                    np.where(keep, cov_sum[1, 1], d),
                )
    return total[0]
