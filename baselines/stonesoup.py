"""Stone Soup trackers on DGPTrack-v0: a wrapper from Stone Soup components to this
project's :class:`~dgpt_gym.tracker.Tracker` interface (extra ``stonesoup``:
``pip install 'dgpt-gym[stonesoup]'``).

:class:`StoneSoupTracker` runs a Stone Soup predictor, updater and hypothesiser. They come
either from a builder ``build(spec, **options) -> (predictor, updater, hypothesiser)``
called at every ``reset`` with the episode's :class:`~dgpt_gym.problem.ProblemSpec` (sensor
layout, sensing range, sigma_z, lambda_T, lambda_c), or ready-made from
:meth:`StoneSoupTracker.from_components`. Each step:

- the observation's real rows (``mask == 1``) become ``Detection`` s at time
  ``EPOCH + t * dt``, with the updater's measurement model;
- the hypothesiser scores them against the track's prediction and the updater turns its
  output (as is: the PDA family, a ``MultipleHypothesis`` the updater takes) into the
  posterior; a step without measurements only predicts;
- the estimate is the posterior mean and variance of the position components (the
  measurement model's ``mapping``, [0, 2] for the state [x, vx, y, vy]).

Before the first measurement the answer is the area's centre with variance area^2 / 12.
The track starts at the first step with measurements from a one-point prior at their
centroid: position standard deviation one sensing range, every other state component
``initial_velocity_std`` (m/s), no correlations; it is then updated with that same scan.
``initial_state(measurements, spec, timestamp) -> State`` replaces this start. There is no
track deletion or restart.

Example (the KF-PDA of :func:`stonesoup_pda_tracker`, one episode of S2 at clutter rate 5)::

    import gymnasium
    import dgpt_gym  # registers DGPTrack-v0
    from baselines.stonesoup import stonesoup_pda_tracker
    from dgpt_gym.benchmark.episodes import run_episode

    tracker = stonesoup_pda_tracker(noise_diff_coeff=20.0, prob_detect=0.99)
    env = gymnasium.make("DGPTrack-v0", scenario="S2", clutter_rate=5)
    print(run_episode(env, tracker, seed=0).metrics()["rmse_2d"])

Your own components, e.g. another transition model::

    import numpy as np
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.updater.kalman import KalmanUpdater
    from stonesoup.updater.probability import PDAUpdater

    def build(spec, transition):
        measurement = LinearGaussian(4, [0, 2], spec.noise_std**2 * np.eye(2))
        predictor = KalmanPredictor(transition)
        hypothesiser = PDAHypothesiser(
            predictor, KalmanUpdater(measurement),
            clutter_spatial_density=spec.clutter_density,
            prob_detect=0.95, prob_gate=0.999)
        return predictor, PDAUpdater(measurement), hypothesiser

    tracker = StoneSoupTracker(build, transition=my_transition_model)  # build's options

The registered id ``stonesoup-pda`` is ``StoneSoupTracker()`` (the builder
:func:`pda_components` with its defaults), so ``scripts/evaluate.py --trackers
stonesoup-pda`` evaluates it like any other tracker.
"""

from __future__ import annotations

import datetime
from collections.abc import Callable

import numpy as np

from dgpt_gym.problem import ProblemSpec
from dgpt_gym.tracker import Estimate, TrackerBase
from dgpt_gym.validation import check_real

try:
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import KalmanUpdater
    from stonesoup.updater.probability import PDAUpdater
except ImportError as error:  # pragma: no cover - depends on the install
    raise ImportError(
        "baselines.stonesoup needs Stone Soup: pip install 'dgpt-gym[stonesoup]'"
    ) from error

__all__ = ["StoneSoupTracker", "pda_components", "stonesoup_pda_tracker", "EPOCH"]

EPOCH = datetime.datetime(2000, 1, 1)
"""Time of step 0; step t is at EPOCH + t * dt."""

