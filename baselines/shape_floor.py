"""The shape-known floor with clutter at every sensor: what can be known of the target
when only its start is unknown.

With ``clutter_sensors="all"`` every sensor reports clutter, so the first steps of an
episode leave the target's position ambiguous: a clutter point in a part of the area that
one sensor alone covers explains that sensor's scan as well as the target does
(:mod:`agents.screening`). The clairvoyant floor (:mod:`baselines.clairvoyant`) is told
which points are the target's and so never sees this ambiguity. This floor is told less:
the path's *shape*, the displacements d_t = x_t - x_0 of the true path, but not its start
x_0, for which it takes a prior uniform over the area. It also knows the measurement model
and its rates. Its estimate at step t is the posterior mean of x_0 given the scans of steps
0..t, plus d_t; the posterior is

    p(x_0 | Z_0..t) ∝ 1[x_0 + d_tau in the area for tau <= t] prod_{tau <= t} LR_tau(x_0 + d_tau),

with LR_tau the likelihood ratio of step tau's scans for a target at a position against no
target (:func:`agents.screening.area_log_likelihood_ratios`): 0 where a sensor covers the
position and reports nothing near it, 1 where no sensor covers it.

A tracker that does not know the shape can do no better on average over starts drawn
uniformly, since it knows less. On a given episode this is an estimator's error, not a bound:
a tracker whose guesses happen to favour that episode's start can beat it there. It answers
whether a goal such as "RMSE with clutter at every sensor at most twice that with clutter at
the detecting sensors" is reachable: where this floor's error over the first steps alone
already exceeds it, no tracker that is not told the start can be expected to meet it.

The posterior is computed by self-normalised importance sampling over x_0, with draws one
third uniform over the area and two thirds around the candidates z - d_tau (every
measurement z of every step tau, shifted back to the start), whose density the weights
divide by, as :func:`agents.screening.scan_posterior` does for one step.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import spatial

from agents.screening import area_log_likelihood_ratios
from dgpt_gym.problem import ProblemSpec

__all__ = ["shape_known_posteriors", "CANDIDATE_STEPS"]

CANDIDATE_STEPS = 8
"""The draws around candidates z - d_tau take z from the first 8 steps only: the start is
ambiguous over a few steps at most (a median of 0-2 on S1-S4), and candidates from every
step would spread the draws thinly over the first steps' modes. Any choice leaves the
estimate consistent: the uniform third of the draws covers the whole area."""


def shape_known_posteriors(
    scans: Sequence[tuple[np.ndarray, np.ndarray]],
    displacements: np.ndarray,
    spec: ProblemSpec,
    n: int,
    rng: np.random.Generator,
    candidate_steps: int = CANDIDATE_STEPS,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The posterior of the start x_0 after each of the first K steps (module docstring).

    Args:
        scans: K steps' ``(points (m, 2), sensors (m,))``, every report of the step.
        displacements: (K, 2) d_t = x_t - x_0 of the path, with d_0 = 0.
        spec: the problem (sensors, range, rates, area; sigma = its ``model_noise_std``).
        n: importance draws of x_0, at least 3.
        rng: the draws' generator.
        candidate_steps: the draws around candidates use the measurements of the first
            this many steps only (:data:`CANDIDATE_STEPS`).

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
    if n < 3:
        raise ValueError(f"n must be at least 3 (a third of the draws are uniform); got {n}")
    noise_var = spec.model_noise_std**2
    candidates = np.concatenate(
        [
            np.asarray(points, dtype=float).reshape(-1, 2) - displacements[t]
            for t, (points, _) in enumerate(scans[:candidate_steps])
        ]
    )
    n_uniform = n if not candidates.shape[0] else n // 3
    starts = rng.random((n, 2)) * spec.area
    proposal = np.full(n, n_uniform / n / spec.area**2)
    if candidates.shape[0]:
        chosen = rng.integers(0, candidates.shape[0], n - n_uniform)
        starts[n_uniform:] = candidates[chosen] + rng.standard_normal((n - n_uniform, 2)) * np.sqrt(
            noise_var
        )
        near = spatial.cKDTree(starts).sparse_distance_matrix(
            spatial.cKDTree(candidates), 6.0 * np.sqrt(noise_var), output_type="ndarray"
        )
        density = np.exp(-0.5 * near["v"] ** 2 / noise_var) / (2.0 * np.pi * noise_var)
        proposal += (
            (n - n_uniform)
            / n
            / candidates.shape[0]
            * np.bincount(near["i"].astype(np.int64), weights=density, minlength=n)
        )
    log_weight = -np.log(proposal)  # the uniform prior's density is a constant
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
                "do not fit the scans, or n is too small"
            )
        weights = np.exp(log_weight - np.max(log_weight))
        weights /= weights.sum()
        means[t] = weights @ starts
        deviation = starts - means[t]
        covs[t] = np.einsum("n,ni,nj->ij", weights, deviation, deviation)
        ess[t] = 1.0 / np.sum(weights**2)
    return means, covs, ess
