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
- :func:`agents.poisson_update.exact_posterior` (``variant="exact"``): the exact posterior
  with the Gaussian prior, a Gaussian sum over which measurements are target-originated. By default
  (``scan_model="per-sensor"``) the measurement model is the environment's (Sec. VI-A): eq.
  (42)'s factors per measurement, but a reporting sensor senses the target and so reports
  at least one target point, which removes every term in which all of a sensor's points are
  clutter; ``scan_model="eq42"`` is eq. (42) as printed. The sum is built measurement by
  measurement; components whose relative weight falls below ``prune_tolerance`` are
  dropped, at most 256 are kept per prior component, and the dropped weight is returned
  (``pruned_mass_``, the largest of the episode): an estimate of what the pruning lost, not
  a bound, since a component dropped at one measurement is not restored when later ones
  favour it (checked against the enumeration of every subset and a fine 2-D grid in the
  tests). See :data:`SCAN_MODELS` and
  :data:`REACQUIRE_RULES` for how the defaults were chosen. Around the state-space DGPT the
  prior is its prediction as it is, a Gaussian mixture over its IMM modes and process-noise
  components, each updated exactly and weighted by its evidence
  (:func:`~agents.poisson_update.mixture_posterior`,
  :data:`PRIOR_MODELS`); in a coverage gap that the DGPT's silence particles carry, the
  estimate is the DGPT's, and at the gap's end the mixture prior is the DGPT's predictions
  there: its particles where the reports put the target, and a new track over the
  region's cells (:data:`agents.state_space_dgpt.GAP_ENDS`,
  :data:`~agents.state_space_dgpt.GAP_REGION_CELL`; ``prior_model="moments"`` takes the
  prediction made at the gap's last step).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from agents import aggregation as agg
from agents.dgpt import DGPT
from agents.likelihood import PoissonLikelihood
from agents.poisson_update import exact_posterior, mixture_posterior
from agents.silence import reporting_and_silent
from agents.state_space_dgpt import StateSpaceDGPT
from dgpt_gym.problem import ProblemSpec
from dgpt_gym.tracker import Estimate, TrackerBase
from dgpt_gym.validation import check_choice, check_real

__all__ = [
    "HybridFilter",
    "paper_posterior",
    "PRIOR_MODELS",
    "VARIANTS",
    "SCAN_MODELS",
    "GP_MODELS",
    "REPORTING_REGION",
]

VARIANTS = ("exact", "paper")
SCAN_MODELS = ("eq42", "per-sensor")
"""The exact variant's measurement model: eq. (42) over all measurements, or the
environment's, in which every reporting sensor has at least one target point
(:func:`~agents.poisson_update.exact_posterior` with ``sensors``). On training seeds 1000-1005
(S1-S4, clutter 1 and
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
(:func:`~agents.poisson_update.mixture_posterior`; each component's state is then
conditioned on its own posterior,
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
in one pass (:func:`~agents.poisson_update.gaussian_sums`): the hybrid's step took 1.5-2.2 ms
in the 0.14.0 grid,
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


REPORTING_REGION = True
"""The exact variant's default for ``reporting_region``. With clutter only at the sensors
that sense the target and a zero-truncated target count (Sec. VI-A), a sensor reports
exactly when the target lies in its disc, so the likelihood of a step holds, beside the
measurements' factors, the indicator of the region inside every reporting disc and outside
every other awake one (:func:`agents.silence.reporting_region`). ``True`` cuts each
component of the Gaussian sum to that region and weighs it by its mass there
(:func:`agents.poisson_update.gaussian_sums` with ``region``). Neither the DGPT's update nor
the per-sensor model uses it otherwise.

Chosen on training seeds 1000-1023 (S1-S4, clutter 1 and 5, fixed and random paths,
sigma_z 1; ``python scripts/model_study.py --seeds 24 --candidates
ss-rbcm-silence-1000-turn-q5 hybrid-no-region hybrid-region --paired-against
ss-rbcm-silence-1000-turn-q5``, 4 min): against ``dgpt-rbcm``, with the region -0.22 +- 0.16
/ -0.26 +- 0.18 m RMSE, paired, on the fixed / random paths; without it -0.04 +- 0.16 /
-0.14 +- 0.19 m. 3-sigma coverage on detected steps 99.69 % either way (``dgpt-rbcm``
99.77 %). At clutter 5 the hybrid with the region had the lower mean RMSE than
``dgpt-rbcm`` in all four scenarios on both path modes (reference paths S1-S4: 8.74, 4.93,
7.97, 6.67 m against 9.13, 5.40, 8.43, 6.73 m; without the region 9.26, 5.49, 8.05, 6.61 m).
``hybrid-trend`` gained -1.29 +- 0.28 / -2.14 +- 0.39 m with it (candidates
``hybrid-trend-region`` / ``hybrid-trend-no-region``, with a first version of the rows).
It costs about 1.4 times the hybrid's step (reference paths, clutter 5, one episode at a
time, mean steps over seeds 1000-1003: 2.6-2.7 ms without, 3.4-3.8 ms with), the quadrature
of :func:`agents.silence.region_truncation` being exact along each row of a component's
box."""


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
        reporting_region: with the per-sensor model, also the likelihood of which sensors
            report (:data:`REPORTING_REGION`).
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
        reporting_region: bool = REPORTING_REGION,
        **dgpt_kwargs,
    ) -> None:
        self.variant = check_choice("variant", variant, VARIANTS)
        self.reacquire = check_choice("reacquire", reacquire, REACQUIRE_RULES)
        self.delta = check_real(
            "delta", delta, low=0.0, high=1.0, low_inclusive=False, high_inclusive=False
        )
        self.prune_tolerance = check_real("prune_tolerance", prune_tolerance, low=0.0, high=1.0)
        self.scan_model = check_choice("scan_model", scan_model, SCAN_MODELS)
        if not isinstance(reporting_region, bool):
            raise TypeError(f"reporting_region must be True or False; got {reporting_region!r}")
        self.reporting_region = reporting_region
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
            region = self._region(obs, sensors) if per_sensor and self.reporting_region else None
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
                    region=region,
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
                    region=region,
                )
                prior_next = self.dgpt.set_estimate(result.mean, result.var)
            mean, var = result.mean, result.var
            self.pruned_mass_ = max(self.pruned_mass_, result.pruned_mass)
        if self.prior_model == "moments":
            bound = np.sqrt(2.0 * np.log(1.0 / self.delta) * var)
        return Estimate(mean, var, bound, prior_next)

    def _region(self, obs: dict, sensors: np.ndarray):
        """The step's :data:`~agents.poisson_update.Region`: the sensors of ``sensors``
        report, every other awake sensor (all without an ``"awake"`` mask) is silent."""
        spec = self.spec_
        reporting, silent = reporting_and_silent(spec.sensor_positions, sensors, obs.get("awake"))
        return reporting, silent, spec.sensing_range, spec.area
