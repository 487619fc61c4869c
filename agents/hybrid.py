"""The hybrid Bayesian filter (paper Sec. VI): DGPT's next-step prediction is the prior of the
target position, eq. (48), and the Poisson measurement likelihood, eq. (42), updates it.
The DGPT is the paper's (:class:`agents.dgpt.DGPT`, ``gp="se"``) or the NCV GP in
state-space form (:class:`agents.state_space_dgpt.StateSpaceDGPT`, ``gp="ncv"``), whose
broadcast state then becomes its prior conditioned on the posterior position.

Two updates, per step:

- :func:`paper_posterior` (``variant="paper"``): the closed form of eqs. (50)-(51), per
  coordinate, exactly as printed. It treats every measurement as a Gaussian observation
  with mean lambda_c / A_sen + lambda_T x and variance (lambda_T sigma_z)^2 (eq. (44); Appendix C
  uses this per-factor variance, which eq. (45) writes with the same symbol as the product's
  (lambda_T sigma_z)^2 / n_t), so clutter pulls the estimate like any measurement. The
  closed form presumes lambda_T = 1 (the paper's setting): for other rates its mean tends to
  mean(z) / lambda_T, a scaled position, and the filter warns once.
- :func:`exact_posterior` (``variant="exact"``): the exact posterior with the Gaussian prior,
  a Gaussian sum over which measurements are target-originated. By default
  (``scan_model="per-sensor"``) the measurement model is the environment's (Sec. VI-A): eq.
  (42)'s factors per measurement, but a reporting sensor senses the target and so reports
  at least one target point, which removes every term in which all of a sensor's points are
  clutter; ``scan_model="eq42"`` is eq. (42) as printed. The sum is built measurement by
  measurement; components whose relative weight falls below ``prune_tolerance`` are
  dropped and their total weight is returned, so the result is exact up to that reported
  mass (measured against a fine 2-D grid in the tests). See :data:`SCAN_MODELS` and
  :data:`REACQUIRE_RULES` for how the defaults were chosen. Around the state-space DGPT the
  prior is its prediction as it is, a Gaussian mixture over its IMM modes and process-noise
  components, each updated exactly and weighted by its evidence (:func:`mixture_posterior`,
  :data:`PRIOR_MODELS`); in a coverage gap that the DGPT's silence particles carry, the
  estimate is the DGPT's, and at the gap's end the mixture prior is the DGPT's predictions
  there: its particles where the reports put the target, and a new track
  (:data:`agents.state_space_dgpt.GAP_ENDS`; ``prior_model="moments"`` takes the
  prediction made at the gap's last step).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agents import aggregation as agg
from agents.dgpt import DGPT
from agents.likelihood import PoissonLikelihood
from agents.state_space_dgpt import StateSpaceDGPT
from dgpt_gym.problem import ProblemSpec
from dgpt_gym.tracker import Estimate, TrackerBase
from dgpt_gym.validation import check_choice, check_real

__all__ = [
    "HybridFilter",
    "paper_posterior",
    "exact_posterior",
    "gaussian_sums",
    "GaussianSumPosterior",
    "mixture_posterior",
    "MixturePosterior",
    "PRIOR_MODELS",
    "VARIANTS",
    "SCAN_MODELS",
    "GP_MODELS",
]

VARIANTS = ("exact", "paper")
SCAN_MODELS = ("eq42", "per-sensor")
"""The exact variant's measurement model: eq. (42) over all measurements, or the
environment's, in which every reporting sensor has at least one target point
(:func:`exact_posterior` with ``sensors``). On training seeds 1000-1005 (S1-S4, clutter 1 and
5, fixed and random paths; ``python scripts/model_study.py --candidates hybrid-trend
hybrid-per-sensor hybrid-ncv hybrid-ncv-per-sensor``; in model_study's names, ``hybrid-ncv``
is the hybrid around the state-space model), "per-sensor" lowered the mean RMSE
around both GP models (SE: 17.19 / 22.99 to 16.44 / 22.42 m, fixed / random paths; NCV:
13.14 / 21.16 to 12.60 / 19.87 m) and raised the median NEES on sensed steps towards its
nominal 1.39 (0.83 to 1.18 and 0.78 to 1.16): eq. (42) lets every sensor's points all be
clutter, so it trusts the agreement between sensors too little."""
GP_MODELS = {"se": DGPT, "ncv": StateSpaceDGPT}
"""The DGPT the filter wraps: the paper's SE model, or the NCV GP in state-space form."""
PRIOR_MODELS = ("mixture", "moments")
"""The exact variant's prior around the state-space DGPT (``gp="ncv"``): ``"mixture"``, the
DGPT's prediction as it is, one Gaussian per IMM mode and process-noise component
(:func:`mixture_posterior`; each component's state is then conditioned on its own posterior,
:meth:`agents.state_space_dgpt.StateSpaceDGPT.set_posterior`), or ``"moments"``, that
mixture's single moment-matched Gaussian (0.9.0-0.13.0). The SE DGPT's prediction and the
paper variant's prior are one Gaussian: ``"moments"``.

Chosen on training seeds 1000-1011 (S1-S4, clutter 1 and 5, fixed and random paths; ``python
scripts/model_study.py --seeds 12 --clutter-rates 1 5 --candidates hybrid-ncv-moments
hybrid-ncv --paired-against hybrid-ncv-moments``): RMSE 8.09 / 17.31 m against 9.75 / 18.13 m
(fixed / random paths), paired -1.65 +- 0.56 / -0.82 +- 0.63 m, and 3-sigma coverage on
detected steps 99.66 against 99.21 %; at sigma_z = 4 (``--noise-std 4``) 13.42 / 20.52
against 14.33 / 20.91 m. Under ``"moments"`` the manoeuvre component (probability 0.02,
400 m^2/s^3) is folded into a prior a few metres wide; when the target turns sharply (S4),
the points it reports lie many prior standard deviations off, the Gaussian sum explains them
as clutter and settles on clutter near the prior with a standard deviation of about 1 m,
while the DGPT's own update, which weighs its hypotheses by their likelihood, stays with the
target. The mixture costs one Gaussian sum per prediction (four with the turn modes), built
in one pass (:func:`gaussian_sums`): the hybrid's step took 1.5-2.2 ms in the 0.14.0 grid,
against 1.1-1.4 ms with the moments in 0.13.0's."""
REACQUIRE_RULES = ("dgpt", "none")
"""What the exact variant does at the first step with measurements after steps without any
(a coverage gap): ``"dgpt"`` answers with the DGPT's own estimate, ``"none"`` applies the
Poisson update to the extrapolated prior as at every other step (the default).

Under eq. (42) ``"dgpt"`` was needed: on training seeds 1000-1019 (16 cells) it lowered the
hybrid's mean RMSE in all 16 (e.g. S4, clutter 5: 23.65 to 19.57 m), because eq. (42) lets
a far prior explain the sensors' points as clutter and moves only part of the way. The
per-sensor model (:data:`SCAN_MODELS`) does not allow that (a reporting sensor's points
include the target's), and with it ``"none"`` is as good or better on training seeds
1000-1005 (``--candidates hybrid-per-sensor hybrid-per-sensor-reacquire-none
hybrid-ncv-per-sensor hybrid-ncv-per-sensor-reacquire-none``): SE 16.44 / 22.42 against
16.34 / 22.37 m, NCV 12.60 / 19.87 against 12.33 / 19.51 m (fixed / random paths)."""


