"""Target trajectories of the paper's four scenarios S1-S4 (Sec. VII-D, Fig. 3).

The paper names each scenario's motion model but prints no parameters; the values below
are this project's documented choices (docs/design.md, "Decisions"). Every scenario is a
frozen dataclass whose fields are those parameters, and :meth:`Scenario.sample` draws a
trajectory from a ``numpy.random.Generator``:

1. the scenario's motion model produces an *unconstrained* path starting at the origin;
2. a path whose bounding box does not fit inside the allowed region
   ``[boundary_margin, area - boundary_margin]^2`` is rejected and drawn again;
3. an accepted path is translated by an offset drawn uniformly among those that keep it
   inside the region.

Translation leaves velocities, accelerations and turn rates untouched, so the kinematic
properties the paper names (turn rates, acceleration bounds) hold exactly.
``Scenario.reference()`` is the scenario's one fixed trajectory (the paper's Monte Carlo
runs share a single trajectory and vary measurements and clutter): the trajectory drawn
from ``reference_seed``.
"""

from __future__ import annotations

import abc
import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Trajectory",
    "Scenario",
    "NearlyConstantVelocityScenario",
    "CoordinatedTurnScenario",
    "SingerScenario",
    "SCENARIOS",
    "get_scenario",
]


@dataclass(frozen=True)
class Trajectory:
    """A sampled target path: ``positions`` and ``velocities`` of shape (n_steps, 2), m and m/s.

    The manoeuvre record, the truth a clairvoyant filter is told (``None`` where the
    scenario has no such switching):

    - ``turn_rate`` (n_steps,): the coordinated-turn rate over the interval ending at step
      k, rad/s (0 on straight legs and at k = 0); S2 and S3.
    - ``new_leg`` (n_steps,) bool: the velocity was redrawn over the interval ending at step
      k (a waypoint); S1.
    """

    positions: np.ndarray
    velocities: np.ndarray
    dt: float
    turn_rate: np.ndarray | None = None
    new_leg: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name in ("positions", "velocities", "turn_rate", "new_leg"):
            array = getattr(self, name)
            if array is not None:
                array.setflags(write=False)
        if self.positions.shape != self.velocities.shape or self.positions.shape[1:] != (2,):
            raise ValueError(
                "positions and velocities must both have shape (n_steps, 2); got "
                f"{self.positions.shape} and {self.velocities.shape}"
            )

    @property
    def n_steps(self) -> int:
        return int(self.positions.shape[0])

    def accelerations(self) -> np.ndarray:
        """Finite-difference accelerations (n_steps - 1, 2), m/s^2."""
        return np.diff(self.velocities, axis=0) / self.dt

    def turn_rates(self) -> np.ndarray:
        """Heading change per unit time between consecutive steps (n_steps - 1,), rad/s."""
        heading = np.arctan2(self.velocities[:, 1], self.velocities[:, 0])
        return np.angle(np.exp(1j * np.diff(heading))) / self.dt


def _integrate_positions(velocities: np.ndarray, dt: float) -> np.ndarray:
    """Positions from velocities with the trapezoidal rule, starting at the origin.

    Exact for velocities that change linearly within a step (the NCV and Singer models).
    """
    increments = 0.5 * dt * (velocities[1:] + velocities[:-1])
    return np.vstack([np.zeros((1, 2)), np.cumsum(increments, axis=0)])


@dataclass(frozen=True)
class Scenario(abc.ABC):
    """Parameters shared by all scenarios.

    Attributes:
        name: ``"S1"`` .. ``"S4"``.
        n_steps: trajectory length in steps (the paper's trajectories last 100-200 s).
        dt: sampling period, s (the paper: 1 s).
        speed_range: target speed bounds, m/s.
        area: side of the square surveillance area, m.
        boundary_margin: the target stays inside ``[margin, area - margin]^2``.
        reference_seed: seed of the scenario's fixed reference trajectory.
        max_attempts: rejection-sampling budget of :meth:`sample`.
    """

    name: str = ""
    n_steps: int = 150
    dt: float = 1.0
    speed_range: tuple[float, float] = (10.0, 25.0)
    area: float = 1000.0
    boundary_margin: float = 50.0
    reference_seed: int = 0
    max_attempts: int = 2000

    @abc.abstractmethod
    def _unconstrained(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, dict]:
        """Positions (starting at the origin) and velocities of one unconstrained path, and
        its manoeuvre record (:class:`Trajectory`'s ``turn_rate`` / ``new_leg``)."""

    def sample(self, rng: np.random.Generator) -> Trajectory:
        """Draw a trajectory inside ``[margin, area - margin]^2`` (module docstring)."""
        low = self.boundary_margin
        high = self.area - self.boundary_margin
        for _ in range(self.max_attempts):
            positions, velocities, manoeuvres = self._unconstrained(rng)
            lower, upper = positions.min(axis=0), positions.max(axis=0)
            if np.all(upper - lower <= high - low):
                offset = rng.uniform(low - lower, high - upper)
                return Trajectory(positions + offset, velocities, self.dt, **manoeuvres)
        raise RuntimeError(
            f"scenario {self.name}: no trajectory fitted inside [{low}, {high}]^2 in "
            f"{self.max_attempts} attempts; shorten n_steps or lower the speeds"
        )

    def reference(self) -> Trajectory:
        """The scenario's one fixed trajectory (``trajectory="fixed"`` in the env)."""
        return _reference_trajectory(self)

    def parameters(self) -> dict:
        """The documented parameters as a plain dict (for tables and records)."""
        return dataclasses.asdict(self)


