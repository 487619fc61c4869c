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

__all__ = ["PoissonLikelihood", "squared_distances", "measurement_chunks", "CHUNK_ELEMENTS"]

CHUNK_ELEMENTS = 2**21
"""Position-measurement pairs evaluated at once (an offsets array of 32 MiB): a scan with
heavy clutter is processed in chunks of measurements instead of one array that grows with
particles x measurements. Scans of the paper's grid fit in one chunk."""


def measurement_chunks(n_positions: int, n_measurements: int) -> list[slice]:
    """Slices of the measurement axis with at most :data:`CHUNK_ELEMENTS` pairs each."""
    size = max(1, CHUNK_ELEMENTS // max(n_positions, 1))
    return [slice(start, start + size) for start in range(0, n_measurements, size)]


def squared_distances(positions: np.ndarray, measurements: np.ndarray) -> np.ndarray:
    """|x_i - z_j|^2 for positions (P, 2) and measurements (n, 2): a (P, n) array."""
    offsets = positions[:, None, :] - measurements[None, :, :]
    return np.einsum("pnk,pnk->pn", offsets, offsets)


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
        return cls(spec.clutter_rate, spec.detection_rate, spec.model_noise_std, spec.sensing_area)

    @property
    def clutter_density(self) -> float:
        """lambda_c / A_sen, the clutter term of every factor."""
        return self.clutter_rate / self.sensing_area

    def log_factors(self, positions: np.ndarray, measurements: np.ndarray) -> np.ndarray:
        """log(lambda_c / A_sen + lambda_T N(z_j; x_i, sigma_z^2 I)) for every position x_i
        (P, 2) and measurement z_j (n, 2): an (P, n) array."""
        variance = self.noise_std**2
        squared = squared_distances(positions, measurements)
        peak = self.detection_rate / (2.0 * np.pi * variance)
        if self.clutter_rate == 0.0:
            return np.log(peak) - 0.5 * squared / variance
        # every factor is at least the clutter density c > 0: no underflow in linear space
        return np.log(self.clutter_density + peak * np.exp(-0.5 * squared / variance))

    def log_likelihood(self, positions: np.ndarray, measurements: np.ndarray) -> np.ndarray:
        """log p(Z | x_i) up to a constant, eq. (42), for positions (P, 2): shape (P,)."""
        total = np.zeros(positions.shape[0])
        for chunk in measurement_chunks(positions.shape[0], measurements.shape[0]):
            total += self.log_factors(positions, measurements[chunk]).sum(axis=1)
        return total
