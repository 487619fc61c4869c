"""The search filter with clutter at every sensor: births from pairs of points, and a
filter that tells the target's points from clutter by their motion."""

import gymnasium as gym
import numpy as np
import pytest
from conftest import problem_spec
from scipy import stats

from agents.screening import MAX_TARGET_SPEED
from agents.search import SearchFilter, pair_births


def test_pair_births_by_hand():
    """Two pairs within reach, (0, 0) then (10, 0) or (10.5, 0), whose Gaussians overlap
    (the far point has no pair): the births sit at the pairs' second points with their
    velocities, and their log ratio is the new target's prior over the two pairs' mixture
    density (scipy's normal densities), over n."""
    previous = np.array([[0.0, 0.0]])
    current = np.array([[10.0, 0.0], [10.5, 0.0], [10.0 + MAX_TARGET_SPEED + 1.0, 0.0]])
    noise_var, speed_std, area, n = 0.25, 25.0, 1000.0, 500
    states, log_ratio = pair_births(
        previous, current, noise_var, 1.0, speed_std, area, n, np.random.default_rng(0)
    )
    position, velocity = states[:, :, 0], states[:, :, 1]
    np.testing.assert_allclose(position.mean(axis=0), [10.25, 0.0], atol=0.05)
    np.testing.assert_allclose(velocity.mean(axis=0), [10.25, 0.0], atol=0.1)
    proposal = np.mean(
        [
            stats.multivariate_normal([end, 0], noise_var).pdf(position)
            * stats.multivariate_normal([end, 0], 2 * noise_var).pdf(velocity)
            for end in (10.0, 10.5)
        ],
        axis=0,
    )
    expected = (
        -2 * np.log(area)
        + stats.multivariate_normal([0, 0], speed_std**2).logpdf(velocity)
        - np.log(proposal)
        - np.log(n)
    )
    np.testing.assert_allclose(log_ratio, expected, rtol=1e-10)
    assert pair_births(previous, current[2:], noise_var, 1.0, speed_std, area, n, None) is None


def test_the_search_settles_on_the_target_under_one_sensor_at_a_time():
    """S2's reference path with clutter at every sensor, where one sensor at a time senses
    the target and one scan cannot tell its point from clutter: within 9 steps the filter
    settles, and wherever it has settled it is within 3 m of the target (training seeds)."""
    for seed in range(1000, 1004):
        env = gym.make(
            "DGPTrack-v0", scenario="S2", clutter_rate=1, clutter_sensors="all"
        ).unwrapped
        env.reset(seed=seed)
        scans = env.scans_
        search = SearchFilter(env.problem_spec, 2000, np.random.default_rng(seed), 25, 25, 0.1, 3)
        settled_steps = []
        for step in range(12):
            rows = scans.rows(step)
            mean, _, settled = search.step(step, scans.measurements[rows], scans.sensor[rows])
            if settled:
                settled_steps.append(step)
                assert np.linalg.norm(mean - env.trajectory_.positions[step]) < 3.0
        # before the screen's own start (steps 10-12 on these seeds); over 8 other random
        # streams of the filter the first settled step was 1-9
        assert settled_steps and settled_steps[0] <= 9, seed


def test_the_search_restarts_when_the_scans_rule_out_everything():
    # one sensor covering the whole area: reporting nothing rules every position out
    spec = problem_spec([[100.0, 100.0]], sensing_range=200.0, area=200.0, clutter_sensors="all")
    search = SearchFilter(spec, 50, np.random.default_rng(0), 25, 25, 0.1, 3)
    assert search.step(0, np.empty((0, 2)), np.empty(0, dtype=int)) is None
    assert search.states is None


@pytest.mark.parametrize(
    "n, birth_probability, message",
    [(5, 0.1, "n must be at least 10"), (100, 0.0, "birth_probability"), (100, 1.0, "birth")],
)
def test_bad_search_arguments_name_themselves(n, birth_probability, message):
    spec = problem_spec(clutter_sensors="all")
    with pytest.raises(ValueError, match=message):
        SearchFilter(spec, n, np.random.default_rng(0), 25, 25, birth_probability, 3)


def first_track_step(search_particles, seed):
    """The step at which the state-space DGPT-RBCM starts its first track on S2's reference
    path with clutter at every sensor, and its error there."""
    from agents.state_space_dgpt import StateSpaceDGPT

    env = gym.make("DGPTrack-v0", scenario="S2", clutter_rate=1, clutter_sensors="all")
    observation, info = env.reset(seed=seed)
    tracker = StateSpaceDGPT(
        aggregation="rbcm", silence_particles=1000, search_particles=search_particles
    )
    tracker.reset(info["problem_spec"], seed=seed)
    for step in range(40):
        estimate = tracker.update(observation)
        assert np.all(np.isfinite(estimate.mean)) and np.all(np.isfinite(estimate.ucb))
        truth = env.unwrapped.trajectory_.positions[step]
        if tracker.mean_ is not None:
            return step, float(np.linalg.norm(estimate.mean - truth))
        observation, *_ = env.step(estimate.mean)
    return 40, float("nan")


def test_the_tracker_starts_from_the_settled_search_before_the_screens_start():
    """With the search the first track starts where the target is, and earlier than the
    screen's start, which needs a point that a second sensor confirms (training seeds)."""
    for seed in range(1000, 1004):
        with_search, error = first_track_step(2000, seed)
        without_search, _ = first_track_step(0, seed)
        assert with_search < without_search and error < 3.0, (seed, with_search, without_search)
