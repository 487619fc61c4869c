"""The shape-known floor's posterior of the start against a dense grid, and its errors."""

import numpy as np
import pytest
from conftest import problem_spec

from agents.screening import area_log_likelihood_ratios
from baselines.shape_floor import shape_known_posteriors, start_box

SPEC = problem_spec(
    [[50.0, 50.0], [150.0, 50.0], [100.0, 150.0]],
    sensing_range=30.0,
    clutter_rate=0.05,  # rare clutter: a point's mode outweighs the uncovered area
    area=200.0,
    clutter_sensors="all",
    n_steps=2,
)

# step 0: one point in sensor 0's disc, one in sensor 1's and one in sensor 2's, each
# covered by its own sensor alone, so all three are candidate starts (the third breaks the
# symmetry of the first two about x = 100); step 1 (the path moved by (10, 5)): a point in
# sensor 0's disc that continues the first candidate, and nothing from sensors 1 and 2,
# whose discs hold the other candidates moved by (10, 5): those are ruled out
SCANS = [
    (np.array([[52.0, 48.0], [148.0, 55.0], [95.0, 170.0]]), np.array([0, 1, 2])),
    (np.array([[62.4, 52.7]]), np.array([0])),
]
DISPLACEMENTS = np.array([[0.0, 0.0], [10.0, 5.0]])


def grid_posterior(box=((0.0, 0.0), (200.0, 200.0)), spacing=0.25):
    """The posterior mean and covariance of the start after each step, by a Riemann sum
    over a grid of the box (the densities are Gaussians of sigma = 1 m, which a 0.25 m grid
    integrates to many digits)."""
    (x_low, y_low), (x_high, y_high) = box
    axes = [
        np.arange(lo + spacing / 2, hi, spacing) for lo, hi in ((x_low, x_high), (y_low, y_high))
    ]
    starts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 2)
    log_weight = np.zeros(starts.shape[0])
    means, covs = [], []
    for (points, sensors), shift in zip(SCANS, DISPLACEMENTS):
        log_weight += area_log_likelihood_ratios(starts + shift, points, sensors, SPEC, 1.0)
        weights = np.exp(log_weight - np.max(log_weight))
        weights /= weights.sum()
        means.append(weights @ starts)
        deviation = starts - means[-1]
        covs.append(np.einsum("n,ni,nj->ij", weights, deviation, deviation))
    return np.array(means), np.array(covs)


def assert_within_monte_carlo_error(means, covs, ess, reference):
    # self-normalised importance sampling: standard error about sqrt(var / ESS) per axis
    standard_error = np.sqrt(np.diagonal(covs, axis1=1, axis2=2) / ess[:, None])
    assert np.all(np.abs(means - reference) <= 4.0 * standard_error)


def test_the_posterior_of_the_start_matches_a_dense_grid():
    means, covs, ess = shape_known_posteriors(
        SCANS, DISPLACEMENTS, SPEC, 40000, np.random.default_rng(0)
    )
    reference, reference_covs = grid_posterior()
    assert_within_monte_carlo_error(means, covs, ess, reference)
    # the case is not trivial: after step 0 the two candidates and the uncovered area
    # share the mass, unequally; after step 1 the first candidate holds nearly all of it
    assert 60.0 < reference[0, 0] < 140.0 and abs(reference[0, 0] - 100.0) > 1.0
    np.testing.assert_allclose(reference[1], [52.2, 47.85], atol=0.05)
    assert np.sqrt(np.max(np.diagonal(reference_covs[0]))) > 30.0
    # (a sd above 1 m: the uncovered area keeps about 4e-4 of the mass)
    assert np.sqrt(np.max(np.diagonal(reference_covs[1]))) < 3.0


def test_a_box_prior_leaves_out_the_candidates_outside_it():
    """The start's law given the shape is uniform on a box: a box that holds only part of the
    first candidate's neighbourhood settles the start there at step 0, as the grid over the
    box does."""
    box = (np.array([20.0, 20.0]), np.array([52.5, 80.0]))  # its edge cuts the candidate
    means, covs, ess = shape_known_posteriors(
        SCANS, DISPLACEMENTS, SPEC, 40000, np.random.default_rng(1), box
    )
    reference, _ = grid_posterior(box)
    assert_within_monte_carlo_error(means, covs, ess, reference)
    assert np.all(np.abs(reference[0] - [52.0, 48.0]) < 2.0)


def test_the_posterior_of_the_start_without_the_shift_stays_ambiguous():
    """Without the displacement the second step's point does not continue the first
    candidate, and the start stays spread over the area: the shift is what resolves it."""
    means, covs, _ = shape_known_posteriors(
        SCANS, np.zeros((2, 2)), SPEC, 40000, np.random.default_rng(0)
    )
    assert np.sqrt(np.max(np.diagonal(covs[1]))) > 10.0


def test_the_start_box_keeps_the_whole_path_inside_the_margins():
    displacements = np.array([[0.0, 0.0], [30.0, -20.0], [-10.0, 40.0]])
    low, high = start_box(displacements, 200.0, 50.0)
    np.testing.assert_allclose(low, [60.0, 70.0])  # 50 - (-10), 50 - (-20)
    np.testing.assert_allclose(high, [120.0, 110.0])  # 150 - 30, 150 - 40
    with pytest.raises(ValueError, match="more than the 100.0 m"):
        start_box(np.array([[0.0, 0.0], [101.0, 0.0]]), 200.0, 50.0)


@pytest.mark.parametrize(
    "displacements, n, box, message",
    [
        (np.zeros((3, 2)), 100, None, "displacements must be"),
        (np.array([[1.0, 0.0], [10.0, 5.0]]), 100, None, "displacements\\[0\\] must be 0"),
        (DISPLACEMENTS, 2, None, "n must be at least 3"),
        (DISPLACEMENTS, 100, ([50.0, 50.0], [40.0, 60.0]), "box must be"),
        (DISPLACEMENTS, 100, ([0.0, 0.0],), "box must be"),
    ],
)
def test_bad_arguments_name_themselves(displacements, n, box, message):
    with pytest.raises(ValueError, match=message):
        shape_known_posteriors(SCANS, displacements, SPEC, n, np.random.default_rng(0), box)


def test_scans_that_rule_out_every_start_raise():
    # one sensor covering the whole area, reporting nothing
    covering = problem_spec(
        [[100.0, 100.0]], sensing_range=200.0, area=200.0, clutter_sensors="all", n_steps=1
    )
    empty = [(np.empty((0, 2)), np.empty(0, dtype=np.int64))]
    with pytest.raises(ValueError, match="rule out every drawn start"):
        shape_known_posteriors(empty, np.zeros((1, 2)), covering, 30, np.random.default_rng(0))
