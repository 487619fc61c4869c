"""Shared fixtures and helpers."""

import numpy as np
import pytest

import dgpt_gym  # noqa: F401  (registers DGPTrack-v0 and the trackers)


def z_tolerance(standard_error: float, z: float = 5.0) -> float:
    """A test tolerance of ``z`` standard errors (5: a false alarm below 1e-6 per check)."""
    return z * standard_error


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
