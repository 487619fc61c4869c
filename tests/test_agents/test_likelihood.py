"""Eq. (42) over large scans: the near pairs of :class:`agents.likelihood.PoissonLikelihood`
and :func:`agents.likelihood.nearest_squared_distance` against every pair formed by hand."""

import numpy as np
import pytest

from agents import likelihood as likelihood_module
from agents.likelihood import (
    NEAR_PAIRS_MIN_MEASUREMENTS,
    PoissonLikelihood,
    nearest_squared_distance,
)

SCAN = NEAR_PAIRS_MIN_MEASUREMENTS + 72  # large enough for the near pairs


def dense_log_likelihood(model: PoissonLikelihood, positions, measurements) -> np.ndarray:
    """Eq. (42) summed over every (position, measurement) pair, written out."""
    variance = model.noise_std**2
    squared = ((positions[:, None, :] - measurements[None, :, :]) ** 2).sum(axis=2)
    target = model.detection_rate / (2.0 * np.pi * variance) * np.exp(-0.5 * squared / variance)
    return np.log(model.clutter_rate / model.sensing_area + target).sum(axis=1)


def scan(rng, n_positions: int, n_measurements: int, spread: float):
    """Positions clustered around (500, 500) and measurements of which a third lie among
    them and the rest anywhere in the 1000 m square."""
    positions = 500.0 + rng.normal(0.0, spread, (n_positions, 2))
    near = n_measurements // 3
    measurements = np.concatenate(
        [
            positions[rng.integers(0, n_positions, near)] + rng.normal(0.0, 2.0, (near, 2)),
            rng.uniform(0.0, 1000.0, (n_measurements - near, 2)),
        ]
    )
    return positions, measurements


@pytest.mark.parametrize(
    "clutter_rate, detection_rate, noise_std, sensing_area",
    [
        (1.0, 1.0, 1.0, np.pi * 50.0**2),  # the paper's rates, sigma_z 1
        (5.0, 2.0, 4.0, np.pi * 50.0**2),  # sigma_z 4: a radius of about 45 m
        (3.0, 1.0, 0.1, np.pi * 30.0**2),  # a sharp peak: rho up to about 2e4
    ],
)
def test_the_near_pairs_give_eq_42_summed_over_every_pair(
    rng, clutter_rate, detection_rate, noise_std, sensing_area
):
    model = PoissonLikelihood(clutter_rate, detection_rate, noise_std, sensing_area)
    positions, measurements = scan(rng, 300, SCAN, spread=10.0)
    near = model.log_likelihood(positions, measurements)
    np.testing.assert_allclose(
        near, dense_log_likelihood(model, positions, measurements), rtol=1e-13, atol=0.0
    )
    # the weights a particle filter takes from it, relative to the largest
    dense = dense_log_likelihood(model, positions, measurements)
    np.testing.assert_allclose(near - near.max(), dense - dense.max(), rtol=0.0, atol=1e-9)


def test_only_the_pairs_below_the_cutoff_are_left_out(rng):
    """With the cutoff raised to log rho = -1 most pairs are left out; the sum equals
    n log c plus log1p(rho) over exactly the pairs with log rho >= -1, by hand."""
    model = PoissonLikelihood(1.0, 1.0, 2.0, np.pi * 50.0**2)
    positions, measurements = scan(rng, 40, SCAN, spread=5.0)
    clutter = model.clutter_rate / model.sensing_area
    squared = ((positions[:, None, :] - measurements[None, :, :]) ** 2).sum(axis=2)
    log_rho = np.log(model.detection_rate / (2.0 * np.pi * 4.0 * clutter)) - squared / 8.0
    kept = log_rho >= -1.0
    assert 0 < kept.sum() < 0.2 * kept.size  # the cutoff leaves most pairs out
    terms = np.where(kept, np.log1p(np.exp(log_rho)), 0.0)
    expected = SCAN * np.log(clutter) + terms.sum(axis=1)
    np.testing.assert_allclose(
        model.near_log_likelihood(positions, measurements, cutoff=-1.0), expected, rtol=1e-13
    )


