"""Building blocks of particle filters shared by the trackers that use particles: the
multiple-model CPF (:mod:`baselines.cpf`) and the state-space DGPT's coverage-gap filter
(:mod:`agents.silence`)."""

from __future__ import annotations

import numpy as np

__all__ = ["kernel_scale", "resample_systematic"]


def kernel_scale(n: int, dimension: int = 4) -> float:
    """h^2 of Silverman's rule for a Gaussian kernel density of ``n`` particles in
    ``dimension`` dimensions, h = (4 / (n (d + 2)))^(1 / (d + 4)): the kernels' covariance is
    h^2 times the particles' (Musso, Oudjane & Le Gland 2001, the regularized particle
    filter). The state [x, vx, y, vy] has d = 4; n = 1000 gives 0.16."""
    return (4.0 / (n * (dimension + 2.0))) ** (2.0 / (dimension + 4.0))


def resample_systematic(
    weights: np.ndarray, rng: np.random.Generator, n: int | None = None
) -> np.ndarray:
    """Indices (n,) of systematic resampling of the weights (N,) summing to one (one
    uniform draw; Douc, Cappe & Moulines 2005); n = N unless given."""
    n = weights.size if n is None else n
    positions = (rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(np.cumsum(weights), positions), weights.size - 1)
