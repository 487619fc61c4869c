"""The observation vector of the tracker-tuning environments: what the DGPT tracker knows
after a step, fixed-size and scaled to about [0, 1] (nothing here comes from the truth)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from agents.dgpt import DGPT, HYPERPARAMETER_BOUNDS
from dgpt_gym.tracker import Estimate

__all__ = [
    "tracker_features",
    "FEATURE_NAMES",
    "FEATURE_HIGH",
    "TrackerObservation",
    "decode_features",
]

FEATURE_NAMES = (
    "n_experts",  # active experts / 10
    "n_measurements",  # log1p(measurements of the coming step) / 4
    "std_x",  # log1p(predictive STD, m) / 6, per axis
    "std_y",
    "ucb_x",  # log1p(UCB half-width, m) / 6, per axis
    "ucb_y",
    "innovation",  # mean distance of the gated summaries from their prediction / sensing range
    "gated_out",  # log1p(measurements the hard gate dropped) / 4
    "window",  # (C - C_min) / (C_max - C_min)
    "threshold",  # the hard gate's position in its range, 1 for no hard gate
    "silent_steps",  # steps since the last measurement / 10
    # the learned log hyperparameters of both axes, each scaled to [0, 1] over its bounds:
    # signal variance, space length scale (0.5 for TGP), time length scale, noise variance
    *(f"{name}_{axis}" for axis in "xy" for name in ("signal", "space", "time", "noise")),
)
FEATURE_HIGH = 10.0
"""Upper bound of every feature (they are clipped to [0, FEATURE_HIGH])."""

_ORDER = ("signal_var", "space_lengthscale", "time_lengthscale", "noise_var")
_INDEX = {name: index for index, name in enumerate(FEATURE_NAMES)}
# scales shared by tracker_features and decode_features
_EXPERT_SCALE = 10.0  # active experts / 10
_SILENT_SCALE = 10.0  # steps since the last measurement / 10


class TrackerObservation(NamedTuple):
    """What the rules and the action tables read of a tuning task's observation."""

    n_experts: int
    """Active experts."""
    innovation: float
    """Mean distance of the last step's gated summaries from their predictions, in sensing
    ranges (0 when the gate left none)."""
    silent_steps: int
    """Steps since the last measurement."""


def decode_features(observation) -> TrackerObservation:
    """The inverse of :func:`tracker_features`' scaling for the fields of
    :class:`TrackerObservation`."""
    return TrackerObservation(
        n_experts=round(float(observation[_INDEX["n_experts"]]) * _EXPERT_SCALE),
        innovation=float(observation[_INDEX["innovation"]]),
        silent_steps=round(float(observation[_INDEX["silent_steps"]]) * _SILENT_SCALE),
    )


def _log_scaled(value: np.ndarray, scale: float) -> np.ndarray:
    return np.log1p(np.maximum(np.nan_to_num(value, nan=0.0, posinf=1e12), 0.0)) / scale


def hyperparameter_features(tracker: DGPT) -> np.ndarray:
    """(8,) log hyperparameters of both axes scaled by :data:`HYPERPARAMETER_BOUNDS`."""
    names = tracker._named_parameters()
    features = np.full((2, 4), 0.5)
    for column, name in enumerate(_ORDER):
        if name in names:
            low, high = np.log(HYPERPARAMETER_BOUNDS[name])
            value = tracker.log_params_[:, names.index(name)]
            features[:, column] = (value - low) / (high - low)
    return features.ravel()


def tracker_features(
    tracker: DGPT,
    estimate: Estimate | None,
    n_next_measurements: int,
    window_position: float,
    threshold_position: float,
    silent_steps: int,
) -> np.ndarray:
    """The observation vector, in the order of :data:`FEATURE_NAMES` (float32)."""
    sensing_range = tracker.spec_.sensing_range
    if estimate is None:  # before the first step
        std = ucb = np.full(2, sensing_range)
    else:
        std = np.sqrt(np.maximum(estimate.var, 0.0))
        ucb = std * 3.0 if estimate.ucb is None else estimate.ucb
    innovation = tracker.last_innovation_
    distance = float(np.mean(np.hypot(*innovation.T))) if innovation.size else 0.0
    vector = np.concatenate(
        [
            [tracker.n_experts_ / _EXPERT_SCALE, np.log1p(n_next_measurements) / 4.0],
            _log_scaled(std, 6.0),
            _log_scaled(ucb, 6.0),
            [
                distance / sensing_range,
                np.log1p(tracker.last_gated_out_) / 4.0,
                window_position,
                threshold_position,
                silent_steps / _SILENT_SCALE,
            ],
            hyperparameter_features(tracker),
        ]
    )
    return np.clip(vector, 0.0, FEATURE_HIGH).astype(np.float32)