MIN_CLUTTER_DENSITY = 1e-12
"""Floor of the PDA clutter density (m^-2) at clutter rate 0, where the PDA is undefined."""


def pda_components(
    spec: ProblemSpec,
    noise_diff_coeff: float = 20.0,
    prob_detect: float = 0.99,
    prob_gate: float = 0.9999,
    gm_method: bool = False,
):
    """A Kalman filter with the textbook PDA from Stone Soup's components: two
    ``ConstantVelocity(q)`` axes (state [x, vx, y, vy]), ``LinearGaussian`` position
    measurements of variance sigma_z^2, ``PDAHypothesiser`` with the clutter density
    lambda_c / (pi r^2) (floored at :data:`MIN_CLUTTER_DENSITY`) and ``PDAUpdater``
    (``gm_method``: Gaussian-mixture reduction instead of the combined innovation; the same
    posterior). Returns (predictor, updater, hypothesiser)."""
    noise_diff_coeff = check_real("noise_diff_coeff", noise_diff_coeff, low=0.0)
    prob_detect = check_real("prob_detect", prob_detect, low=0.0, low_inclusive=False, high=1.0)
    prob_gate = check_real("prob_gate", prob_gate, low=0.0, low_inclusive=False, high=1.0)
    transition = CombinedLinearGaussianTransitionModel(
        [ConstantVelocity(noise_diff_coeff), ConstantVelocity(noise_diff_coeff)]
    )
    measurement = LinearGaussian(4, [0, 2], spec.noise_std**2 * np.eye(2))
    predictor = KalmanPredictor(transition)
    hypothesiser = PDAHypothesiser(
        predictor,
        KalmanUpdater(measurement),
        clutter_spatial_density=max(spec.clutter_density, MIN_CLUTTER_DENSITY),
        prob_detect=prob_detect,
        prob_gate=prob_gate,
    )
    # the gm_method property is recent (older releases take it only as update's argument)
    updater = PDAUpdater(measurement, gm_method=True) if gm_method else PDAUpdater(measurement)
    return predictor, updater, hypothesiser


class _Components:
    """A builder that ignores the problem and returns fixed components (picklable, unlike a
    lambda)."""

    def __init__(self, predictor, updater, hypothesiser) -> None:
        self.components = (predictor, updater, hypothesiser)

    def __call__(self, spec: ProblemSpec):
        return self.components