def test_a_target_term_below_the_cutoff_everywhere_leaves_n_log_c(rng):
    """rho at most about 2.5e-24 < e^-50: no pair is kept and every position gets n log c,
    which is eq. (42) to rounding."""
    model = PoissonLikelihood(5.0, 1e-25, 1.0, np.pi * 50.0**2)
    positions, measurements = scan(rng, 20, SCAN, spread=5.0)
    near = model.log_likelihood(positions, measurements)
    np.testing.assert_array_equal(near, np.full(20, SCAN * np.log(5.0 / model.sensing_area)))
    np.testing.assert_allclose(
        near, dense_log_likelihood(model, positions, measurements), rtol=1e-13
    )


def test_the_near_pairs_need_clutter():
    model = PoissonLikelihood(0.0, 1.0, 1.0, np.pi * 50.0**2)
    with pytest.raises(ValueError, match="clutter_rate"):
        model.near_log_likelihood(np.zeros((3, 2)), np.zeros((SCAN, 2)))


def test_without_clutter_a_large_scan_is_summed_densely(rng):
    """Without clutter every pair contributes its squared distance: no pair may be left out."""
    model = PoissonLikelihood(0.0, 1.0, 1.5, np.pi * 50.0**2)
    positions, measurements = scan(rng, 30, SCAN, spread=5.0)
    expected = (
        np.log(1.0 / (2.0 * np.pi * 2.25))
        - 0.5 * ((positions[:, None, :] - measurements[None, :, :]) ** 2).sum(axis=2) / 2.25
    ).sum(axis=1)
    np.testing.assert_allclose(model.log_likelihood(positions, measurements), expected, rtol=1e-13)


def test_a_non_finite_position_keeps_the_dense_sum(rng):
    """A KD-tree raises on NaN; the dense sum carries it to that position alone."""
    model = PoissonLikelihood(1.0, 1.0, 1.0, np.pi * 50.0**2)
    positions, measurements = scan(rng, 10, SCAN, spread=5.0)
    positions[3] = np.nan
    values = model.log_likelihood(positions, measurements)
    assert np.isnan(values[3]) and np.all(np.isfinite(np.delete(values, 3)))
    assert np.isnan(nearest_squared_distance(positions, measurements))


def test_the_nearest_pair_of_a_large_scan(rng, monkeypatch):
    """By hand: the particle at the origin and the point (3, 4) are the closest pair, 25 m^2
    apart; and on random scans the KD-tree's answer is the dense one's."""
    positions = np.array([[0.0, 0.0], [100.0, 100.0]])
    measurements = np.concatenate([[[3.0, 4.0]], rng.uniform(200.0, 900.0, (SCAN - 1, 2))])
    assert nearest_squared_distance(positions, measurements) == pytest.approx(25.0, rel=1e-15)
    positions, measurements = scan(rng, 300, SCAN, spread=10.0)
    near = nearest_squared_distance(positions, measurements)
    monkeypatch.setattr(likelihood_module, "NEAR_PAIRS_MIN_MEASUREMENTS", 10**9)
    dense = nearest_squared_distance(positions, measurements)
    assert near == pytest.approx(dense, rel=1e-12)
    assert dense == pytest.approx(
        ((positions[:, None, :] - measurements[None, :, :]) ** 2).sum(axis=2).min(), rel=1e-15
    )


def test_the_near_pairs_are_summed_in_chunks_of_measurements(rng, monkeypatch):
    """With every pair near, the near pairs are as many as the dense array's entries: they
    are found chunk by chunk, and the sum is the one of a single chunk."""
    model = PoissonLikelihood(5.0, 1.0, 4.0, np.pi * 50.0**2)
    positions, measurements = scan(rng, 50, SCAN, spread=5.0)
    whole = model.near_log_likelihood(positions, measurements)
    monkeypatch.setattr(likelihood_module, "CHUNK_ELEMENTS", 50 * 16)  # 16 points a chunk
    np.testing.assert_allclose(
        model.near_log_likelihood(positions, measurements), whole, rtol=1e-14
    )
    np.testing.assert_allclose(
        whole, dense_log_likelihood(model, positions, measurements), rtol=1e-13
    )
