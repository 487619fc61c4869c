"""What a tracker may know about the problem: :class:`ProblemSpec`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ProblemSpec"]


@dataclass(frozen=True, eq=False)
class ProblemSpec:
    """The sensor network and the measurement model, handed to trackers at reset.

    Model-based trackers (the hybrid filter, the CPF) use the rates and the noise level, as
    the paper assumes them known; data-driven trackers must not use ``noise_std``.

    Attributes:
        sensor_positions: (n_sensors, 2) sensor coordinates, m.
        sensing_range: r, m.
        noise_std: sigma_z of target measurements, m.
        clutter_rate: lambda_c, clutter points per clutter-producing sensor per step.
        detection_rate: lambda_T of the zero-truncated Poisson target count.
        dt: sampling period, s.
        area: side of the square surveillance area, m.
        clutter_sensors: ``"detecting"`` or ``"all"``.
        n_steps: episode length in steps.
    """

    sensor_positions: np.ndarray
    sensing_range: float
    noise_std: float
    clutter_rate: float
    detection_rate: float
    dt: float
    area: float
    clutter_sensors: str
    n_steps: int

    @property
    def sensing_area(self) -> float:
        """A_sen = pi r^2, the area of one sensing disc."""
        return float(np.pi * self.sensing_range**2)

    @property
    def n_sensors(self) -> int:
        return int(self.sensor_positions.shape[0])
