"""The sliding window of gated summaries (paper Sec. IV-B) and its arrangement into padded
expert arrays for the GP core."""

from __future__ import annotations

import dataclasses
from collections import deque
from dataclasses import dataclass

import numpy as np

from agents.gating import group_starts

__all__ = [
    "StepRecord",
    "SlidingWindow",
    "ExpertData",
    "padded_size",
    "pad_by_group",
    "window_prior_mean",
    "PRIOR_MEANS",
]


@dataclass(frozen=True)
class StepRecord:
    """The gated summaries of one step: ``sensors`` (k,), ``summaries`` (k, 2), and the
    tracker's estimate of the previous step (2,), the spatial input of STGP (eq. (25))."""

    step: int
    sensors: np.ndarray
    summaries: np.ndarray
    previous_estimate: np.ndarray


def pad_by_group(groups: np.ndarray, *values: np.ndarray):
    """Arrange rows by group into padded arrays.

    ``groups`` (N,) labels; each of ``values`` (N, ...). Returns ``(labels (M,), mask (M, n),
    padded values (M, n, ...))`` with the rows of each group in their original order and
    zeros in the padding, n being the largest group size.
    """
    order = np.argsort(groups, kind="stable")
    sorted_groups = groups[order]
    starts = group_starts(sorted_groups)
    sizes = np.diff(np.r_[starts, sorted_groups.size])
    group_index = np.repeat(np.arange(starts.size), sizes)
    slot = np.arange(sorted_groups.size) - np.repeat(starts, sizes)
    mask = np.zeros((starts.size, int(sizes.max())), dtype=bool)
    mask[group_index, slot] = True
    padded = []
    for value in values:
        array = np.zeros((starts.size, mask.shape[1]) + value.shape[1:], dtype=value.dtype)
        array[group_index, slot] = value[order]
        padded.append(array)
    return sorted_groups[starts], mask, padded


def padded_size(size: int) -> int:
    """The smallest of 1, 2, 3, 4, 6, 8, 12, 16, 24, ... (powers of two and 1.5 times them)
    that is at least ``size``.

    Expert arrays are padded to these sizes, alone or stacked with other episodes', so an
    episode's arrays have the same shape whatever it is batched with, and the GP core's
    results, which are exact under batching but change in the last bits with the padded
    shape, are identical in a single run and in a lockstep batch (:func:`agents.dgpt.update_batch`).
    At most 1.5 times the size.
    """
    if size <= 2:
        return max(int(size), 1)
    power = 1 << (int(size) - 1).bit_length()
    return 3 * power // 4 if 3 * power // 4 >= size else power


@dataclass(frozen=True)
class ExpertData:
    """Training data of the experts for both axes, of one episode or stacked over episodes
    (a leading axis E on every field, :meth:`stack`).

    ``sensors`` (M,) the expert sensors (a single -1 for one pooled expert, -2 on padding);
    ``X`` (2, M, n, d) inputs, ``z`` (2, M, n) outputs minus the prior mean, ``mask`` (M, n)
    True for real points. The prior mean of each axis is ``intercept + slope * tau`` (each
    (2,)) at the time ``tau`` relative to the window's end (:meth:`prior_mean`), with the
    least-squares coefficient matrix ``trend_covariance`` (2, 2).
    """

    sensors: np.ndarray
    X: np.ndarray
    z: np.ndarray
    mask: np.ndarray
    intercept: np.ndarray
    slope: np.ndarray
    trend_covariance: np.ndarray

    @property
    def n_points(self) -> int:
        return int(self.mask.sum())

    @property
    def experts(self) -> np.ndarray:
        """(..., M) True for real experts, False for padding."""
        return self.mask.any(axis=-1)

    def prior_mean(self, relative_time: float) -> np.ndarray:
        """(..., 2) prior mean of the coordinates at ``relative_time`` (s after the window's
        end)."""
        return self.intercept + self.slope * relative_time

    def prior_mean_variance(self, relative_time: float, residual_var: np.ndarray) -> np.ndarray:
        """(..., 2) variance of the estimated prior mean at ``relative_time``: the
        least-squares coefficient covariance ``residual_var (H^T H)^-1`` mapped through
        ``[1, tau]`` (R&W Sec. 2.7: the uncertainty of explicit basis functions adds to the
        predictive variance, and grows quadratically away from the data)."""
        c = self.trend_covariance
        tau = relative_time
        quadratic_form = (
            c[..., 0, 0] + tau * (c[..., 0, 1] + c[..., 1, 0]) + tau * tau * c[..., 1, 1]
        )
        return residual_var * quadratic_form[..., None]

    def padded(self, n_experts: int, n_points: int) -> ExpertData:
        """The same data padded to ``n_experts`` experts of ``n_points`` points (one episode)."""
        experts, points = self.mask.shape
        if (experts, points) == (n_experts, n_points):
            return self
        if experts > n_experts or points > n_points:
            raise ValueError(
                f"cannot pad {experts} experts x {points} points to {n_experts} x {n_points}"
            )
        sensors = np.full(n_experts, -2, dtype=self.sensors.dtype)
        sensors[:experts] = self.sensors
        X = np.zeros((2, n_experts, n_points, self.X.shape[-1]))
        X[:, :experts, :points] = self.X
        z = np.zeros((2, n_experts, n_points))
        z[:, :experts, :points] = self.z
        mask = np.zeros((n_experts, n_points), dtype=bool)
        mask[:experts, :points] = self.mask
        return ExpertData(sensors, X, z, mask, self.intercept, self.slope, self.trend_covariance)

    @classmethod
    def stack(cls, items: list[ExpertData]) -> ExpertData:
        """Episodes' data of equal shapes stacked on a new leading axis."""
        return cls(
            *(np.stack([getattr(item, f.name) for item in items]) for f in dataclasses.fields(cls))
        )


