"""A simple reference tracker: gated weighted centroid with an alpha-beta filter.

Not from the paper: it exists so the environment, the evaluation loop and the tables run end
to end before the paper's trackers, and as a floor any serious tracker should beat.
"""

from __future__ import annotations

import numpy as np

from dgpt_gym.problem import ProblemSpec
from dgpt_gym.tracker import Estimate, TrackerBase
from dgpt_gym.validation import check_integer, check_real

__all__ = ["GatedCentroidTracker", "weighted_centroid"]


def weighted_centroid(
    points: np.ndarray, centre: np.ndarray, gate_radius: float
) -> tuple[np.ndarray, float, float] | None:
    """Centroid of the ``points`` (n, 2) within ``gate_radius`` of ``centre``.

    Points are weighted by a Gaussian of standard deviation ``gate_radius / 2`` in their
    distance to ``centre``. Returns ``(centroid, variance, effective_count)`` where
    ``variance`` is the weighted per-axis spread of the gated points, or None when no point
    is inside the gate.
    """
    offsets = points - centre
    squared = np.einsum("nk,nk->n", offsets, offsets)
    inside = squared <= gate_radius**2
    if not inside.any():
        return None
    weights = np.exp(-2.0 * squared[inside] / gate_radius**2)
    weights /= weights.sum()
    gated = points[inside]
    centroid = weights @ gated
    spread = float(weights @ np.einsum("nk,nk->n", gated - centroid, gated - centroid)) / 2.0
    return centroid, spread, float(1.0 / np.sum(weights**2))


class GatedCentroidTracker(TrackerBase):
    """Alpha-beta filter on the gated weighted centroid of the measurements.

    Each step the previous estimate is propagated with the estimated velocity; the
    measurements within ``gate_radius`` of that prediction give a weighted centroid
    (:func:`weighted_centroid`), and the position and velocity are corrected by the
    innovation with gains ``alpha`` and ``beta``. A step without gated measurements keeps
    the prediction and its variance grows by ``process_std^2``. The track is (re)started at
    the centroid of the measurements around their coordinate-wise median (robust to a
    minority of clutter) at the first step with measurements and whenever measurements
    arrive after ``reacquire_after`` steps without gated ones, e.g. after the target crossed
    a gap in sensor coverage. The first step with
    measurements initialises the track at the centroid of the measurements around their
    coordinate-wise median (robust to a minority of clutter).

    Args:
        gate_radius: radius of the gate around the predicted position, m.
        alpha: position gain in (0, 1].
        beta: velocity gain in [0, 1].
        process_std: standard deviation of the per-step position change not explained by
            the velocity, m; sets how fast the variance grows while coasting.
        reacquire_after: steps without gated measurements after which the track restarts
            from the measurements at hand.
    """

    name = "centroid"

    def __init__(
        self,
        gate_radius: float = 30.0,
        alpha: float = 0.6,
        beta: float = 0.3,
        process_std: float = 10.0,
        reacquire_after: int = 3,
    ) -> None:
        self.gate_radius = check_real("gate_radius", gate_radius, low=0.0, low_inclusive=False)
        self.alpha = check_real("alpha", alpha, low=0.0, high=1.0, low_inclusive=False)
        self.beta = check_real("beta", beta, low=0.0, high=1.0)
        self.process_std = check_real("process_std", process_std, low=0.0)
        self.reacquire_after = check_integer("reacquire_after", reacquire_after, low=1)

    def reset(self, spec: ProblemSpec, seed: int | None = None) -> None:
        self.spec_ = spec
        self.position_: np.ndarray | None = None
        self.velocity_ = np.zeros(2)
        self.var_ = np.full(2, spec.area**2 / 12.0)
        self.steps_coasted_ = 0

    def update(self, obs: dict) -> Estimate:
        if self.spec_ is None:
            raise RuntimeError("call reset(spec) before update(obs)")
        points = np.asarray(obs["measurements"])[np.asarray(obs["mask"]) == 1]
        dt = self.spec_.dt
        if self.position_ is None:
            if points.shape[0] == 0:
                centre = np.full(2, self.spec_.area / 2.0)
                return Estimate(centre, self.var_.copy())
            return self._initialise(points)

        predicted = self.position_ + self.velocity_ * dt
        predicted_var = self.var_ + self.process_std**2
        if self.steps_coasted_ >= self.reacquire_after and len(points):
            return self._initialise(points)
        gated = weighted_centroid(points, predicted, self.gate_radius) if len(points) else None
        if gated is None:
            self.position_, self.var_ = predicted, predicted_var
            self.steps_coasted_ += 1
        else:
            self.steps_coasted_ = 0
            centroid, spread, count = gated
            innovation = centroid - predicted
            self.position_ = predicted + self.alpha * innovation
            self.velocity_ = self.velocity_ + self.beta * innovation / dt
            self.var_ = (1.0 - self.alpha) * predicted_var + self.alpha * (spread / count + 1.0)
        return self._estimate()

    def _initialise(self, points: np.ndarray) -> Estimate:
        """Start (or restart) the track at the gated centroid around the median measurement."""
        median = np.median(points, axis=0)
        start = weighted_centroid(points, median, self.gate_radius)
        self.position_, spread, count = start if start else (median, self.gate_radius**2, 1.0)
        self.velocity_ = np.zeros(2)
        self.var_ = np.full(2, spread / count + 1.0)
        self.steps_coasted_ = 0
        return self._estimate()

    def _estimate(self) -> Estimate:
        dt = self.spec_.dt
        return Estimate(
            self.position_.copy(),
            self.var_.copy(),
            prior_next=(self.position_ + self.velocity_ * dt, self.var_ + self.process_std**2),
        )
