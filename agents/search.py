"""The search for a target that has no track yet, with clutter at every sensor.

With ``clutter_sensors="all"`` one step's scans leave the target's position ambiguous: a
clutter point in a part of the area that one sensor alone covers explains that sensor's
scan as well as the target does (:mod:`agents.screening`). Only the motion over several
steps tells the target's points from the clutter. :class:`SearchFilter` is the Bayes filter
of the target's state [position, velocity] per axis from the first scan on, with a prior
uniform over the area and the scans' exact likelihood ratio
(:func:`agents.screening.area_log_likelihood_ratios`), as particles:

- the first step's particles are the position's posterior given its scans
  (:func:`agents.screening.scan_posterior`), with velocities from the prior
  N(0, ``speed_std``^2 I);
- at every later step the particles move under the NCV model with white-acceleration
  intensity ``process_noise`` and are weighed by the step's scans; and a share of the draws
  is *born* from pairs of measurements of this step and the last that a target could join
  (:func:`pair_births`), so that a particle starts on the target's point with the
  target's velocity, which blind draws would rarely do. The births stand for the target
  being somewhere new (prior probability ``birth_probability`` per step, position uniform,
  velocity from the prior) and are weighed by both steps' scans over their proposal's
  density. The next scan then separates them: the target's pair predicts its next point
  within a few metres, a pair of clutter points predicts a place where a covering sensor
  reports nothing (likelihood 0) or no sensor covers (likelihood 1).

The filter has *settled* when its position's standard deviation is at most
``settle_std`` on each axis: the tracker then starts its track there.
"""

from __future__ import annotations

import numpy as np
from scipy import spatial

from agents.particles import resample_systematic
from agents.screening import MAX_TARGET_SPEED, area_log_likelihood_ratios, scan_posterior
from agents.silence import propagate_particles
from dgpt_gym.problem import ProblemSpec

__all__ = ["SearchFilter", "pair_births", "weighed_births"]


def pair_births(
    previous: np.ndarray,
    current: np.ndarray,
    noise_var: float,
    dt: float,
    speed_std: float,
    area: float,
    n: int,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray] | None:
    """``n`` states born from pairs (a, b) of a previous-step point a (m0, 2) and a
    current-step point b (m1, 2) closer than :data:`agents.screening.MAX_TARGET_SPEED` x
    ``dt``: a pair drawn uniformly among the K of them, the position b + e_b and the
    velocity (b - a) / dt + e_v with e_b ~ N(0, s^2 I), e_v ~ N(0, 2 s^2 / dt^2 I), s^2 =
    ``noise_var`` (the spread of the position and of the difference of two measurements).

    Returns ``(states (n, 2 axes, 2) = [position, velocity], log_ratio (n,))``, log_ratio =
    log prior - log proposal - log n: the prior of a new target, position uniform over the
    ``area`` square and velocity N(0, ``speed_std``^2 I), over the proposal's density, the
    mixture (1/K) sum_k of every pair's Gaussian (the target's several points per step give
    pairs whose Gaussians overlap; components beyond 8 standard deviations, below e^-32 of
    their peak, are left out). None without a pair."""
    if not previous.shape[0] or not current.shape[0]:
        return None
    near = spatial.cKDTree(current).sparse_distance_matrix(
        spatial.cKDTree(previous), MAX_TARGET_SPEED * dt, output_type="ndarray"
    )
    if not near.size:
        return None
    velocity_var = 2.0 * noise_var / dt**2
    # each pair's Gaussian is the standard normal in these scaled [position, velocity]
    scale = np.r_[np.full(2, np.sqrt(noise_var)), np.full(2, np.sqrt(velocity_var))]
    ends = current[near["i"]]
    centres = np.column_stack([ends, (ends - previous[near["j"]]) / dt])
    chosen = rng.integers(0, near.size, n)
    draws = centres[chosen] + rng.standard_normal((n, 4)) * scale
    overlap = spatial.cKDTree(draws / scale).sparse_distance_matrix(
        spatial.cKDTree(centres / scale), 8.0, output_type="ndarray"
    )
    kernel_sum = np.bincount(
        overlap["i"].astype(np.int64), weights=np.exp(-0.5 * overlap["v"] ** 2), minlength=n
    )
    log_proposal = (
        np.log(kernel_sum)
        - np.log((2.0 * np.pi) ** 2 * noise_var * velocity_var)
        - np.log(near.size)
    )
    position, velocity = draws[:, :2], draws[:, 2:]
    log_prior = (
        -2.0 * np.log(area)
        - 0.5 * np.sum(velocity**2, axis=1) / speed_std**2
        - np.log(2.0 * np.pi * speed_std**2)
    )
    return np.stack([position, velocity], axis=2), log_prior - log_proposal - np.log(n)