class SlidingWindow:
    """The gated summaries of the window of C = ``length`` steps.

    The window ends at the latest step with summaries: at a step with measurements it is
    the paper's window of the last C steps, and a sensor is an expert while it has at least
    one summary in it. Through a stretch without measurements the window stays where the
    data ended, so the tracker extrapolates from its most recent data with a variance that
    grows steadily with the time since (rather than losing its data one step at a time).
    """

    def __init__(self, length: int, capacity: int | None = None) -> None:
        self.length = length
        self.capacity = length if capacity is None else max(capacity, length)
        self.records: deque[StepRecord] = deque()

    def add(self, record: StepRecord) -> None:
        """Append a step's summaries; records older than ``capacity`` steps are dropped (the
        window uses the last ``length`` of them: a larger capacity lets the length grow
        again mid-episode)."""
        self.records.append(record)
        while self.records[0].step <= record.step - max(self.capacity, self.length):
            self.records.popleft()

    def expert_data(
        self,
        step: int,
        spatial: bool,
        mean: str,
        pooled: bool,
        origin: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> ExpertData | None:
        """Padded expert arrays of the window ending at ``step`` (None if there is no data).

        Inputs: the time relative to ``step`` (TGP), preceded for STGP by the previous
        estimate of the same coordinate (eqs. (25)-(26)). The GP models the outputs minus a
        prior mean (:func:`window_prior_mean`); for ``mean="prediction"`` that is the line
        ``origin`` = (position (2,), velocity (2,)) at ``step``, which no summary of the
        window enters. ``pooled`` puts every summary into one expert (the centralized GP).
        """
        if not self.records:
            return None
        latest = self.records[-1].step
        records = [record for record in self.records if record.step > latest - self.length]
        counts = [record.sensors.size for record in records]
        sensors = np.concatenate([record.sensors for record in records])
        summaries = np.concatenate([record.summaries for record in records])
        steps = np.repeat([record.step for record in records], counts)
        previous = np.repeat(
            np.array([record.previous_estimate for record in records]), counts, axis=0
        )
        groups = np.full(sensors.size, -1) if pooled else sensors
        labels, mask, (padded_summaries, padded_steps, padded_previous) = pad_by_group(
            groups, summaries, steps, previous
        )
        if mean == "prediction":
            if origin is None:
                raise ValueError('mean="prediction" needs the origin line')
            intercept, slope = (np.asarray(value, dtype=float) for value in origin)
            trend_covariance = np.zeros((2, 2))
        else:
            intercept, slope, trend_covariance = window_prior_mean(
                mean, (steps - step).astype(float), summaries
            )
        relative = (padded_steps - step).astype(float)
        trend = intercept[:, None, None] + slope[:, None, None] * relative
        z = (np.moveaxis(padded_summaries, -1, 0) - trend) * mask
        time = np.broadcast_to(relative, (2,) + mask.shape)
        if spatial:
            space = np.moveaxis(padded_previous, -1, 0) - intercept[:, None, None]
            X = np.stack([space, time], axis=-1)
        else:
            X = time[..., None]
        return ExpertData(labels, X, z, mask, intercept, slope, trend_covariance)


PRIOR_MEANS = ("linear", "window", "zero", "prediction")


def window_prior_mean(kind: str, times: np.ndarray, summaries: np.ndarray):
    """Intercept and slope (each (2,)) of the GP prior mean over the window, and the 2 x 2
    matrix (H^T H)^-1 of the least-squares fit in the basis [1, tau] (zero where a
    coefficient is fixed rather than estimated).

    - ``"zero"``: the paper's zero-mean GP on raw coordinates;
    - ``"window"``: the mean of the window's summaries (constant);
    - ``"linear"``: the least-squares line through the summaries over time, a
      constant-velocity trend; the GP models the deviations from it, and predictions
      through a stretch without measurements follow the trend instead of reverting to a
      constant. With a single time in the window the slope is 0 (and treated as known).

    (``"prediction"``, a line given from outside the window, is handled by
    :meth:`SlidingWindow.expert_data`.)
    """
    covariance = np.zeros((2, 2))
    if kind == "zero":
        return np.zeros(2), np.zeros(2), covariance
    centre = summaries.mean(axis=0)
    n = times.size
    if kind == "window":
        covariance[0, 0] = 1.0 / n
        return centre, np.zeros(2), covariance
    if kind != "linear":
        raise ValueError(f"mean must be one of {list(PRIOR_MEANS)}; got {kind!r}")
    mean_time = times.mean()
    time_offset = times - mean_time
    spread = float(time_offset @ time_offset)
    if spread == 0:
        covariance[0, 0] = 1.0 / n
        return centre, np.zeros(2), covariance
    slope = (time_offset @ (summaries - centre)) / spread
    # inverse of [[n, sum t], [sum t, sum t^2]] with sum t^2 - n mean^2 = spread
    covariance[:] = np.array(
        [
            [1.0 / n + mean_time**2 / spread, -mean_time / spread],
            [-mean_time / spread, 1.0 / spread],
        ]
    )
    return centre - slope * mean_time, slope, covariance