def paper_posterior(
    prior_mean: np.ndarray,
    prior_var: np.ndarray,
    measurements: np.ndarray,
    likelihood: PoissonLikelihood,
) -> tuple[np.ndarray, np.ndarray]:
    """Eqs. (50)-(51), per coordinate: with s^2 = (lambda_T sigma_z)^2 and n measurements,

        mu_t      = (mu_{t-1} s^2 + sigma_{t-1}^2 sum_j (lambda_T z_j - lambda_T lambda_c / A_sen))
                    / (s^2 + n sigma_{t-1}^2 lambda_T^2)
        sigma_t^2 = s^2 sigma_{t-1}^2 / (s^2 + n sigma_{t-1}^2 lambda_T^2).

    ``prior_mean``, ``prior_var`` (2,); ``measurements`` (n, 2). No measurement: the prior.
    """
    n = measurements.shape[0]
    rate = likelihood.detection_rate
    s2 = (rate * likelihood.noise_std) ** 2
    numerator = prior_mean * s2 + prior_var * np.sum(
        rate * measurements - rate * likelihood.clutter_density, axis=0
    )
    denominator = s2 + n * prior_var * rate**2
    return numerator / denominator, s2 * prior_var / denominator


@dataclass(frozen=True)
class GaussianSumPosterior:
    """Moments of the exact posterior and what the pruning dropped.

    ``pruned_mass`` bounds the total variation between the returned and the exact posterior
    mixture (relative weight of the dropped components). ``log_evidence`` is the log of the
    prior's integral against the likelihood, int N(x; mu, diag(P)) prod_j (c + lambda_T
    N(z_j; x, sigma_z^2 I)) dx (per-sensor model: its factors), less the pruned
    components' share: what weighs one prior against another (:func:`mixture_posterior`).
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
) -> GaussianSumPosterior:
    """Posterior moments of N(x; mu, diag(P)) prod_j (c + lambda_T N(z_j; x, sigma_z^2 I)).

    Expanding the product, every subset S of target-originated measurements contributes a
    Gaussian component (a Kalman update of the prior with the measurements in S) with weight
    c^(n - |S|) lambda_T^|S| N(z_S; ...). Measurements whose target branch is below
    ``prune_tolerance`` of the clutter branch under the prior predictive are skipped first
    (their branch ratios are added to ``pruned_mass``). The components are built one measurement at a time,
    each splitting into "clutter" (weight x c) and "target" (Kalman update, weight x
    lambda_T x predictive density); after each measurement, components below
    ``prune_tolerance`` of the total weight are dropped (and at most ``max_components``
    kept), their mass accumulated in ``pruned_mass``. The posterior mean and per-axis
    variance are the moments of the final mixture.

    ``sensors`` (n,), the reporting sensor of each measurement, gives the environment's
    model (Sec. VI-A) instead of eq. (42)'s: a sensor reports only when it senses the target,
    and then at least one target point (a zero-truncated Poisson count), so each sensor's
    factor is prod_(j in i) (c + lambda_T N_j) - c^(n_i) and only the subsets S with a
    target point from every reporting sensor remain. The pre-gate then keeps every
    measurement of a sensor none of whose measurements passes it.
    """
    result = gaussian_sums(
        np.asarray(prior_mean, dtype=float)[None, :],
        np.asarray(prior_var, dtype=float)[None, :],
        measurements,
        likelihood,
        prune_tolerance,
        max_components,
        sensors,
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
) -> GaussianSumPosterior:
    """:func:`exact_posterior` of H priors at once, N(x; mu_h, diag(P_h)) (``prior_means``,
    ``prior_vars`` (H, 2)), under the same measurements: every field of the result has a
    leading axis H. The components of all priors are built in one pass over the
    measurements, each carrying its prior's index; a measurement that one prior's pre-gate
    skips splits only into its clutter branch there. Each prior's numbers are those of
    :func:`exact_posterior` alone, up to rounding."""
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
        skipped = log_ratio < (np.log(prune_tolerance) if prune_tolerance > 0 else -np.inf)
        if sensors is not None:  # a sensor's target point is among its measurements
            for row in skipped:
                row &= np.isin(groups, groups[~row])
        pruned = np.sum(np.where(skipped, np.exp(log_ratio), 0.0), axis=1)
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
    # per-sensor model drops h's components with no target point of that sensor
    last = np.zeros(skipped.shape, dtype=bool)
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
        log_target = log_rate - 0.5 * np.sum(
            residual**2 / predictive_var + np.log(2.0 * np.pi * predictive_var), axis=1
        )
        gain = split_vars / predictive_var
        means = np.concatenate([means, split_means + gain * residual])
        variances = np.concatenate([variances, (1.0 - gain) * split_vars])
        log_weights = np.concatenate([log_weights + clutter, log_weights[split] + log_target])
        owner = np.concatenate([owner, owner[split]])
        has_target = np.concatenate([has_target, np.ones(residual.shape[0], dtype=bool)])
        valid = pending = None  # eq. (42): every component valid, none pending
        if sensors is not None:
            # the model has no "all of this sensor's points are clutter"
            ends = last[owner, index]
            valid = has_target | ~ends
            has_target = has_target & ~ends
            # Within a sensor, the components with none of its points as the target's yet
            # are kept whatever their weight (they branch into its later points) and are
            # not the reference of the pruning: they are dropped at its last point.
            pending = valid & ~has_target
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
        if np.count_nonzero(keep) > max_components:
            for prior in np.flatnonzero(np.bincount(owner[keep], minlength=count) > max_components):
                own = keep & (owner == prior)
                threshold = np.sort(weights[own])[-max_components]
                keep &= (owner != prior) | (weights >= threshold)
                if pending is not None:
                    keep |= pending & (owner == prior)
        dropped = np.bincount(owner, np.where(keep, 0.0, weights), minlength=count)
        pruned = pruned + (1.0 - pruned) * dropped / np.where(total > 0, total, 1.0)
        means, variances, log_weights = means[keep], variances[keep], log_weights[keep]
        owner, has_target = owner[keep], has_target[keep]
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
) -> MixturePosterior:
    """The exact posterior of the prior sum_h pi_h N(x; mu_h, diag(P_h)) (``log_priors``
    (H,), ``prior_means`` and ``prior_vars`` (H, 2)) under the measurement model of
    :func:`exact_posterior`: each component's posterior is its :func:`exact_posterior`,
    and its probability is pi_h times its evidence, normalised. The state-space DGPT's
    prediction is such a mixture (its IMM modes and process-noise components); the hybrid
    updates each component, so a component that the measurements favour (a manoeuvre, a
    turn) gains weight instead of the measurements being explained as clutter around the
    collapsed prior."""
    posteriors = gaussian_sums(
        prior_means, prior_vars, measurements, likelihood, prune_tolerance, sensors=sensors
    )
    log_weights = np.asarray(log_priors, dtype=float) + posteriors.log_evidence
    log_weights = log_weights - np.logaddexp.reduce(log_weights)
    weights = np.exp(log_weights)
    mean = weights @ posteriors.mean
    var = weights @ (posteriors.var + (posteriors.mean - mean) ** 2)
    pruned = float(weights @ posteriors.pruned_mass)
    return MixturePosterior(log_weights, posteriors.mean, posteriors.var, mean, var, pruned)


_paper_variant_warned = False


def _warn_paper_variant_once(detection_rate: float) -> None:
    global _paper_variant_warned
    if not _paper_variant_warned:
        _paper_variant_warned = True
        warnings.warn(
            f"hybrid variant='paper' with detection_rate={detection_rate:g}: eqs. (50)-(51) "
            "are exact only for lambda_T = 1 (the paper's setting); otherwise their mean tends "
            "to mean(z) / lambda_T. Use variant='exact' for other rates.",
            UserWarning,
            stacklevel=3,
        )


class HybridFilter(TrackerBase):
    """Hybrid Bayesian filter (Sec. VI) composed of a DGPT tracker and a Poisson update.

    Each step the prior is the DGPT's prediction for this step made at the previous one
    (eq. (48); with ``gp="ncv"`` and the exact variant, the mixture of its predictions,
    :data:`PRIOR_MODELS`); the step's measurements update it under the Poisson likelihood
    (eq. (42)), with the closed form of eqs. (50)-(51) (``variant="paper"``) or the exact
    posterior (``variant="exact"``). The posterior is the estimate, and it is fed back to
    the DGPT as its estimate of the step (the spatial input of STGP; with ``gp="ncv"``, the
    state the tracker broadcasts and predicts from). The first step of a track (the
    episode's first, or, with clutter at every sensor, one the state-space DGPT restarts
    from the step's points), which has no prediction to update, and a step on which the
    state-space DGPT made no prediction (a coverage gap carried by its silence particles,
    ``silence_particles`` > 0, as in the registered ``hybrid``) return the DGPT's estimate.
    The bound is Lemma 1 on the posterior, (2 log(1 / delta))^(1/2) sigma_t; with the
    mixture prior, the bound of the posterior's mixture over the prior's components
    (:func:`agents.aggregation.mixture_half_width`: Lemma 1 on each component with its
    share of delta), since the mixture's moments are not a Gaussian's.

    Args:
        variant: ``"exact"`` or ``"paper"``.
        delta: failure probability of the bound, in (0, 1).
        prune_tolerance: relative weight below which exact-posterior components are dropped.
        reacquire: what the exact variant does after a coverage gap (:data:`REACQUIRE_RULES`).
        gp: the wrapped DGPT, ``"ncv"`` (the default; with RBCM unless ``aggregation`` is
            given, as ``hybrid``) or ``"se"`` (:data:`GP_MODELS`; ``hybrid-trend``).
        scan_model: the exact variant's measurement model (:data:`SCAN_MODELS`); with
            ``clutter_sensors="all"`` a reporting sensor need not sense the target, and eq.
            (42) is used.
        prior_model: the exact variant's prior around ``gp="ncv"`` (:data:`PRIOR_MODELS`);
            None: ``"mixture"`` there, ``"moments"`` otherwise (the only choice).
        **dgpt_kwargs: arguments of the wrapped tracker (aggregation, window,
            silence_particles, ...).
    """

    name = "hybrid"

    def __init__(
        self,
        variant: str = "exact",
        delta: float = 0.003,
        prune_tolerance: float = 1e-9,
        reacquire: str = "none",
        gp: str = "ncv",
        scan_model: str = "per-sensor",
        prior_model: str | None = None,
        **dgpt_kwargs,
    ) -> None:
        self.variant = check_choice("variant", variant, VARIANTS)
        self.reacquire = check_choice("reacquire", reacquire, REACQUIRE_RULES)
        self.delta = check_real(
            "delta", delta, low=0.0, high=1.0, low_inclusive=False, high_inclusive=False
        )
        self.prune_tolerance = check_real("prune_tolerance", prune_tolerance, low=0.0, high=1.0)
        self.scan_model = check_choice("scan_model", scan_model, SCAN_MODELS)
        self.gp = check_choice("gp", gp, GP_MODELS)
        if self.gp == "ncv":  # the registered ``hybrid`` wraps ``dgpt-rbcm``'s model
            dgpt_kwargs.setdefault("aggregation", "rbcm")
        mixture_allowed = self.gp == "ncv" and self.variant == "exact"
        if prior_model is None:
            prior_model = "mixture" if mixture_allowed else "moments"
        self.prior_model = check_choice("prior_model", prior_model, PRIOR_MODELS)
        if self.prior_model == "mixture" and not mixture_allowed:
            raise ValueError(
                "prior_model: 'mixture' needs variant='exact' and gp='ncv' (the SE DGPT "
                "predicts one Gaussian, and eqs. (50)-(51) take one); got variant="
                f"{self.variant!r}, gp={self.gp!r}"
            )
        self.dgpt = GP_MODELS[self.gp](delta=delta, **dgpt_kwargs)
        inputs = self.dgpt.inputs if self.gp == "se" else "ncv"
        self.name = f"hybrid-{self.variant}-{self.dgpt.aggregation}-{inputs}"

    @property
    def silence_particles(self) -> int:
        """The wrapped DGPT's particles in coverage gaps (0: it does not use the silence)."""
        return getattr(self.dgpt, "silence_particles", 0)

    def reset(self, spec: ProblemSpec, seed: int | None = None) -> None:
        if self.variant == "paper" and spec.detection_rate != 1.0:
            _warn_paper_variant_once(spec.detection_rate)
        self.spec_ = spec
        self.dgpt.reset(spec, seed)
        self.likelihood_ = PoissonLikelihood.from_spec(spec)
        self.pruned_mass_ = 0.0
        self.silent_steps_ = 0  # consecutive steps without measurements, up to the last

    def update(self, obs: dict) -> Estimate:
        return self.update_batch([self], [obs])[0]

    def diagnostics(self) -> dict[str, float]:
        """Those of the wrapped DGPT (its fit's ``share_at_bound``)."""
        return self.dgpt.diagnostics()

    @classmethod
    def update_batch(
        cls, trackers: Sequence[HybridFilter], observations: Sequence[dict]
    ) -> list[Estimate]:
        """One step of many episodes in lockstep: the wrapped DGPTs of each kind step
        together (their ``update_batch``, exact per episode), then each episode's Poisson
        update runs on its own."""
        for tracker in trackers:
            if tracker.spec_ is None:
                raise RuntimeError("call reset(spec) before update(obs)")
        priors = [tracker.dgpt.prior_next_ for tracker in trackers]
        learned: list[Estimate | None] = [None] * len(trackers)
        for model in {type(tracker.dgpt) for tracker in trackers}:
            indices = [i for i, tracker in enumerate(trackers) if type(tracker.dgpt) is model]
            estimates = model.update_batch(
                [trackers[i].dgpt for i in indices], [observations[i] for i in indices]
            )
            for i, estimate in zip(indices, estimates):
                learned[i] = estimate
        return [
            tracker._posterior(obs, prior, estimate)
            for tracker, obs, prior, estimate in zip(trackers, observations, priors, learned)
        ]

    def _posterior(self, obs: dict, prior, learned: Estimate) -> Estimate:
        """The Poisson update of ``prior`` (the DGPT's prediction of this step) by the step's
        measurements, fed back to the DGPT; ``learned`` (the DGPT's estimate) at the first
        step, which has no prior."""
        mask = np.asarray(obs["mask"]).astype(bool)
        measurements = np.asarray(obs["measurements"], dtype=float)[mask]
        reacquiring = self.silent_steps_ > 0 and measurements.shape[0] > 0
        self.silent_steps_ = 0 if measurements.shape[0] else self.silent_steps_ + 1
        if prior is None:
            return learned
        if self.gp == "ncv" and (self.dgpt.step_predictions_ is None or self.dgpt.new_track_):
            # No prediction to update: the DGPT's particles carry a coverage gap
            # (silence_particles > 0) and its estimate is their posterior given the sensors'
            # silence (with clutter at every sensor, given every scan, none of which its
            # screen admitted), or, before a track, the scans' posterior; or the DGPT has
            # just started a track from this step's points (with clutter at every sensor,
            # after its screen dropped the old one), which the last prediction does not hold.
            return learned
        if reacquiring and self.variant == "exact" and self.reacquire == "dgpt":
            # After a gap the prior is an extrapolation that may lie tens of metres off, and
            # the Poisson update of a narrow far prior by a few measurements moves it only
            # part of the way; the DGPT, refitted on the new data, has already moved.
            return learned
        if self.variant == "paper":
            mean, var = paper_posterior(prior[0], prior[1], measurements, self.likelihood_)
            prior_next = self.dgpt.set_estimate(mean, var)
        else:
            # with clutter at every sensor a reporting sensor need not sense the target
            per_sensor = self.scan_model == "per-sensor" and self.spec_.clutter_sensors != "all"
            sensors = np.asarray(obs["sensor"])[mask] if per_sensor else None
            if self.prior_model == "mixture":
                log_priors, state_means, state_covs, _ = self.dgpt.step_predictions_
                result = mixture_posterior(
                    log_priors,
                    state_means[..., 0],
                    state_covs[..., 0, 0],
                    measurements,
                    self.likelihood_,
                    self.prune_tolerance,
                    sensors=sensors,
                )
                prior_next = self.dgpt.set_posterior(result.log_weights, result.means, result.vars)
                bound = agg.mixture_half_width(
                    np.exp(result.log_weights),
                    result.means - result.mean,
                    np.sqrt(result.vars),
                    self.delta,
                )
            else:
                result = exact_posterior(
                    prior[0],
                    prior[1],
                    measurements,
                    self.likelihood_,
                    self.prune_tolerance,
                    sensors=sensors,
                )
                prior_next = self.dgpt.set_estimate(result.mean, result.var)
            mean, var = result.mean, result.var
            self.pruned_mass_ = max(self.pruned_mass_, result.pruned_mass)
        if self.prior_model == "moments":
            bound = np.sqrt(2.0 * np.log(1.0 / self.delta) * var)
        return Estimate(mean, var, bound, prior_next)
