"""The sliding window of gated summaries (paper Sec. IV-B) and its arrangement into padded
expert arrays for the GP core."""

from __future__ import annotations

import functools
from collections import deque
from dataclasses import dataclass

import numpy as np

from agents.gating import group_starts
from agents.gp import TrainingData

__all__ = [
    "StepRecord", "SlidingWindow", "ExpertData", "pad_by_group", "window_prior_mean", "PRIOR_MEANS"
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


@dataclass(frozen=True)
class ExpertData:
    """Training data of the experts for both axes.

    ``sensors`` (M,) the expert sensors (a single -1 for one pooled expert); ``X`` (2, M, n,
    d) inputs, ``z`` (2, M, n) outputs minus the prior mean, ``mask`` (M, n); ``steps`` (M,
    n) the step of every point. The prior mean of each axis is ``intercept + slope * tau``
    at the time ``tau`` relative to the window's end (:meth:`prior_mean`).
    """

    sensors: np.ndarray
    X: np.ndarray
    z: np.ndarray
    mask: np.ndarray
    intercept: np.ndarray
    slope: np.ndarray
    steps: np.ndarray

    @property
    def n_points(self) -> int:
        return int(self.mask.sum())

    @functools.cached_property
    def training(self) -> TrainingData:
        """The GP core's prepared form of ``X``, ``z`` and ``mask``."""
        return TrainingData.build(self.X, self.z, self.mask)

    def prior_mean(self, relative_time: float) -> np.ndarray:
        """(2,) prior mean of the coordinates at ``relative_time`` (s after the window's end)."""
        return self.intercept + self.slope * relative_time


class SlidingWindow:
    """The gated summaries of the last ``length`` steps (the window of C steps).

    A sensor is an expert while it has at least one summary in the window. If the window
    holds no summary (a stretch without measurements), the records of the last ``length``
    steps that had summaries are used instead, so the tracker keeps predicting from its
    most recent data, with a variance that grows with the distance in time.
    """

    def __init__(self, length: int) -> None:
        self.length = length
        self.records: deque[StepRecord] = deque()

    def add(self, record: StepRecord) -> None:
        self.records.append(record)
        # keep the last `length` steps that had data (they stand in during a gap)
        while self.records and self.records[0].step <= record.step - self.length:
            self.records.popleft()

    def current(self, step: int) -> list[StepRecord]:
        """Records inside the window ending at ``step``, or the most recent ones (see class)."""
        inside = [record for record in self.records if record.step > step - self.length]
        return inside if inside else list(self.records)

    def expert_data(self, step: int, spatial: bool, mean: str, pooled: bool) -> ExpertData | None:
        """Padded expert arrays of the window ending at ``step`` (None if there is no data).

        Inputs: the time relative to ``step`` (TGP), preceded for STGP by the previous
        estimate of the same coordinate (eqs. (25)-(26)). The GP models the outputs minus a
        prior mean (:func:`window_prior_mean`). ``pooled`` puts every summary into one
        expert (the centralized GP).
        """
        records = self.current(step)
        if not records:
            return None
        counts = [record.sensors.size for record in records]
        sensors = np.concatenate([record.sensors for record in records])
        summaries = np.concatenate([record.summaries for record in records])
        steps = np.repeat([record.step for record in records], counts)
        previous = np.repeat(np.array([record.previous_estimate for record in records]), counts, axis=0)
        groups = np.full(sensors.size, -1) if pooled else sensors
        labels, mask, (padded_summaries, padded_steps, padded_previous) = pad_by_group(
            groups, summaries, steps, previous
        )
        intercept, slope = window_prior_mean(mean, (steps - step).astype(float), summaries)
        relative = (padded_steps - step).astype(float)
        trend = intercept[:, None, None] + slope[:, None, None] * relative
        z = (np.moveaxis(padded_summaries, -1, 0) - trend) * mask
        time = np.broadcast_to(relative, (2,) + mask.shape)
        if spatial:
            space = np.moveaxis(padded_previous, -1, 0) - intercept[:, None, None]
            X = np.stack([space, time], axis=-1)
        else:
            X = time[..., None]
        return ExpertData(labels, X, z, mask, intercept, slope, padded_steps)


PRIOR_MEANS = ("linear", "window", "zero")


def window_prior_mean(kind: str, times: np.ndarray, summaries: np.ndarray):
    """Intercept and slope (each (2,)) of the GP prior mean over the window.

    - ``"zero"``: the paper's zero-mean GP on raw coordinates;
    - ``"window"``: the mean of the window's summaries (constant);
    - ``"linear"``: the least-squares line through the summaries over time, a
      constant-velocity trend; the GP models the deviations from it, and predictions
      through a stretch without measurements follow the trend instead of reverting to a
      constant. With a single time in the window the slope is 0.
    """
    if kind == "zero":
        return np.zeros(2), np.zeros(2)
    centre = summaries.mean(axis=0)
    if kind == "window":
        return centre, np.zeros(2)
    if kind != "linear":
        raise ValueError(f"mean must be one of {list(PRIOR_MEANS)}; got {kind!r}")
    time_offset = times - times.mean()
    spread = float(time_offset @ time_offset)
    slope = (time_offset @ (summaries - centre)) / spread if spread > 0 else np.zeros(2)
    return centre - slope * times.mean(), slope
