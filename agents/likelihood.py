"""The Poisson measurement likelihood with clutter (paper Sec. VI-A, eqs. (40)-(43)), shared
by the hybrid filter and the multiple-model convolution particle filter.

For the measurements z_1..z_n of one step,

    p(Z | x)  proportional to  prod_j ( lambda_c / A_sen + lambda_T N(z_j; x, sigma_z^2 I) ),

eq. (42), with the clutter density uniform over a sensing disc of area A_sen = pi r^2 and
the rates and noise known (:class:`~dgpt_gym.problem.ProblemSpec`). The product is a sum
of log factors, so hundreds of measurements do not underflow; each factor is at least the
clutter density (or, without clutter, computed in log space).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dgpt_gym.problem import ProblemSpec

__all__ = ["PoissonLikelihood"]


@dataclass(frozen=True)
class PoissonLikelihood:
    """Eq. (42) for 2-D positions.

    Attributes:
        clutter_rate: lambda_c.
        detection_rate: lambda_T.
        noise_std: sigma_z, m.
        sensing_area: A_sen, m^2.
    """

    clutter_rate: float
    detection_rate: float
    noise_std: float
    sensing_area: float

    @classmethod
    def from_spec(cls, spec: ProblemSpec) -> PoissonLikelihood:
        return cls(spec.clutter_rate, spec.detection_rate, spec.noise_std, spec.sensing_area)

    @property
    def clutter_density(self) -> float:
        """lambda_c / A_sen, the clutter term of every factor."""
        return self.clutter_rate / self.sensing_area

    def log_factors(self, positions: np.ndarray, measurements: np.ndarray) -> np.ndarray:
        """log(lambda_c / A_sen + lambda_T N(z_j; x_i, sigma_z^2 I)) for every position x_i
        (P, 2) and measurement z_j (n, 2): an (P, n) array."""
        variance = self.noise_std**2
        offsets = positions[:, None, :] - measurements[None, :, :]
        squared = np.einsum("pnk,pnk->pn", offsets, offsets)
        peak = self.detection_rate / (2.0 * np.pi * variance)
        if self.clutter_rate == 0.0:
            return np.log(peak) - 0.5 * squared / variance
        # every factor is at least the clutter density c > 0: no underflow in linear space
        return np.log(self.clutter_density + peak * np.exp(-0.5 * squared / variance))

    def log_likelihood(self, positions: np.ndarray, measurements: np.ndarray) -> np.ndarray:
        """log p(Z | x_i) up to a constant, eq. (42), for positions (P, 2): shape (P,)."""
        if measurements.shape[0] == 0:
            return np.zeros(positions.shape[0])
        return self.log_factors(positions, measurements).sum(axis=1)