@functools.lru_cache(maxsize=64)
def _reference_trajectory(scenario: Scenario) -> Trajectory:
    return scenario.sample(np.random.default_rng(scenario.reference_seed))


@dataclass(frozen=True)
class NearlyConstantVelocityScenario(Scenario):
    """S1: nearly-constant-velocity (NCV) legs with an abrupt velocity change at each waypoint.

    Each leg lasts ``leg_duration_range`` seconds at a speed drawn from ``speed_range``; at a
    waypoint the heading jumps by an angle of magnitude in ``heading_change_deg`` (sign random)
    and a new speed is drawn. Within a leg the velocity follows the NCV model: a random walk
    with white acceleration noise of standard deviation ``acceleration_noise_std`` m/s^2.
    """

    name: str = "S1"
    n_steps: int = 150
    leg_duration_range: tuple[int, int] = (15, 30)
    heading_change_deg: tuple[float, float] = (60.0, 150.0)
    acceleration_noise_std: float = 0.2
    reference_seed: int = 1

    def _unconstrained(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, dict]:
        n_legs = self.n_steps // self.leg_duration_range[0] + 1
        durations = rng.integers(self.leg_duration_range[0], self.leg_duration_range[1] + 1, n_legs)
        speeds = rng.uniform(*self.speed_range, n_legs)
        turns = rng.uniform(*np.deg2rad(self.heading_change_deg), n_legs)
        turns *= rng.choice([-1.0, 1.0], n_legs)
        turns[0] = rng.uniform(-np.pi, np.pi)
        headings = np.cumsum(turns)
        leg_of_step = np.repeat(np.arange(n_legs), durations)[: self.n_steps]
        nominal = speeds[:, None] * np.column_stack([np.cos(headings), np.sin(headings)])
        noise = rng.normal(0.0, self.acceleration_noise_std * self.dt, (self.n_steps, 2))
        # The NCV random walk restarts at every waypoint: cumulative noise within each leg.
        walk = np.cumsum(noise, axis=0)
        leg_start = np.r_[0, np.flatnonzero(np.diff(leg_of_step)) + 1]
        walk -= np.repeat(walk[leg_start], np.diff(np.r_[leg_start, self.n_steps]), axis=0)
        velocities = nominal[leg_of_step] + walk
        speed = np.linalg.norm(velocities, axis=1, keepdims=True)
        velocities *= np.clip(speed, *self.speed_range) / speed
        new_leg = np.zeros(self.n_steps, dtype=bool)
        new_leg[leg_start[1:]] = True
        return _integrate_positions(velocities, self.dt), velocities, {"new_leg": new_leg}


@dataclass(frozen=True)
class CoordinatedTurnScenario(Scenario):
    """S2 and S3: constant-velocity legs alternating with coordinated turns.

    The speed is constant over the trajectory (drawn from ``speed_range``). Legs of
    ``cv_duration_range`` seconds at constant velocity alternate with turns at
    ``turn_rate_deg`` deg/s lasting ``turn_duration`` seconds; the turn direction alternates
    left and right, starting with a random one, so both occur. Positions are integrated
    exactly along the circular arcs.
    """

    name: str = "S2"
    n_steps: int = 150
    turn_rate_deg: float = 20.0
    turn_duration: int = 10
    cv_duration_range: tuple[int, int] = (8, 20)
    reference_seed: int = 2

    def _unconstrained(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, dict]:
        period = self.cv_duration_range[0] + self.turn_duration
        n_legs = self.n_steps // period + 2
        cv_durations = rng.integers(
            self.cv_duration_range[0], self.cv_duration_range[1] + 1, n_legs
        )
        first_sign = rng.choice([-1.0, 1.0])
        omega = np.deg2rad(self.turn_rate_deg)
        rates = []
        for leg, duration in enumerate(cv_durations):
            rates.append(np.zeros(duration))
            rates.append(np.full(self.turn_duration, first_sign * (-1.0) ** leg * omega))
        # rate_per_step[k] is the turn rate between step k and k + 1.
        rate_per_step = np.concatenate(rates)[: self.n_steps - 1]
        speed = rng.uniform(*self.speed_range)
        heading = rng.uniform(-np.pi, np.pi) + np.r_[0.0, np.cumsum(rate_per_step * self.dt)]
        velocities = speed * np.column_stack([np.cos(heading), np.sin(heading)])
        straight = velocities[:-1] * self.dt
        turning = rate_per_step != 0.0
        safe_rate = np.where(turning, rate_per_step, 1.0)
        arc = (speed / safe_rate)[:, None] * np.column_stack(
            [np.sin(heading[1:]) - np.sin(heading[:-1]), np.cos(heading[:-1]) - np.cos(heading[1:])]
        )
        increments = np.where(turning[:, None], arc, straight)
        positions = np.vstack([np.zeros((1, 2)), np.cumsum(increments, axis=0)])
        return positions, velocities, {"turn_rate": np.r_[0.0, rate_per_step]}


