"""What a tracker may know about the problem: :class:`ProblemSpec`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dgpt_gym.measurements import CLUTTER_SENSORS
from dgpt_gym.validation import check_choice, check_integer, check_real

__all__ = ["ProblemSpec", "MIN_MODEL_NOISE_STD"]

MIN_MODEL_NOISE_STD = 1e-3
"""m: the smallest sigma_z a model-based tracker assumes (a millimetre: far below any
error the trackers reach, far above what makes a Gaussian density overflow)."""


@dataclass(frozen=True, eq=False)
class ProblemSpec:
    """The sensor network and the measurement model, handed to trackers at reset.

    Model-based trackers (the hybrid filter, the CPF) use the rates and the noise level, as
    the paper assumes them known; the GP models must not use ``noise_std`` (they learn
    sigma_n). With ``clutter_sensors="all"`` DGPT's screening of clutter-only sensors and
    its track start use the rates and ``noise_std`` (``agents/screening.py``).

    Attributes:
        sensor_positions: (n_sensors, 2) sensor coordinates, m.
        sensing_range: r, m.
        noise_std: sigma_z of target measurements, m, >= 0 (0: exact target measurements;
            model-based trackers use :attr:`model_noise_std`).
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

    def __post_init__(self) -> None:
        # trackers divide by these; the env checks them too, a hand-built spec gets the same
        for name in ("sensing_range", "detection_rate", "dt", "area"):
            check_real(name, getattr(self, name), low=0.0, low_inclusive=False)
        for name in ("noise_std", "clutter_rate"):
            check_real(name, getattr(self, name), low=0.0)
        check_choice("clutter_sensors", self.clutter_sensors, CLUTTER_SENSORS)
        check_integer("n_steps", self.n_steps, low=1)
        positions = np.asarray(self.sensor_positions)
        if positions.ndim != 2 or positions.shape[1] != 2 or not np.all(np.isfinite(positions)):
            raise ValueError(
                "sensor_positions must be a finite (n_sensors, 2) array; got shape "
                f"{positions.shape}"
            )

    @property
    def model_noise_std(self) -> float:
        """The sigma_z model-based trackers assume: ``noise_std``, floored at
        :data:`MIN_MODEL_NOISE_STD` so that exact measurements (``noise_std = 0``) leave
        their Gaussian likelihoods and Kalman gains finite."""
        return max(self.noise_std, MIN_MODEL_NOISE_STD)

    @property
    def sensing_area(self) -> float:
        """A_sen = pi r^2, the area of one sensing disc."""
        return float(np.pi * self.sensing_range**2)

    @property
    def clutter_density(self) -> float:
        """c = lambda_c / A_sen, the density of one clutter-producing sensor's clutter in its
        disc (per m^2)."""
        return self.clutter_rate / self.sensing_area

    @property
    def n_sensors(self) -> int:
        return int(self.sensor_positions.shape[0])
