"""The shape-known floor's posterior of the start against a dense grid, and its errors."""

import numpy as np
import pytest
from conftest import problem_spec

from agents.screening import area_log_likelihood_ratios
from baselines.shape_floor import shape_known_posteriors

SPEC = problem_spec(
    [[50.0, 50.0], [150.0, 50.0], [100.0, 150.0]],
    sensing_range=30.0,
    clutter_rate=0.05,  # rare clutter: a point's mode outweighs the uncovered area
    area=200.0,
    clutter_sensors="all",
    n_steps=2,
)

# step 0: one point in sensor 0's disc and one in sensor 1's, each covered by its own
# sensor alone, so both are candidate starts; step 1 (the path moved by (10, 5)): a point
# in sensor 0's disc that continues the first candidate, and nothing from sensor 1, whose
# disc holds the second candidate moved by (10, 5): the second is ruled out
SCANS = [
    (np.array([[52.0, 48.0], [148.0, 55.0]]), np.array([0, 1])),
    (np.array([[62.4, 52.7]]), np.array([0])),
]
DISPLACEMENTS = np.array([[0.0, 0.0], [10.0, 5.0]])


def grid_posterior_means(spacing=0.25):
    """The posterior mean of the start after each step by a Riemann sum over a grid of the
    area (the densities are Gaussians of sigma = 1 m, which a 0.25 m grid integrates to
    many digits)."""
    axis = np.arange(spacing / 2, SPEC.area, spacing)
    starts = np.stack(np.meshgrid(axis, axis, indexing="ij"), axis=-1).reshape(-1, 2)
    log_weight = np.zeros(starts.shape[0])
    means = []
    for (points, sensors), shift in zip(SCANS, DISPLACEMENTS):
        log_weight += area_log_likelihood_ratios(starts + shift, points, sensors, SPEC, 1.0)
        weights = np.exp(log_weight - np.max(log_weight))
        means.append(weights @ starts / weights.sum())
    return np.array(means)


def test_the_posterior_of_the_start_matches_a_dense_grid():
    means, covs, ess = shape_known_posteriors(
        SCANS, DISPLACEMENTS, SPEC, 40000, np.random.default_rng(0)
    )
    reference = grid_posterior_means()
    # self-normalised importance sampling: standard error about sqrt(var / ESS) per axis
    standard_error = np.sqrt(np.diagonal(covs, axis1=1, axis2=2) / ess[:, None])
    assert np.all(np.abs(means - reference) <= 4.0 * standard_error)
    # the case is not trivial: after step 0 the two candidates and the uncovered area
    # share the mass, after step 1 the first candidate holds it
    assert 60.0 < reference[0, 0] < 140.0
    np.testing.assert_allclose(reference[1], [52.2, 48.35], atol=0.5)
    # (a sd above 1 m: the uncovered area keeps about 4e-4 of the mass)
    assert (
        np.sqrt(np.max(np.diagonal(covs[1]))) < 3.0 < 30.0 < np.sqrt(np.min(np.diagonal(covs[0])))
    )


def test_the_posterior_of_the_start_without_the_shift_stays_ambiguous():
    """Without the displacement the second step's point does not continue the first
    candidate, and the start stays spread over the area: the shift is what resolves it."""
    means, covs, _ = shape_known_posteriors(
        SCANS, np.zeros((2, 2)), SPEC, 40000, np.random.default_rng(0)
    )
    assert np.sqrt(np.max(np.diagonal(covs[1]))) > 10.0


@pytest.mark.parametrize(
    "displacements, n, message",
    [
        (np.zeros((3, 2)), 100, "displacements must be"),
        (np.array([[1.0, 0.0], [10.0, 5.0]]), 100, "displacements\\[0\\] must be 0"),
        (DISPLACEMENTS, 2, "n must be at least 3"),
    ],
)
def test_bad_arguments_name_themselves(displacements, n, message):
    with pytest.raises(ValueError, match=message):
        shape_known_posteriors(SCANS, displacements, SPEC, n, np.random.default_rng(0))


def test_scans_that_rule_out_every_start_raise():
    # one sensor covering the whole area, reporting nothing
    covering = problem_spec(
        [[100.0, 100.0]], sensing_range=200.0, area=200.0, clutter_sensors="all", n_steps=1
    )
    empty = [(np.empty((0, 2)), np.empty(0, dtype=np.int64))]
    with pytest.raises(ValueError, match="rule out every drawn start"):
        shape_known_posteriors(empty, np.zeros((1, 2)), covering, 30, np.random.default_rng(0))