class StoneSoupTracker(TrackerBase):
    """Runs Stone Soup components through the :class:`~dgpt_gym.tracker.Tracker` interface
    (module docstring).

    Args:
        build: ``build(spec, **options) -> (predictor, updater, hypothesiser)``, called at
            every :meth:`reset`; default :func:`pda_components`. The updater must take the
            hypothesiser's output and have the ``measurement_model`` of the detections.
        initial_velocity_std: standard deviation of the non-position components of the
            default initial state (velocities, m/s).
        initial_state: ``initial_state(measurements, spec, timestamp) -> State``, the track's
            start from the first scan with measurements ((m, 2) array) in place of the
            default; the returned state is then updated with that scan.
        **options: passed to ``build`` (e.g. ``noise_diff_coeff``, ``prob_detect``).
    """

    name = "stonesoup"

    def __init__(
        self,
        build: Callable = pda_components,
        initial_velocity_std: float = 15.0,
        initial_state: Callable | None = None,
        **options,
    ) -> None:
        if not callable(build):
            raise ValueError(f"build must be callable (spec, **options); got {build!r}")
        if initial_state is not None and not callable(initial_state):
            raise ValueError(
                "initial_state must be None or callable (measurements, spec, timestamp); "
                f"got {initial_state!r}"
            )
        self.build = build
        self.initial_velocity_std = check_real(
            "initial_velocity_std", initial_velocity_std, low=0.0, low_inclusive=False
        )
        self.initial_state = initial_state
        self.options = options

    @classmethod
    def from_components(
        cls,
        predictor,
        updater,
        hypothesiser,
        initial_velocity_std: float = 15.0,
        initial_state: Callable | None = None,
    ) -> StoneSoupTracker:
        """A tracker with ready-made components, the same in every episode (their models do
        not follow the episode's :class:`ProblemSpec`)."""
        return cls(
            _Components(predictor, updater, hypothesiser),
            initial_velocity_std=initial_velocity_std,
            initial_state=initial_state,
        )

    def reset(self, spec: ProblemSpec, seed: int | None = None) -> None:
        self.spec_ = spec
        self.predictor_, self.updater_, self.hypothesiser_ = self.build(spec, **self.options)
        model = self.updater_.measurement_model
        self.position_index_ = np.asarray(model.mapping, dtype=int)
        if self.position_index_.shape != (2,):
            raise ValueError(
                "the updater's measurement model must measure two state components (x, y); "
                f"its mapping is {tuple(model.mapping)}"
            )
        self.track_: Track | None = None

    def _start(self, measurements: np.ndarray, when: datetime.datetime):
        """The default one-point start: the centroid, position variance r^2, every other
        component initial_velocity_std^2."""
        ndim = self.updater_.measurement_model.ndim_state
        mean = np.zeros(ndim)
        mean[self.position_index_] = measurements.mean(axis=0)
        variances = np.full(ndim, self.initial_velocity_std**2)
        variances[self.position_index_] = self.spec_.sensing_range**2
        return GaussianState(mean.reshape(-1, 1), np.diag(variances), timestamp=when)

    def update(self, obs: dict) -> Estimate:
        if self.spec_ is None:
            raise RuntimeError("call reset(spec) before update(obs)")
        mask = np.asarray(obs["mask"]).astype(bool)
        measurements = np.asarray(obs["measurements"], dtype=float)[mask]
        when = EPOCH + datetime.timedelta(seconds=float(obs["t"]) * self.spec_.dt)
        if self.track_ is None:
            if measurements.shape[0] == 0:
                return Estimate.uninformed(self.spec_)
            if self.initial_state is None:
                start = self._start(measurements, when)
            else:
                start = self.initial_state(measurements, self.spec_, when)
            self.track_ = Track([start])  # then updated with the same scan (dt = 0)
        model = self.updater_.measurement_model
        detections = [
            Detection(z.reshape(-1, 1), timestamp=when, measurement_model=model)
            for z in measurements
        ]
        if detections:
            hypotheses = self.hypothesiser_.hypothesise(self.track_, set(detections), when)
            self.track_.append(self.updater_.update(hypotheses))
        else:
            self.track_.append(self.predictor_.predict(self.track_.state, timestamp=when))
        state = self.track_.state
        mean = np.asarray(state.mean, dtype=float).ravel()[self.position_index_]
        variance = np.diag(np.asarray(state.covar, dtype=float))[self.position_index_]
        return Estimate(mean, np.maximum(variance, 1e-12))


def stonesoup_pda_tracker(
    noise_diff_coeff: float = 20.0,
    prob_detect: float = 0.99,
    prob_gate: float = 0.9999,
    gm_method: bool = False,
    initial_velocity_std: float = 15.0,
) -> StoneSoupTracker:
    """A KF-PDA built from Stone Soup components (:func:`pda_components`: nearly constant
    velocity with acceleration spectral density ``noise_diff_coeff`` per axis, m^2/s^3; PDA
    with detection and gate probabilities ``prob_detect`` and ``prob_gate`` and the clutter
    density lambda_c / (pi r^2) of the episode), wrapped in :class:`StoneSoupTracker`."""
    tracker = StoneSoupTracker(
        pda_components,
        initial_velocity_std=initial_velocity_std,
        noise_diff_coeff=noise_diff_coeff,
        prob_detect=prob_detect,
        prob_gate=prob_gate,
        gm_method=gm_method,
    )
    tracker.name = "stonesoup-pda"
    return tracker
