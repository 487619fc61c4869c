"""Target-originated measurements and Poisson clutter (paper Sec. VI, assumptions A1-A3, and
Sec. VII-B).

Every step, each sensor within ``sensing_range`` of the target reports a zero-truncated
Poisson(lambda_T) number of measurements ``z = p + N(0, sigma_z^2 I)``; each
clutter-producing sensor reports Poisson(lambda_c) clutter points uniform in its sensing
disc. A whole episode is simulated at once, vectorized over steps, sensors and
measurements, and stored in compressed-row form (:class:`Scans`), so an environment step is
a slice.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dgpt_gym.network import SensorNetwork

__all__ = [
    "CLUTTER_SENSORS",
    "Scans",
    "zero_truncated_poisson",
    "uniform_in_discs",
    "simulate_scans",
]

CLUTTER_SENSORS = ("detecting", "all")


def zero_truncated_poisson(rng: np.random.Generator, rate: float, size: int) -> np.ndarray:
    """Draws of a Poisson(rate) count conditioned on being at least one; mean rate / (1 - e^-rate).

    Exact construction: given at least one event of a rate-``rate`` Poisson process on
    [0, 1], the first event time T has CDF (1 - e^(-rate s)) / (1 - e^(-rate)); the events
    after it are Poisson(rate (1 - T)). The count is 1 plus those.
    """
    uniform = rng.random(size)
    first_arrival = -np.log1p(uniform * np.expm1(-rate)) / rate
    return 1 + rng.poisson(rate * (1.0 - first_arrival))


def uniform_in_discs(rng: np.random.Generator, centres: np.ndarray, radius: float) -> np.ndarray:
    """One point uniform in the disc of ``radius`` around each row of ``centres`` (n, 2).

    The radius is ``radius * sqrt(U)`` so that P(R <= r) = r^2 / radius^2.
    """
    n = centres.shape[0]
    distance = radius * np.sqrt(rng.random(n))
    angle = rng.uniform(0.0, 2.0 * np.pi, n)
    return centres + distance[:, None] * np.column_stack([np.cos(angle), np.sin(angle)])


@dataclass(frozen=True, eq=False)
class Scans:
    """All measurements of an episode; the rows of step ``t`` are ``offsets[t]:offsets[t + 1]``.

    Within a step, rows are grouped by reporting sensor (ascending) in random order inside
    each sensor, so target and clutter measurements are indistinguishable by position in
    the list. ``is_target`` is the truth and is never shown to trackers.
    ``detecting`` is the (n_steps, n_sensors) matrix of which sensors sense the target.
    """

    measurements: np.ndarray
    sensor: np.ndarray
    is_target: np.ndarray
    offsets: np.ndarray
    detecting: np.ndarray

    @property
    def n_steps(self) -> int:
        return int(self.offsets.shape[0] - 1)

    def rows(self, step: int) -> slice:
        return slice(int(self.offsets[step]), int(self.offsets[step + 1]))

    def counts(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-step numbers of target and of clutter measurements, each (n_steps,)."""
        per_step = np.diff(self.offsets)
        step_of_row = np.repeat(np.arange(self.n_steps), per_step)
        n_target = np.bincount(step_of_row[self.is_target], minlength=self.n_steps)
        return n_target, per_step - n_target


def simulate_scans(
    rng: np.random.Generator,
    network: SensorNetwork,
    positions: np.ndarray,
    noise_std: float,
    detection_rate: float,
    clutter_rate: float,
    clutter_sensors: str = "detecting",
) -> Scans:
    """Simulate the measurements of every step of a target path ``positions`` (n_steps, 2).

    Args:
        rng: the only source of randomness.
        network: sensor layout and sensing range.
        positions: true target position per step, m.
        noise_std: sigma_z, standard deviation per axis of target measurements, m.
        detection_rate: lambda_T of the zero-truncated Poisson count per detecting sensor.
        clutter_rate: lambda_c, mean clutter count per clutter-producing sensor per step.
        clutter_sensors: ``"detecting"`` (clutter only at sensors that sense the target, as
            in the paper) or ``"all"`` (at every sensor).
    """
    if clutter_sensors not in CLUTTER_SENSORS:
        raise ValueError(
            f"clutter_sensors must be one of {CLUTTER_SENSORS}; got {clutter_sensors!r}"
        )
    n_steps = positions.shape[0]
    detecting = network.in_range(positions)
    detect_step, detect_sensor = np.nonzero(detecting)

    target_counts = zero_truncated_poisson(rng, detection_rate, detect_step.size)
    target_step = np.repeat(detect_step, target_counts)
    target_sensor = np.repeat(detect_sensor, target_counts)
    target_z = positions[target_step] + rng.normal(0.0, noise_std, (target_step.size, 2))

    if clutter_sensors == "detecting":
        source_step, source_sensor = detect_step, detect_sensor
    else:
        source_step = np.repeat(np.arange(n_steps), network.n_sensors)
        source_sensor = np.tile(np.arange(network.n_sensors), n_steps)
    clutter_counts = rng.poisson(clutter_rate, source_step.size)
    clutter_step = np.repeat(source_step, clutter_counts)
    clutter_sensor = np.repeat(source_sensor, clutter_counts)
    clutter_z = uniform_in_discs(rng, network.positions[clutter_sensor], network.sensing_range)

    step = np.concatenate([target_step, clutter_step])
    sensor = np.concatenate([target_sensor, clutter_sensor])
    is_target = np.concatenate([np.ones(target_step.size, bool), np.zeros(clutter_step.size, bool)])
    order = np.lexsort((rng.random(step.size), sensor, step))
    step = step[order]
    return Scans(
        measurements=np.concatenate([target_z, clutter_z])[order],
        sensor=sensor[order].astype(np.int64),
        is_target=is_target[order],
        offsets=np.searchsorted(step, np.arange(n_steps + 1)).astype(np.int64),
        detecting=detecting,
    )
