"""The shape-known floor with clutter at every sensor: what can be known of the target
when only its start is unknown.

With ``clutter_sensors="all"`` every sensor reports clutter, so the first steps of an
episode leave the target's position ambiguous: a clutter point in a part of the area that
one sensor alone covers explains that sensor's scan as well as the target does
(:mod:`agents.screening`). The clairvoyant floor (:mod:`baselines.clairvoyant`) is told
which points are the target's and so never sees this ambiguity. This floor is told less:
the path's *shape*, the displacements d_t = x_t - x_0 of the true path, but not its start
x_0. It also knows the measurement model and its rates.

**The start's law given the shape.** :meth:`dgpt_gym.scenarios.Scenario.sample` draws a
path's shape, then translates it by an offset uniform among those that keep it inside
``[margin, area - margin]^2``. Given the shape, x_0 is therefore uniform on the box
B = [margin - min_t d_t, area - margin - max_t d_t] (per axis; :func:`start_box`). With
that prior the posterior after steps 0..t is

    p(x_0 | d, Z_0..t) = const 1[x_0 in B] prod_{tau <= t} LR_tau(x_0 + d_tau),

with LR_tau the likelihood ratio of step tau's scans for a target at a position against no
target (:func:`agents.screening.area_log_likelihood_ratios`): 0 where a sensor covers the
position and reports nothing within 6 sigma of it, 1 where no sensor covers it. Its mean
plus d_t is the floor's estimate of x_t.

**What it shows.** For random paths (``trajectory="random"``) this is the exact posterior
given the shape and the scans, so its mean is the least mean-squared-error estimate from
them: over random-path episodes, no tracker, which sees the scans but not the shape, has a
smaller mean squared error at any step, up to the Monte Carlo error of the sampler below.
The reference path (``trajectory="fixed"``) is one such draw; the floor then treats it as if
its start were unknown, and on one fixed path it is an estimator's error, not a bound.
Where the floor's error already exceeds a goal, no tracker can be expected to meet it;
where it does not, the goal is not ruled out, though a tracker that is not told the shape
may still be unable to reach it.

**How.** Self-normalised importance sampling over x_0, with draws one third uniform over B
and two thirds around the candidates z - d_tau inside B (every measurement z of every step
tau, shifted back to the start), whose density the weights divide by, as
:func:`agents.screening.scan_posterior` does for one step.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from agents.screening import area_log_likelihood_ratios, draws_near_candidates
from dgpt_gym.problem import ProblemSpec

__all__ = ["shape_known_posteriors", "start_box"]


def start_box(
    displacements: np.ndarray, area: float, margin: float
) -> tuple[np.ndarray, np.ndarray]:
    """The box (low (2,), high (2,)) of the starts that keep a path of these displacements
    (T, 2) inside ``[margin, area - margin]^2``: the support of the start's law given the
    shape (module docstring)."""
    displacements = np.asarray(displacements, dtype=float)
    low = margin - displacements.min(axis=0)
    high = area - margin - displacements.max(axis=0)
    if np.any(high < low):
        raise ValueError(
            f"displacements span {displacements.max(axis=0) - displacements.min(axis=0)} m, "
            f"more than the {area - 2 * margin} m that the area and margin allow"
        )
    return low, high


def shape_known_posteriors(
    scans: Sequence[tuple[np.ndarray, np.ndarray]],
    displacements: np.ndarray,
    spec: ProblemSpec,
    n: int,
    rng: np.random.Generator,
    box: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The posterior of the start x_0 after each of the first K steps (module docstring).

    Args:
        scans: K steps' ``(points (m, 2), sensors (m,))``, every report of the step.
        displacements: (K, 2) d_t = x_t - x_0 of the path, with d_0 = 0.
        spec: the problem (sensors, range, rates, area; sigma = its ``model_noise_std``).
        n: importance draws of x_0, at least 3.
        rng: the draws' generator.
        box: ``(low (2,), high (2,))``, the support of x_0's uniform prior
            (:func:`start_box` of the whole path); the area if None.

    Returns ``(means (K, 2), covs (K, 2, 2), ess (K,))``: the posterior mean and covariance
    of x_0 after steps 0..t, and the effective number of the draws behind them
    (1 / sum w^2), from which a mean's Monte Carlo standard error is about
    sqrt(cov / ess)."""
    displacements = np.asarray(displacements, dtype=float)
    k = len(scans)
    if k < 1 or displacements.shape != (k, 2):
        raise ValueError(
            f"displacements must be (K, 2) for the K = {k} scans (K >= 1); got shape "
            f"{displacements.shape}"
        )
    if not np.allclose(displacements[0], 0.0):
        raise ValueError(f"displacements[0] must be 0 (d_0 = x_0 - x_0); got {displacements[0]}")
    low, high = np.zeros(2), np.full(2, float(spec.area))
    if box is not None:
        if len(box) != 2:
            raise ValueError(f"box must be (low (2,), high (2,)); got {box!r}")
        low, high = (np.asarray(bound, dtype=float) for bound in box)
        if low.shape != (2,) or high.shape != (2,) or not np.all(low < high):
            raise ValueError(f"box must be (low (2,), high (2,)) with low < high; got {box!r}")
    noise_var = spec.model_noise_std**2
    candidates = np.concatenate(
        [
            np.asarray(points, dtype=float).reshape(-1, 2) - displacements[t]
            for t, (points, _) in enumerate(scans)
        ]
    )
    reach = 6.0 * np.sqrt(noise_var)  # a candidate's draws reach this far
    candidates = candidates[
        np.all((candidates > low - reach) & (candidates < high + reach), axis=1)
    ]
    starts, proposal = draws_near_candidates(candidates, low, high, noise_var, n, rng)
    inside = np.all((starts >= low) & (starts <= high), axis=1)
    log_weight = np.where(inside, -np.log(proposal), -np.inf)  # the prior is flat on the box
    means, covs, ess = np.empty((k, 2)), np.empty((k, 2, 2)), np.empty(k)
    for t, (points, sensors) in enumerate(scans):
        log_weight = log_weight + area_log_likelihood_ratios(
            starts + displacements[t],
            np.asarray(points, dtype=float).reshape(-1, 2),
            np.asarray(sensors),
            spec,
            noise_var,
        )
        if not np.any(np.isfinite(log_weight)):
            raise ValueError(
                f"the scans of steps 0..{t} rule out every drawn start: the displacements "
                "or the box do not fit the scans, or n is too small"
            )
        weights = np.exp(log_weight - np.max(log_weight))
        weights /= weights.sum()
        means[t] = weights @ starts
        deviation = starts - means[t]
        covs[t] = np.einsum("n,ni,nj->ij", weights, deviation, deviation)
        ess[t] = 1.0 / np.sum(weights**2)
    return means, covs, ess