@dataclass(frozen=True)
class SingerScenario(Scenario):
    """S4: the Singer acceleration model (Singer, 1970).

    Per axis the acceleration is a first-order Markov process with time constant
    ``time_constant`` (s): ``a[k+1] = rho a[k] + sqrt(1 - rho^2) sigma_m w``, ``rho =
    exp(-dt / time_constant)``, with Singer's variance
    ``sigma_m^2 = max_acceleration^2 / 3 * (1 + 4 prob_max_acceleration - prob_no_acceleration)``.
    The target's acceleration vector is clipped to norm ``max_acceleration``. Speeds are
    kept inside ``speed_range``: a step that would slow the target below the minimum keeps
    only the turning (perpendicular) part of its velocity change, and a speed above the
    maximum is projected onto it. Both operations only shorten the velocity change, so the
    realised acceleration never exceeds ``max_acceleration``. With the defaults (sigma_m =
    25.8 m/s^2, time constant 10 s) the speed bounds absorb much of the acceleration and the
    path is a smooth, continually manoeuvring curve (median realised acceleration ~5 m/s^2).
    """

    name: str = "S4"
    n_steps: int = 150
    max_acceleration: float = 50.0
    prob_no_acceleration: float = 0.4
    prob_max_acceleration: float = 0.05
    time_constant: float = 10.0
    reference_seed: int = 4

    @property
    def acceleration_std(self) -> float:
        """Singer's sigma_m, m/s^2."""
        variance = (
            self.max_acceleration**2
            / 3.0
            * (1.0 + 4.0 * self.prob_max_acceleration - self.prob_no_acceleration)
        )
        return float(np.sqrt(variance))

    def _unconstrained(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, dict]:
        rho = np.exp(-self.dt / self.time_constant)
        sigma = self.acceleration_std
        min_speed, max_speed = self.speed_range
        shocks = rng.normal(0.0, sigma * np.sqrt(1.0 - rho**2), (self.n_steps, 2))
        heading = rng.uniform(-np.pi, np.pi)
        velocity = rng.uniform(min_speed, max_speed) * np.array([np.cos(heading), np.sin(heading)])
        acceleration = rng.normal(0.0, sigma, 2)
        velocities = np.empty((self.n_steps, 2))
        velocities[0] = velocity
        for k in range(1, self.n_steps):  # sequential by nature: each step clips the last
            acceleration = rho * acceleration + shocks[k]
            norm = np.linalg.norm(acceleration)
            if norm > self.max_acceleration:
                acceleration *= self.max_acceleration / norm
            change = acceleration * self.dt
            proposal = velocity + change
            if np.linalg.norm(proposal) < min_speed:
                along = velocity / np.linalg.norm(velocity)
                change = change - min(float(change @ along), 0.0) * along
                proposal = velocity + change
            speed = np.linalg.norm(proposal)
            if speed > max_speed:
                proposal *= max_speed / speed
            velocity = proposal
            velocities[k] = velocity
        return _integrate_positions(velocities, self.dt), velocities, {}


SCENARIOS: dict[str, Scenario] = {
    "S1": NearlyConstantVelocityScenario(),
    "S2": CoordinatedTurnScenario(
        name="S2", turn_rate_deg=20.0, turn_duration=10, reference_seed=2
    ),
    "S3": CoordinatedTurnScenario(name="S3", turn_rate_deg=30.0, turn_duration=9, reference_seed=3),
    "S4": SingerScenario(),
}


def get_scenario(name: str) -> Scenario:
    """The scenario registered under ``name`` (``"S1"`` .. ``"S4"``)."""
    try:
        return SCENARIOS[name]
    except (KeyError, TypeError):
        raise ValueError(f"scenario must be one of {sorted(SCENARIOS)}; got {name!r}") from None


def scenario_table_markdown() -> str:
    """Markdown table of every scenario's parameters (docs/usage.md quotes it verbatim).

    The fields shared by all scenarios (``dt``, ``area``, ``boundary_margin``,
    ``max_attempts``) are left out: they are the same for all and follow the env.
    """
    common = {field.name for field in dataclasses.fields(Scenario)}
    lines = [
        "| scenario | model | steps | speed, m/s | model parameters | reference seed |",
        "|---|---|---|---|---|---|",
    ]
    for name, scenario in SCENARIOS.items():
        specific = ", ".join(
            f"`{key}` = {value}"
            for key, value in scenario.parameters().items()
            if key not in common
        )
        low, high = scenario.speed_range
        lines.append(
            f"| {name} | `{type(scenario).__name__}` | {scenario.n_steps} | {low:g}-{high:g} | "
            f"{specific} | {scenario.reference_seed} |"
        )
    return "\n".join(lines)
