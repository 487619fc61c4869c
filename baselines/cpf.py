"""Multiple-model convolution particle filter (CPF), the model-based baseline of Sec. VII-F.

Centralized: one filter processes every sensor's measurements. State per particle
[x, vx, y, vy] and a motion mode m in {0..4}:

- **Transition** (:func:`turn_transition`): the coordinated-turn matrix F(omega_m) printed in
  Sec. VII-F with T_s = dt and omega = (0, 0.55, 0.49, -0.55, -0.49) rad/s (omega = 0 is the
  constant-velocity model, its limit), plus white acceleration noise of standard deviation
  ``acceleration_std`` (the paper does not print it).
- **Modes**: a Markov chain with the printed 5 x 5 transition matrix and initial
  probabilities (0.6, 0.1, 0.1, 0.1, 0.1), sampled per particle.
- **Update**: the Poisson likelihood with clutter, eq. (42) (:mod:`agents.likelihood`).
- **Resampling**: systematic, when the effective sample size falls below
  ``resample_threshold`` x N, followed by the convolution (regularisation) step: every
  resampled state is jittered by a Gaussian kernel whose covariance is the weighted
  covariance of the particles times Silverman's bandwidth factor (Musso, Oudjane and Le
  Gland's regularised particle filter). The paper prints no kernel. Its position variance
  is floored at the least that the filter's own model allows the posterior after the step
  (:func:`least_position_variance`): when the weights have degenerated onto a few
  particles, their weighted covariance, and with it Silverman's kernel, is about 0, and
  without the floor the resampled cloud collapses onto one point and reports a variance
  near 0 (dgpt-gym before 0.25.0: the episodes' ANEES on sensed steps up to 5e7).

Initialisation (first step with measurements): positions are drawn around the
measurements (each particle picks one at random and adds N(0, sigma_z^2 I)), velocities
uniform in heading with speeds up to ``max_initial_speed``; the step's Poisson likelihood
then weighs them, so clutter-seeded particles lose weight to the dense target cluster. The
same re-initialisation recovers a lost track: when every measurement of a step lies more
than ``REACQUIRE_SIGMAS`` sigma_z from every particle (after an abrupt manoeuvre or a long
coverage gap, which no reweighting can repair).
Steps without measurements only predict. The same parameters serve all four scenarios, as
in the paper.
"""

from __future__ import annotations

import numpy as np

from agents.likelihood import PoissonLikelihood, nearest_squared_distance
from agents.particles import resample_systematic
from dgpt_gym.problem import ProblemSpec
from dgpt_gym.tracker import Estimate, TrackerBase
from dgpt_gym.validation import check_integer, check_real

__all__ = [
    "MultipleModelCPF",
    "turn_transition",
    "TURN_RATES",
    "MODE_TRANSITION",
    "INITIAL_MODE_PROBABILITIES",
    "least_position_variance",
    "validate_mode_transition",
]

TURN_RATES = np.array([0.0, 0.55, 0.49, -0.55, -0.49])
"""omega of the five modes, rad/s (Sec. VII-F)."""

MODE_TRANSITION = np.array(
    [
        [0.84, 0.05, 0.03, 0.05, 0.03],
        [0.05, 0.88, 0.07, 0.00, 0.00],
        [0.03, 0.07, 0.90, 0.00, 0.00],
        [0.05, 0.00, 0.00, 0.88, 0.07],
        [0.03, 0.00, 0.00, 0.07, 0.90],
    ]
)
"""P[i, j] = P(mode j at t | mode i at t - 1), as printed in Sec. VII-F."""

INITIAL_MODE_PROBABILITIES = np.array([0.6, 0.1, 0.1, 0.1, 0.1])

REACQUIRE_SIGMAS = 5.0
"""The track is re-initialised when every measurement is farther than this many sigma_z
from every particle."""


def turn_transition(omega: float, dt: float) -> np.ndarray:
    """F(omega) of Sec. VII-F for the state [x, vx, y, vy]; omega -> 0 gives the
    constant-velocity matrix (the limits sin(w T)/w -> T, (1 - cos(w T))/w -> 0)."""
    if abs(omega) < 1e-9:
        return np.array(
            [[1.0, dt, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, dt], [0.0, 0.0, 0.0, 1.0]]
        )
    s, c = np.sin(omega * dt), np.cos(omega * dt)
    return np.array(
        [
            [1.0, s / omega, 0.0, -(1.0 - c) / omega],
            [0.0, c, 0.0, -s],
            [0.0, (1.0 - c) / omega, 1.0, s / omega],
            [0.0, s, 0.0, c],
        ]
    )