def weighed_births(
    previous_scan,
    scan,
    spec: ProblemSpec,
    noise_var: float,
    dt: float,
    speed_std: float,
    n: int,
    rng: np.random.Generator,
    birth_probability: float,
    last_log_evidence: float,
) -> tuple[np.ndarray, np.ndarray] | None:
    """``n`` births of a new target (:func:`pair_births`) from the pairs of points of the
    last step's ``previous_scan`` and this step's ``scan`` ((points, sensors, awake) each,
    ``dt`` seconds apart), with their log weights on the scale of a particle filter whose
    particles carry log(1 - beta) plus this step's scan log likelihood ratio: log beta (beta
    = ``birth_probability``) plus the births' log prior over proposal, plus both steps' scan
    log likelihood ratios (:func:`agents.screening.area_log_likelihood_ratios`; the last
    step's at the position moved back by dt v), minus ``last_log_evidence``, the filter's
    log p(Z_t-1 | Z_..t-2): a target born at the last step has the probability beta
    p(Z_t-1, Z_t | new) / p(Z_t-1 | Z_..t-2) relative to the particles' p(Z_t | x). Returns
    ``(states (n, 2, 2), log_weights (n,))``, or None without a pair."""
    points, sensors, awake = scan
    previous_points, previous_sensors, previous_awake = previous_scan
    born = pair_births(previous_points, points, noise_var, dt, speed_std, spec.area, n, rng)
    if born is None:
        return None
    states, log_ratio = born
    log_weights = (
        np.log(birth_probability)
        + log_ratio
        + area_log_likelihood_ratios(states[..., 0], points, sensors, spec, noise_var, awake)
        + area_log_likelihood_ratios(
            states[..., 0] - dt * states[..., 1],
            previous_points,
            previous_sensors,
            spec,
            noise_var,
            previous_awake,
        )
        - last_log_evidence
    )
    return states, log_weights


class SearchFilter:
    """The particle filter of the module docstring, for one episode of a tracker.

    Args:
        spec: the problem (sensors, range, rates, area; sigma = ``model_noise_std``).
        n: particles, at least 10; each step after the first also draws n / 2 births.
        rng: the draws' generator.
        speed_std: m/s per axis, the velocity prior of a new target.
        process_noise: q, m^2/s^3, the NCV white-acceleration intensity per axis.
        birth_probability: the prior probability per step that the target is somewhere new.
        settle_std: m, the position standard deviation per axis at which it has settled.
    """

    def __init__(
        self,
        spec: ProblemSpec,
        n: int,
        rng: np.random.Generator,
        speed_std: float,
        process_noise: float,
        birth_probability: float,
        settle_std: float,
    ) -> None:
        if n < 10:
            raise ValueError(f"n must be at least 10; got {n}")
        if not 0.0 < birth_probability < 1.0:
            raise ValueError(f"birth_probability must be in (0, 1); got {birth_probability}")
        self.spec, self.n, self.rng = spec, n, rng
        self.speed_std, self.process_noise = speed_std, process_noise
        self.birth_probability, self.settle_std = birth_probability, settle_std
        self.noise_var = spec.model_noise_std**2
        self.reset()

    def reset(self) -> None:
        """Forget every scan: the next step starts from the uniform prior."""
        self.states = None  # (n, 2, 2) after the last step, equally weighted
        self.previous = None  # the last step's (points, sensors, awake)
        self.log_evidence = 0.0  # log of the last step's normaliser of the weights
        self.last_step = 0

    def step(self, step: int, points, sensors, awake=None):
        """Filter one step's scans (every report). Returns ``(mean (2,), var (2,),
        settled)`` of the position, or None when the scans rule out every particle and
        every birth (the filter then starts again at the next step)."""
        spec, rng = self.spec, self.rng
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        sensors = np.asarray(sensors)
        if self.states is None:
            posterior = scan_posterior(
                points, sensors, spec, self.noise_var, self.n, rng, awake, with_log_evidence=True
            )
            if posterior is None:
                return None
            positions, weights, self.log_evidence = posterior
            velocities = rng.standard_normal((self.n, 2)) * self.speed_std
            states = np.stack([positions, velocities], axis=2)
        else:
            dt = (step - self.last_step) * spec.dt
            states = propagate_particles(
                self.states, dt, np.full(2, self.process_noise), 0.0, 0.0, rng
            )
            log_weight = np.log1p(-self.birth_probability) + area_log_likelihood_ratios(
                states[..., 0], points, sensors, spec, self.noise_var, awake
            )
            born = weighed_births(
                self.previous,
                (points, sensors, awake),
                spec,
                self.noise_var,
                dt,
                self.speed_std,
                self.n // 2,
                rng,
                self.birth_probability,
                self.log_evidence,
            )
            if born is not None:
                born_states, log_born = born
                states = np.concatenate([states, born_states])
                log_weight = np.concatenate([log_weight + np.log(1.0 / self.n), log_born])
            else:
                log_weight = log_weight + np.log(1.0 / self.n)
            top = np.max(log_weight)
            if not np.isfinite(top):
                self.reset()
                return None
            weights = np.exp(log_weight - top)
            self.log_evidence = top + np.log(weights.sum())
            weights /= weights.sum()
        chosen = resample_systematic(weights, rng, self.n)
        mean = weights @ states[:, :, 0]
        var = weights @ (states[:, :, 0] - mean) ** 2
        self.states = states[chosen]
        self.previous = (points, sensors, awake)
        self.last_step = step
        return mean, var, bool(np.all(np.sqrt(var) <= self.settle_std))
