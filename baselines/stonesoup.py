"""Stone Soup trackers on DGPTrack-v0: a wrapper from Stone Soup components to this
project's :class:`~agents.base.Tracker` interface (extra ``stonesoup``:
``pip install 'dgpt-gym[stonesoup]'``).

A Stone Soup user builds the components from the problem (:class:`ProblemSpec`: sensor
layout, sensing range, sigma_z, lambda_T, lambda_c) and the wrapper runs them: each step's
measurements become ``Detection`` s at time ``t * dt``, the hypothesiser scores them against
the track's prediction, the updater turns the hypotheses into the posterior, and the
estimate is its position with the position variances. Steps without measurements only
predict. The track starts at the first step with measurements from a prior at their
centroid, with a position standard deviation of one sensing range and velocity
``initial_velocity_std``, updated with that scan.

Example (the KF-PDA of :func:`pda_components`, one episode of S2 at clutter rate 5)::

    import gymnasium
    import dgpt_gym
    from baselines.stonesoup import StoneSoupTracker, pda_components
    from dgpt_gym.evaluation import run_episode

    tracker = StoneSoupTracker(pda_components, noise_diff_coeff=20.0)
    env = gymnasium.make("DGPTrack-v0", scenario="S2", clutter_rate=5)
    print(run_episode(env, tracker, seed=0).metrics()["rmse_2d"])

Any builder ``build(spec, **options) -> (predictor, updater, hypothesiser)`` whose
hypothesiser returns the ``MultipleHypothesis`` its updater takes (the PDA family) works the
same way; the registered id ``stonesoup-pda`` is this example, so
``scripts/evaluate.py --trackers stonesoup-pda`` evaluates it like any other tracker.
"""

from __future__ import annotations

import datetime
from collections.abc import Callable

import numpy as np

from agents.base import Estimate, TrackerBase
from dgpt_gym.problem import ProblemSpec
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

__all__ = ["StoneSoupTracker", "pda_components", "EPOCH"]

EPOCH = datetime.datetime(2000, 1, 1)
"""Time of step 0; step t is at EPOCH + t * dt."""


def pda_components(
    spec: ProblemSpec,
    noise_diff_coeff: float = 20.0,
    prob_detect: float = 0.99,
    prob_gate: float = 0.9999,
):
    """A Kalman filter with the textbook PDA from Stone Soup's components: two
    ``ConstantVelocity(q)`` axes, ``LinearGaussian`` position measurements of variance
    sigma_z^2, ``PDAHypothesiser`` with the clutter density lambda_c / (pi r^2) and
    ``PDAUpdater``. Returns (predictor, updater, hypothesiser)."""
    transition = CombinedLinearGaussianTransitionModel(
        [ConstantVelocity(noise_diff_coeff), ConstantVelocity(noise_diff_coeff)]
    )
    measurement = LinearGaussian(4, [0, 2], spec.noise_std**2 * np.eye(2))
    predictor = KalmanPredictor(transition)
    hypothesiser = PDAHypothesiser(
        predictor,
        KalmanUpdater(measurement),
        clutter_spatial_density=max(spec.clutter_rate / spec.sensing_area, 1e-12),
        prob_detect=prob_detect,
        prob_gate=prob_gate,
    )
    return predictor, PDAUpdater(measurement), hypothesiser


class StoneSoupTracker(TrackerBase):
    """Runs Stone Soup components through the :class:`~agents.base.Tracker` interface.

    Args:
        build: ``build(spec, **options) -> (predictor, updater, hypothesiser)``; default
            :func:`pda_components`.
        initial_velocity_std: velocity standard deviation of the initial state, m/s.
        **options: passed to ``build`` (e.g. ``noise_diff_coeff``, ``prob_detect``).
    """

    name = "stonesoup"

    def __init__(
        self,
        build: Callable = pda_components,
        initial_velocity_std: float = 15.0,
        **options,
    ) -> None:
        if not callable(build):
            raise ValueError(f"build must be callable (spec, **options); got {build!r}")
        self.build = build
        self.initial_velocity_std = check_real(
            "initial_velocity_std", initial_velocity_std, low=0.0, low_inclusive=False
        )
        self.options = options

    def reset(self, spec: ProblemSpec, seed: int | None = None) -> None:
        self.spec_ = spec
        self.predictor_, self.updater_, self.hypothesiser_ = self.build(spec, **self.options)
        self.track_: Track | None = None

    def _start(self, measurements: np.ndarray, when: datetime.datetime) -> None:
        centroid = measurements.mean(axis=0)
        mean = np.array([centroid[0], 0.0, centroid[1], 0.0])
        variances = np.array([self.spec_.sensing_range, self.initial_velocity_std] * 2) ** 2
        self.track_ = Track([GaussianState(mean.reshape(-1, 1), np.diag(variances), when)])

    def update(self, obs: dict) -> Estimate:
        if self.spec_ is None:
            raise RuntimeError("call reset(spec) before update(obs)")
        mask = np.asarray(obs["mask"]).astype(bool)
        measurements = np.asarray(obs["measurements"], dtype=float)[mask]
        when = EPOCH + datetime.timedelta(seconds=float(obs["t"]) * self.spec_.dt)
        if self.track_ is None:
            if measurements.shape[0] == 0:
                return Estimate.uninformed(self.spec_)
            self._start(measurements, when)  # then updated with the same scan (dt = 0)
        model = self.updater_.measurement_model
        detections = {
            Detection(z.reshape(-1, 1), timestamp=when, measurement_model=model)
            for z in measurements
        }
        if detections:
            hypotheses = self.hypothesiser_.hypothesise(self.track_, detections, when)
            self.track_.append(self.updater_.update(hypotheses))
        else:
            self.track_.append(self.predictor_.predict(self.track_.state, timestamp=when))
        state = self.track_.state
        mean = np.asarray(state.state_vector, dtype=float).ravel()
        variance = np.diag(np.asarray(state.covar, dtype=float))
        return Estimate(mean[[0, 2]], np.maximum(variance[[0, 2]], 1e-12))