def least_position_variance(
    dt: float, acceleration_std: float, noise_std: float, n_measurements: int
) -> float:
    """The least position variance per axis, m^2, that the CPF's motion model allows the
    exact posterior after a step with ``n_measurements`` measurements of sd ``noise_std``:
    1 / (1 / q + m / sigma_z^2) with q = (dt^2 / 2 x ``acceleration_std``)^2, the position
    variance the step's acceleration noise adds. Given the previous state, the mode and the
    association the posterior is Gaussian with at least this variance (all m measurements
    the target's); by the law of total variance the posterior, a mixture over those, varies
    at least as much. 0 without acceleration noise; ``noise_std`` must be positive (the
    filter passes the spec's ``model_noise_std``, floored at 1 mm)."""
    check_real("noise_std", noise_std, low=0.0, low_inclusive=False)
    q = (0.5 * dt**2 * acceleration_std) ** 2
    if q == 0.0:
        return 0.0
    return 1.0 / (1.0 / q + n_measurements / noise_std**2)


def validate_mode_transition(matrix: np.ndarray, name: str = "mode_transition") -> np.ndarray:
    """A square row-stochastic matrix (non-negative rows summing to 1), or ``ValueError``."""
    matrix = np.asarray(matrix, dtype=float)
    if matrix.ndim != 2 or matrix.shape[0] != matrix.shape[1]:
        raise ValueError(f"{name} must be a square matrix; got shape {matrix.shape}")
    if (
        not np.all(np.isfinite(matrix))
        or np.any(matrix < 0)
        or not np.allclose(matrix.sum(axis=1), 1.0)
    ):
        raise ValueError(
            f"{name} must be row-stochastic (non-negative rows summing to 1); got {matrix.tolist()}"
        )
    return matrix


