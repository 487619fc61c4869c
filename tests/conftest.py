"""Shared fixtures and helpers."""

import numpy as np
import pytest

import dgpt_gym  # noqa: F401  (registers DGPTrack-v0 and the trackers)
from dgpt_gym.problem import ProblemSpec


def problem_spec(sensor_positions=((0.0, 0.0),), **changes) -> ProblemSpec:
    """A hand-built ProblemSpec for tests: 50 m range, sigma_z 1 m, unit rates and period,
    a 1000 m area, clutter at detecting sensors, 10 steps, unless ``changes`` say otherwise."""
    fields = dict(
        sensing_range=50.0,
        noise_std=1.0,
        clutter_rate=1.0,
        detection_rate=1.0,
        dt=1.0,
        area=1000.0,
        clutter_sensors="detecting",
        n_steps=10,
    )
    return ProblemSpec(np.asarray(sensor_positions, dtype=float), **{**fields, **changes})


def mixture_moments(log_weights, means, covs):
    """Mean and covariance of a Gaussian mixture, component by component (a reference for
    the vectorized reductions): weights normalised from their logs, covariance
    sum_j w_j (P_j + (m_j - mean)(m_j - mean)^T)."""
    log_weights = np.asarray(log_weights, dtype=float)
    weights = np.exp(log_weights - log_weights.max())
    weights /= weights.sum()
    means = np.asarray(means)
    mean = weights @ means
    cov = sum(w * (c + np.outer(m - mean, m - mean)) for w, m, c in zip(weights, means, covs))
    return mean, cov


def z_tolerance(standard_error: float, z: float = 5.0) -> float:
    """A test tolerance of ``z`` standard errors (5: a false alarm below 1e-6 per check)."""
    return z * standard_error


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
