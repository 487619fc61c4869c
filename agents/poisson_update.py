"""The exact Poisson update of a Gaussian (mixture) prior of the target position: the
posterior under eq. (42)'s likelihood, or the environment's per-sensor form of it (paper
Sec. VI-A), as a Gaussian sum over which measurements are the target's, with its evidence.

The hybrid filter's exact variant (:mod:`agents.hybrid`) is this update of the DGPT's
prediction; the state-space DGPT (:mod:`agents.state_space_dgpt`) weighs its hypotheses at a
coverage gap's end by the evidence (:data:`agents.state_space_dgpt.GAP_END_EVIDENCE`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from agents.likelihood import PoissonLikelihood
from agents.silence import region_truncation

__all__ = [
    "exact_posterior",
    "gaussian_sums",
    "GaussianSumPosterior",
    "mixture_posterior",
    "MixturePosterior",
    "Region",
    "LOG_MASS_BEYOND_QUADRATURE",
]

Region = tuple[np.ndarray, np.ndarray, float, float]
"""Which sensors report, as :func:`agents.silence.reporting_region` takes it:
``(reporting_positions, silent_positions, sensing_range, area)``."""

LOG_MASS_BEYOND_QUADRATURE = float(np.log1p(-((1.0 - 2.0 * special.ndtr(-4.0)) ** 2)))
"""The log mass given to a prior's components when none of them has mass in the region on
a row of its box (:func:`agents.silence.region_truncation`): the mass outside a component's
+-4 standard-deviation box, 1 - (1 - 2 Phi(-4))^2 = 1.27e-4, which bounds theirs there
unless the region slips between the rows (a sliver thinner than the rows' spacing inside
the reporting discs' y extent)."""


@dataclass(frozen=True)
class GaussianSumPosterior:
    """Moments of the exact posterior and what the pruning dropped.

    ``pruned_mass`` estimates the total variation between the returned and the exact
    posterior mixture: the dropped components' weights, each relative to its prior's total
    when it was dropped. It is not a bound: the pruning is sequential, and a component
    dropped at one measurement is not restored when later ones favour it.
    ``log_evidence`` is the log of the prior's integral against the likelihood,
    int N(x; mu, diag(P)) prod_j (c + lambda_T N(z_j; x, sigma_z^2 I)) dx (per-sensor
    model: its factors), less the pruned components' share: what weighs one prior against
    another (:func:`mixture_posterior`).
    From :func:`gaussian_sums` every field has a leading axis, one entry per prior."""

    mean: np.ndarray
    var: np.ndarray
    n_components: int | np.ndarray
    pruned_mass: float | np.ndarray
    log_evidence: float | np.ndarray = 0.0


def exact_posterior(
    prior_mean: np.ndarray,
    prior_var: np.ndarray,
    measurements: np.ndarray,
    likelihood: PoissonLikelihood,
    prune_tolerance: float = 1e-9,
    max_components: int = 256,
    sensors: np.ndarray | None = None,
    region: Region | None = None,
) -> GaussianSumPosterior:
    """Posterior moments of N(x; mu, diag(P)) prod_j (c + lambda_T N(z_j; x, sigma_z^2 I)).

    Expanding the product, every subset S of target-originated measurements contributes a
    Gaussian component (a Kalman update of the prior with the measurements in S) with weight
    c^(n - |S|) lambda_T^|S| N(z_S; ...). A measurement whose target branches hold less
    than ``prune_tolerance`` of the prior's mass under its predictive (r / (1 + r), r the
    ratio of the target branch to the clutter branch) is skipped first as clutter (its
    share is added to ``pruned_mass``). The components are built one measurement at a time,
    each splitting into "clutter" (weight x c) and "target" (Kalman update, weight x
    lambda_T x predictive density); after each measurement, components below
    ``prune_tolerance`` of the total weight are dropped (and at most ``max_components``
    kept), their mass accumulated in ``pruned_mass``. The posterior mean and per-axis
    variance are the moments of the final mixture. The pruning is sequential: a point far
    from the prior whose evidence is decisive only together with later points (a prior far
    from the target) can be lost, which ``pruned_mass`` does not show.

    ``sensors`` (n,), the reporting sensor of each measurement, gives the environment's
    model (Sec. VI-A) instead of eq. (42)'s: a sensor reports only when it senses the target,
    and then at least one target point (a zero-truncated Poisson count), so each sensor's
    factor is prod_(j in i) (c + lambda_T N_j) - c^(n_i) and only the subsets S with a
    target point from every reporting sensor remain. The pre-gate's share is then of the
    sensor's factor, which has no all-clutter branch, so a sensor's likeliest point is never
    skipped. Within a sensor, the components with none of its points as the target's yet are
    exempt from the pruning and the cap (its later points need them); at its last point
    every component is pruned and capped. ``region`` adds the likelihood of which sensors
    report (:func:`gaussian_sums`).
    """
    result = gaussian_sums(
        np.asarray(prior_mean, dtype=float)[None, :],
        np.asarray(prior_var, dtype=float)[None, :],
        measurements,
        likelihood,
        prune_tolerance,
        max_components,
        sensors,
        region,
    )
    return GaussianSumPosterior(
        result.mean[0],
        result.var[0],
        int(result.n_components[0]),
        float(result.pruned_mass[0]),
        float(result.log_evidence[0]),
    )


def gaussian_sums(
    prior_means: np.ndarray,
    prior_vars: np.ndarray,
    measurements: np.ndarray,
    likelihood: PoissonLikelihood,
    prune_tolerance: float = 1e-9,
    max_components: int = 256,
    sensors: np.ndarray | None = None,
    region: Region | None = None,
) -> GaussianSumPosterior:
    """:func:`exact_posterior` of H priors at once, N(x; mu_h, diag(P_h)) (``prior_means``,
    ``prior_vars`` (H, 2)), under the same measurements: every field of the result has a
    leading axis H. The components of all priors are built in one pass over the
    measurements, each carrying its prior's index; a measurement that one prior's pre-gate
    skips splits only into its clutter branch there. Each prior's numbers are those of
    :func:`exact_posterior` alone, up to rounding.

    ``region`` (with ``sensors``: clutter only at the sensors that sense the target) adds the
    likelihood of which sensors report, the indicator of the region where exactly those
    sensors sense the target: each final component is cut to it
    (:func:`agents.silence.region_truncation`), its weight times its mass there, so the
    evidence and the moments are those of the whole likelihood. A prior none of whose
    components reaches the region keeps its components, each with
    :data:`LOG_MASS_BEYOND_QUADRATURE`."""
    noise_var = likelihood.noise_std**2
    log_clutter = np.log(likelihood.clutter_density) if likelihood.clutter_rate > 0 else -np.inf
    log_rate = np.log(likelihood.detection_rate)
    prior_means = np.asarray(prior_means, dtype=float)
    prior_vars = np.asarray(prior_vars, dtype=float)
    measurements = np.asarray(measurements, dtype=float)
    count = prior_means.shape[0]
    means, variances = prior_means.copy(), prior_vars.copy()
    owner = np.arange(count)  # each component's prior
    log_weights = np.zeros(count)
    log_scale = np.zeros(count)  # prior h's log weights are relative to exp(log_scale[h])
    pruned = np.zeros(count)
    groups = np.zeros(measurements.shape[0], dtype=np.int64) if sensors is None else sensors
    # Pre-gate: a measurement whose target branch is already negligible against a prior's
    # predictive (ratio to the clutter branch below the tolerance) can only be clutter for
    # every component of that prior: it multiplies their weights by the same c and is
    # skipped there. Its ratio is added to the prior's pruned mass.
    skipped = np.zeros((count, measurements.shape[0]), dtype=bool)
    if likelihood.clutter_rate > 0 and measurements.shape[0]:
        predictive = prior_vars[:, None, :] + noise_var
        log_ratio = (
            log_rate
            - log_clutter
            - 0.5
            * np.sum(
                (measurements - prior_means[:, None, :]) ** 2 / predictive
                + np.log(2.0 * np.pi * predictive),
                axis=-1,
            )
        )
        # eq. (42): each point's factor is c (1 + r_j), and its target branches hold the
        # share r_j / (1 + r_j) of the prior's mass
        log_factors = np.logaddexp(0.0, log_ratio)
        log_share = log_ratio - log_factors
        if sensors is not None:
            # the per-sensor model has no branch in which all of a sensor's points are
            # clutter: the sensor's factor is c^n (prod_k (1 + r_k) - 1), of which z_j's
            # target branches hold r_j / (1 + r_j) / (1 - 1 / prod_k (1 + r_k)). A sensor's
            # likeliest point holds at least about 1 / n of it, so it is never skipped.
            _, sensor_index = np.unique(groups, return_inverse=True)
            one_hot = sensor_index[:, None] == np.arange(sensor_index.max() + 1)
            log_products = (log_factors @ one_hot)[:, sensor_index]
            with np.errstate(divide="ignore"):  # a product of 1 (every r_k underflows): keep
                log_share = log_share - np.log(-np.expm1(-log_products))
        skipped = log_share < (np.log(prune_tolerance) if prune_tolerance > 0 else -np.inf)
        pruned = np.sum(np.where(skipped, np.exp(log_share), 0.0), axis=1)
        log_scale += skipped.sum(axis=1) * log_clutter
        everywhere = skipped.all(axis=0)
        measurements, groups, skipped = (
            measurements[~everywhere],
            groups[~everywhere],
            skipped[:, ~everywhere],
        )
    order = np.argsort(groups, kind="stable")
    measurements, groups, skipped = measurements[order], groups[order], skipped[:, order]
    # last[h, j]: z_j is the last point of its sensor that prior h does not skip, where the
    # per-sensor model drops h's components with no target point of that sensor; it and
    # has_target serve that model only (eq. (42) without sensors needs neither)
    last = np.zeros(skipped.shape, dtype=bool)
    if sensors is not None:
        for prior, row in enumerate(skipped):
            kept = np.flatnonzero(~row)
            if kept.size:
                last[prior, kept[np.r_[groups[kept][1:] != groups[kept][:-1], True]]] = True
    has_target = np.zeros(count, dtype=bool)  # per component: a target point of this sensor
    any_skipped = skipped.any(axis=0)
    for index, z in enumerate(measurements):
        split, clutter = slice(None), log_clutter  # the components z may be the target of
        if any_skipped[index]:
            gated = skipped[owner, index]  # z is clutter for this component's prior
            split = np.flatnonzero(~gated)
            clutter = np.where(gated, 0.0, log_clutter)  # skipped: already in the scale
        split_means, split_vars = means[split], variances[split]
        predictive_var = split_vars + noise_var
        residual = z - split_means
        terms = residual**2 / predictive_var + np.log(2.0 * np.pi * predictive_var)
        log_target = log_rate - 0.5 * (terms[:, 0] + terms[:, 1])
        gain = split_vars / predictive_var
        means = np.concatenate([means, split_means + gain * residual])
        variances = np.concatenate([variances, (1.0 - gain) * split_vars])
        log_weights = np.concatenate([log_weights + clutter, log_weights[split] + log_target])
        owner = np.concatenate([owner, owner[split]])
        valid = pending = None  # eq. (42): every component valid, none pending
        if sensors is not None:
            has_target = np.concatenate([has_target, np.ones(residual.shape[0], dtype=bool)])
            # the model has no "all of this sensor's points are clutter"
            ends = last[owner, index]
            valid = has_target | ~ends
            has_target = has_target & ~ends
            # Within a sensor, the components with none of its points as the target's yet
            # are kept whatever their weight (they branch into its later points) and are
            # not the reference of the pruning: they are dropped at its last point. There
            # every valid component has one of the sensor's points as the target's, and all
            # are pruned against their total before they enter the next sensor.
            pending = valid & ~has_target & ~ends
        valid_log_weights = log_weights if valid is None else log_weights[valid]
        if count == 1:
            largest = np.array([np.max(valid_log_weights)])
        else:
            largest = np.full(count, -np.inf)
            np.maximum.at(largest, owner if valid is None else owner[valid], valid_log_weights)
            largest = np.where(np.isfinite(largest), largest, 0.0)
        log_weights -= largest[owner]
        log_scale += largest
        if valid is None:
            weights = np.exp(log_weights)
        else:
            weights = np.zeros(log_weights.size)
            weights[valid] = np.exp(log_weights[valid])  # the invalid may lie far above
        total = np.bincount(owner, weights, minlength=count)
        if valid is None:
            keep = weights >= prune_tolerance * total[owner]
        else:
            settled = valid & ~pending
            reference = np.where(
                np.bincount(owner, settled, minlength=count) > 0,
                np.bincount(owner, np.where(settled, weights, 0.0), minlength=count),
                total,
            )
            keep = valid & ((weights >= prune_tolerance * reference[owner]) | pending)
        # the cap: a prior's heaviest max_components of the components it may drop (the
        # pending ones excepted, which its later points need)
        capped = keep if pending is None else keep & ~pending
        if np.count_nonzero(capped) > max_components:
            for prior in np.flatnonzero(
                np.bincount(owner[capped], minlength=count) > max_components
            ):
                own = np.flatnonzero(capped & (owner == prior))
                lightest = np.argsort(weights[own], kind="stable")[:-max_components]
                keep[own[lightest]] = False
        dropped = np.bincount(owner, np.where(keep, 0.0, weights), minlength=count)
        pruned = pruned + (1.0 - pruned) * dropped / np.where(total > 0, total, 1.0)
        means, variances, log_weights = means[keep], variances[keep], log_weights[keep]
        owner = owner[keep]
        if sensors is not None:
            has_target = has_target[keep]
    if region is not None:
        log_mass, means, variances = region_truncation(means, variances, *region)
        reached = np.bincount(owner, np.isfinite(log_mass), minlength=count) > 0
        log_mass = np.where(reached[owner], log_mass, LOG_MASS_BEYOND_QUADRATURE)
        log_weights = log_weights + log_mass
        largest = np.full(count, -np.inf)
        np.maximum.at(largest, owner, log_weights)
        log_weights -= largest[owner]
        log_scale += largest
    weights = np.exp(log_weights)  # each prior's largest kept is at most 1: no overflow
    total = np.bincount(owner, weights, minlength=count)
    weights /= total[owner]
    mean = np.stack([np.bincount(owner, weights * means[:, a], minlength=count) for a in (0, 1)], 1)
    spread = variances + (means - mean[owner]) ** 2
    var = np.stack([np.bincount(owner, weights * spread[:, a], minlength=count) for a in (0, 1)], 1)
    return GaussianSumPosterior(
        mean,
        var,
        np.bincount(owner, minlength=count),
        pruned,
        log_scale + np.log(total),
    )


@dataclass(frozen=True)
class MixturePosterior:
    """The exact posterior under a Gaussian-mixture prior: per prior component h its
    posterior probability (``log_weights`` (H,), normalised) and the moments of its own
    posterior (``means``, ``vars`` (H, 2)); the mixture's moments (``mean``, ``var`` (2,));
    and the dropped mass, the components' ``pruned_mass`` weighted by their probabilities
    (an estimate of the mixture's: the weights come from evidences less their pruned
    shares, so it is not a bound)."""

    log_weights: np.ndarray
    means: np.ndarray
    vars: np.ndarray
    mean: np.ndarray
    var: np.ndarray
    pruned_mass: float


def mixture_posterior(
    log_priors: np.ndarray,
    prior_means: np.ndarray,
    prior_vars: np.ndarray,
    measurements: np.ndarray,
    likelihood: PoissonLikelihood,
    prune_tolerance: float = 1e-9,
    sensors: np.ndarray | None = None,
    region: Region | None = None,
) -> MixturePosterior:
    """The exact posterior of the prior sum_h pi_h N(x; mu_h, diag(P_h)) (``log_priors``
    (H,), ``prior_means`` and ``prior_vars`` (H, 2)) under the measurement model of
    :func:`exact_posterior`: each component's posterior is its :func:`exact_posterior`,
    and its probability is pi_h times its evidence, normalised. The state-space DGPT's
    prediction is such a mixture (its IMM modes and process-noise components); the hybrid
    updates each component, so a component that the measurements favour (a manoeuvre, a
    turn) gains weight instead of the measurements being explained as clutter around the
    collapsed prior. ``region`` adds the likelihood of which sensors report
    (:func:`gaussian_sums`)."""
    posteriors = gaussian_sums(
        prior_means,
        prior_vars,
        measurements,
        likelihood,
        prune_tolerance,
        sensors=sensors,
        region=region,
    )
    log_weights = np.asarray(log_priors, dtype=float) + posteriors.log_evidence
    log_weights = log_weights - np.logaddexp.reduce(log_weights)
    weights = np.exp(log_weights)
    mean = weights @ posteriors.mean
    var = weights @ (posteriors.var + (posteriors.mean - mean) ** 2)
    pruned = float(weights @ posteriors.pruned_mass)
    return MixturePosterior(log_weights, posteriors.mean, posteriors.var, mean, var, pruned)
