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
from scipy.spatial import KDTree

from dgpt_gym.problem import ProblemSpec

__all__ = [
    "PoissonLikelihood",
    "squared_distances",
    "measurement_chunks",
    "nearest_squared_distance",
    "CHUNK_ELEMENTS",
    "NEAR_PAIRS_MIN_MEASUREMENTS",
    "NEAR_LOG_RATIO_CUTOFF",
]

CHUNK_ELEMENTS = 2**21
"""Position-measurement pairs evaluated at once (an offsets array of 32 MiB): a scan with
heavy clutter is processed in chunks of measurements instead of one array that grows with
particles x measurements. Scans of the paper's grid fit in one chunk."""


NEAR_PAIRS_MIN_MEASUREMENTS = 128
"""From this many measurements in a scan, :meth:`PoissonLikelihood.log_likelihood` (with
clutter) and :func:`nearest_squared_distance` use only the position-measurement pairs a
KD-tree finds near each other, instead of forming all of them. Against 2000 particles the
near pairs are the faster way from about 16 measurements at sigma_z 1 and 64 at sigma_z 4
(docs/performance.md, "Large scans in the CPF"); the dense way is kept below 128, which the
paper's grid never reaches (at most 76 points a scan), so the grid's CPF numbers are those
of the dense sums."""

NEAR_LOG_RATIO_CUTOFF = -50.0
"""The near pairs of :meth:`PoissonLikelihood.log_likelihood` are those whose target term
is at least exp(-50) ~ 2e-22 times the clutter density: each pair left out would add at
most log1p(2e-22) ~ 2e-22 to a position's log-likelihood, far below its rounding."""


def measurement_chunks(n_positions: int, n_measurements: int) -> list[slice]:
    """Slices of the measurement axis with at most :data:`CHUNK_ELEMENTS` pairs each."""
    size = max(1, CHUNK_ELEMENTS // max(n_positions, 1))
    return [slice(start, start + size) for start in range(0, n_measurements, size)]


def squared_distances(positions: np.ndarray, measurements: np.ndarray) -> np.ndarray:
    """|x_i - z_j|^2 for positions (P, 2) and measurements (n, 2): a (P, n) array."""
    offsets = positions[:, None, :] - measurements[None, :, :]
    return np.einsum("pnk,pnk->pn", offsets, offsets)


def nearest_squared_distance(positions: np.ndarray, measurements: np.ndarray) -> float:
    """min over i, j of |x_i - z_j|^2 for positions (P, 2) and measurements (n, 2), n >= 1:
    every pair formed, in chunks, or from :data:`NEAR_PAIRS_MIN_MEASUREMENTS` finite
    measurements on, the nearest measurement of each position from a KD-tree."""
    if measurements.shape[0] >= NEAR_PAIRS_MIN_MEASUREMENTS and _all_finite(
        positions, measurements
    ):
        distances, _ = KDTree(measurements).query(positions)
        return float(np.min(distances) ** 2)
    return min(
        float(squared_distances(positions, measurements[chunk]).min())
        for chunk in measurement_chunks(len(positions), len(measurements))
    )


def _all_finite(*arrays: np.ndarray) -> bool:
    """A KD-tree raises on non-finite coordinates; the dense sums carry them along."""
    return all(bool(np.all(np.isfinite(array))) for array in arrays)


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
        """log p(Z | x_i) up to a constant, eq. (42), for positions (P, 2): shape (P,), the
        sum of :meth:`log_factors` over the measurements. With clutter and from
        :data:`NEAR_PAIRS_MIN_MEASUREMENTS` finite measurements on it is summed from the
        near pairs only (:meth:`near_log_likelihood`), the same values up to rounding."""
        if (
            self.clutter_rate > 0.0
            and measurements.shape[0] >= NEAR_PAIRS_MIN_MEASUREMENTS
            and _all_finite(positions, measurements)
        ):
            return self.near_log_likelihood(positions, measurements)
        total = np.zeros(positions.shape[0])
        for chunk in measurement_chunks(positions.shape[0], measurements.shape[0]):
            total += self.log_factors(positions, measurements[chunk]).sum(axis=1)
        return total

    def near_log_likelihood(
        self,
        positions: np.ndarray,
        measurements: np.ndarray,
        cutoff: float = NEAR_LOG_RATIO_CUTOFF,
    ) -> np.ndarray:
        """:meth:`log_likelihood` with clutter (finite inputs), as n log c plus, over the
        pairs (i, j) whose target-to-clutter ratio rho_ij = (lambda_T N(z_j; x_i,
        sigma_z^2 I)) / c is at least e^``cutoff``, log1p(rho_ij): each factor of eq. (42)
        is c (1 + rho_ij). Those pairs lie within |x_i - z_j|^2 <= 2 sigma_z^2 (log(rho_max)
        - cutoff), rho_max = lambda_T / (2 pi sigma_z^2 c), and a KD-tree of each side finds
        them, so a scan of n points costs about the pairs near the positions, not P n."""
        if not self.clutter_rate > 0.0:
            raise ValueError(
                f"near_log_likelihood needs clutter (clutter_rate > 0); got {self.clutter_rate}"
            )
        variance = self.noise_std**2
        log_clutter = np.log(self.clutter_density)
        log_peak_ratio = np.log(self.detection_rate / (2.0 * np.pi * variance)) - log_clutter
        total = np.full(positions.shape[0], measurements.shape[0] * log_clutter)
        radius2 = 2.0 * variance * (log_peak_ratio - cutoff)
        if radius2 <= 0.0:  # no pair reaches the cutoff
            return total
        tree = KDTree(positions)
        # in chunks of measurements, as the dense sums: when every pair is near (a wide
        # sigma_z, a dense scan) the pairs are as many as the dense array's entries
        for chunk in measurement_chunks(positions.shape[0], measurements.shape[0]):
            pairs = tree.sparse_distance_matrix(
                KDTree(measurements[chunk]), np.sqrt(radius2), output_type="ndarray"
            )
            terms = np.log1p(np.exp(log_peak_ratio - 0.5 * pairs["v"] ** 2 / variance))
            total += np.bincount(pairs["i"], terms, minlength=positions.shape[0])
        return total