class MultipleModelCPF(TrackerBase):
    """Multiple-model convolution particle filter; see the module docstring.

    Args:
        n_particles: N (default 2000).
        acceleration_std: white acceleration noise per axis, m/s^2 (default 2: covers the
            speed changes of S1's waypoints over a few steps without blurring a straight leg).
        turn_rates: omega per mode, rad/s.
        mode_transition: row-stochastic mode transition matrix.
        initial_mode_probabilities: a probability vector.
        resample_threshold: resample when ESS < threshold x N, in (0, 1].
        max_initial_speed: upper bound of the initial speed, m/s.
        kernel_position_std_floor: least standard deviation (m) of the convolution kernel
            per position axis; None (the default) floors its variance at the step's
            :func:`least_position_variance` instead, and 0 leaves Silverman's kernel alone,
            as dgpt-gym before 0.25.0 did. Chosen on training seeds 1000-1029 (S1-S4,
            clutter 1 and 5, both path modes, sigma_z 1 and 4) against 0, 0.5, 1 and 2 m:
            docs/analysis.md, section "0.25.0".
    """

    name = "cpf"

    def __init__(
        self,
        n_particles: int = 2000,
        acceleration_std: float = 2.0,
        turn_rates: np.ndarray = TURN_RATES,
        mode_transition: np.ndarray = MODE_TRANSITION,
        initial_mode_probabilities: np.ndarray = INITIAL_MODE_PROBABILITIES,
        resample_threshold: float = 0.5,
        max_initial_speed: float = 30.0,
        kernel_position_std_floor: float | None = None,
    ) -> None:
        self.n_particles = check_integer("n_particles", n_particles, low=1)
        self.acceleration_std = check_real("acceleration_std", acceleration_std, low=0.0)
        self.turn_rates = np.asarray(turn_rates, dtype=float)
        self.mode_transition = validate_mode_transition(mode_transition)
        probabilities = np.asarray(initial_mode_probabilities, dtype=float)
        if (
            probabilities.shape != (self.turn_rates.size,)
            or np.any(probabilities < 0)
            or not np.isclose(probabilities.sum(), 1.0)
        ):
            raise ValueError(
                f"initial_mode_probabilities must be a probability vector of length {self.turn_rates.size}; "
                f"got {probabilities.tolist()}"
            )
        if self.mode_transition.shape[0] != self.turn_rates.size:
            raise ValueError(
                f"mode_transition must be {self.turn_rates.size} x {self.turn_rates.size} to match turn_rates; "
                f"got {self.mode_transition.shape}"
            )
        self.initial_mode_probabilities = probabilities
        self.resample_threshold = check_real(
            "resample_threshold", resample_threshold, low=0.0, high=1.0, low_inclusive=False
        )
        self.max_initial_speed = check_real("max_initial_speed", max_initial_speed, low=0.0)
        self.kernel_position_std_floor = (
            None
            if kernel_position_std_floor is None
            else check_real("kernel_position_std_floor", kernel_position_std_floor, low=0.0)
        )

    def reset(self, spec: ProblemSpec, seed: int | None = None) -> None:
        self.spec_ = spec
        self.rng_ = np.random.default_rng(seed)
        self.likelihood_ = PoissonLikelihood.from_spec(spec)
        self.transitions_ = np.stack([turn_transition(w, spec.dt) for w in self.turn_rates])
        self.cumulative_transition_ = np.cumsum(self.mode_transition, axis=1)
        self.particles_: np.ndarray | None = None
        self.modes_: np.ndarray | None = None
        self.log_weights_: np.ndarray | None = None
        self.reinitialisations_ = 0

    # -- filter steps ---------------------------------------------------------------------

    def _initialise(self, measurements: np.ndarray) -> None:
        n, rng = self.n_particles, self.rng_
        seeds = measurements[rng.integers(0, measurements.shape[0], n)]
        positions = seeds + rng.normal(0.0, self.spec_.model_noise_std, (n, 2))
        heading = rng.uniform(0.0, 2.0 * np.pi, n)
        speed = self.max_initial_speed * np.sqrt(rng.random(n))
        self.particles_ = np.column_stack(
            [positions[:, 0], speed * np.cos(heading), positions[:, 1], speed * np.sin(heading)]
        )
        self.modes_ = rng.choice(self.turn_rates.size, n, p=self.initial_mode_probabilities)
        self.log_weights_ = np.full(n, -np.log(n))

    def _predict(self) -> None:
        rng, dt = self.rng_, self.spec_.dt
        uniform = rng.random(self.n_particles)
        self.modes_ = (uniform[:, None] > self.cumulative_transition_[self.modes_]).sum(axis=1)
        self.modes_ = np.minimum(self.modes_, self.turn_rates.size - 1)
        moved = np.empty_like(self.particles_)
        for mode, transition in enumerate(self.transitions_):  # five modes, not particles
            chosen = self.modes_ == mode
            moved[chosen] = self.particles_[chosen] @ transition.T
        self.particles_ = moved
        noise = rng.normal(0.0, self.acceleration_std, (self.n_particles, 2))
        self.particles_[:, [0, 2]] += 0.5 * dt**2 * noise
        self.particles_[:, [1, 3]] += dt * noise

    def _lost(self, measurements: np.ndarray) -> bool:
        """True when no particle is within ``REACQUIRE_SIGMAS`` sigma_z of any measurement:
        the target left the cloud (an abrupt manoeuvre, a long gap) and no reweighting can
        bring it back."""
        closest = nearest_squared_distance(self.particles_[:, [0, 2]], measurements)
        return closest > (REACQUIRE_SIGMAS * self.spec_.model_noise_std) ** 2

    def _update(self, measurements: np.ndarray) -> None:
        if self._lost(measurements):
            self.reinitialisations_ += 1
            self._initialise(measurements)
        positions = self.particles_[:, [0, 2]]
        self.log_weights_ = self.log_weights_ + self.likelihood_.log_likelihood(
            positions, measurements
        )
        self.log_weights_ -= np.logaddexp.reduce(self.log_weights_)
        weights = np.exp(self.log_weights_)
        if 1.0 / np.sum(weights**2) < self.resample_threshold * self.n_particles:
            self._resample(weights, measurements.shape[0])

    def _resample(self, weights: np.ndarray, n_measurements: int) -> None:
        """Systematic resampling followed by the Gaussian convolution kernel, whose position
        variance is floored (``kernel_position_std_floor``; by default the step's
        :func:`least_position_variance`)."""
        n, rng = self.n_particles, self.rng_
        index = resample_systematic(weights, rng)
        mean = weights @ self.particles_
        centred = self.particles_ - mean
        covariance = (weights[:, None] * centred).T @ centred
        dimension = self.particles_.shape[1]
        bandwidth = (4.0 / (n * (dimension + 2))) ** (1.0 / (dimension + 4))
        kernel = bandwidth**2 * covariance
        if self.kernel_position_std_floor is None:
            floor = least_position_variance(
                self.spec_.dt, self.acceleration_std, self.spec_.model_noise_std, n_measurements
            )
        else:
            floor = self.kernel_position_std_floor**2
        positions = [0, 2]
        kernel[positions, positions] = np.maximum(kernel[positions, positions], floor)
        factor = np.linalg.cholesky(kernel + 1e-9 * np.eye(dimension))
        self.particles_ = self.particles_[index] + rng.normal(size=(n, dimension)) @ factor.T
        self.modes_ = self.modes_[index]
        self.log_weights_ = np.full(n, -np.log(n))

    # -- Tracker API ----------------------------------------------------------------------

    def mode_probabilities(self) -> np.ndarray:
        """Posterior probability of each mode (weights summed per mode)."""
        weights = np.exp(self.log_weights_)
        return np.bincount(self.modes_, weights=weights, minlength=self.turn_rates.size)

    def update(self, obs: dict) -> Estimate:
        if self.spec_ is None:
            raise RuntimeError("call reset(spec) before update(obs)")
        mask = np.asarray(obs["mask"]).astype(bool)
        measurements = np.asarray(obs["measurements"], dtype=float)[mask]
        if self.particles_ is None:
            if measurements.shape[0] == 0:
                return Estimate.uninformed(self.spec_)
            self._initialise(measurements)
        else:
            self._predict()
        if measurements.shape[0]:
            self._update(measurements)
        weights = np.exp(self.log_weights_)
        positions = self.particles_[:, [0, 2]]
        mean = weights @ positions
        var = weights @ (positions - mean) ** 2
        return Estimate(mean, np.maximum(var, 1e-12))
