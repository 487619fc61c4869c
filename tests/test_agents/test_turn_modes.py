"""The coordinated-turn modes of the state-space DGPT: the per-axis turn prediction against
the dense four-dimensional one, an IMM step against a dense recomputation, and a turn carried
through a coverage gap."""

import numpy as np
import pytest
from conftest import measurement_obs, mixture_moments, problem_spec
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import norm

from agents.state_space import ncv_predict, turn_predict
from agents.state_space_dgpt import StateSpaceDGPT
from baselines.cpf import turn_transition
from baselines.kalman import constant_velocity_model

seeds = st.integers(0, 2**32 - 1)


def random_axes_state(rng, batch=()):
    """Per-axis states (..., 2 axes, 2) and positive-definite covariances (..., 2, 2, 2)."""
    mean = rng.normal(0.0, 10.0, batch + (2, 2))
    factor = rng.normal(0.0, 2.0, batch + (2, 2, 2))
    return mean, factor @ np.swapaxes(factor, -1, -2) + 0.1 * np.eye(2)


def dense_turn_prediction(mean, cov, dt, q, omega):
    """The coordinated-turn prediction of the joint state [x, vx, y, vy] with the two axes'
    block-diagonal covariance, by the 4 x 4 matrices; returns the axes' blocks."""
    joint_mean = mean.reshape(4)
    joint_cov = np.zeros((4, 4))
    joint_cov[:2, :2], joint_cov[2:, 2:] = cov
    transition = turn_transition(omega, dt)
    noise = np.zeros((4, 4))
    for axis in range(2):
        noise[2 * axis : 2 * axis + 2, 2 * axis : 2 * axis + 2] = constant_velocity_model(
            dt, q[axis]
        )[1][:2, :2]
    new_mean = transition @ joint_mean
    new_cov = transition @ joint_cov @ transition.T + noise
    return new_mean.reshape(2, 2), np.stack([new_cov[:2, :2], new_cov[2:, 2:]])


@given(seed=seeds, dt=st.floats(0.1, 3.0), omega=st.floats(-1.0, 1.0))
@settings(max_examples=30, deadline=None)
def test_turn_prediction_is_the_dense_joint_prediction_per_axis(seed, dt, omega):
    rng = np.random.default_rng(seed)
    mean, cov = random_axes_state(rng, (3,))
    q = rng.uniform(0.01, 50.0, (3, 2))
    new_mean, new_cov = turn_predict(mean, cov, dt, q, omega)
    for index in range(3):
        expected_mean, expected_cov = dense_turn_prediction(
            mean[index], cov[index], dt, q[index], omega
        )
        np.testing.assert_allclose(new_mean[index], expected_mean, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(new_cov[index], expected_cov, rtol=1e-12, atol=1e-10)
    ncv_mean, ncv_cov = ncv_predict(mean, cov, dt, q)
    zero_mean, zero_cov = turn_predict(mean, cov, dt, q, 0.0)
    np.testing.assert_allclose(zero_mean, ncv_mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(zero_cov, ncv_cov, rtol=1e-12, atol=1e-10)


def test_turn_prediction_rotates_the_velocity_along_the_arc():
    """A target at 10 m/s heading east, turning left at 0.5 rad/s for 1 s: its velocity turns
    by 0.5 rad and it moves along the chord of the arc of radius 20 m."""
    mean = np.array([[0.0, 10.0], [0.0, 0.0]])  # x: position, velocity; y: the same
    new_mean, _ = turn_predict(mean, np.zeros((2, 2, 2)), 1.0, np.zeros(2), 0.5)
    radius = 10.0 / 0.5
    np.testing.assert_allclose(new_mean[:, 1], 10.0 * np.array([np.cos(0.5), np.sin(0.5)]))
    np.testing.assert_allclose(
        new_mean[:, 0], radius * np.array([np.sin(0.5), 1.0 - np.cos(0.5)]), rtol=1e-12
    )


def dense_imm_step(modes, transition, q, manoeuvre, turn_rates, turn_q, point, noise_var):
    """One IMM step of the tracker with one sensor reporting the single point ``point`` (its
    target probability is 1, so the summary is the point with variance sigma_n^2), recomputed
    mode by mode and axis by axis; ``point`` None is a step without data. Returns the modes'
    posteriors and probabilities and the moments of their mixture."""
    means, covs, probabilities = modes
    count = len(probabilities)
    predicted = np.array(
        [sum(probabilities[i] * transition[i, j] for i in range(count)) for j in range(count)]
    )
    mixed = []
    for j in range(count):
        log_mixing = np.log(
            [probabilities[i] * transition[i, j] / predicted[j] for i in range(count)]
        )
        mixed.append(
            [mixture_moments(log_mixing, means[:, axis], covs[:, axis]) for axis in range(2)]
        )
    hypotheses = []  # (mode, log prior, per-axis (mean, cov))
    for intensity, probability in ((q, 1.0 - manoeuvre[1]), (q + manoeuvre[0], manoeuvre[1])):
        hypotheses.append(
            (
                0,
                np.log(predicted[0] * probability),
                [
                    ncv_predict(mixed[0][axis][0], mixed[0][axis][1], 1.0, intensity[axis])
                    for axis in range(2)
                ],
            )
        )
    for mode, omega in enumerate(turn_rates, start=1):
        joint_mean = np.stack([mixed[mode][axis][0] for axis in range(2)])
        joint_cov = np.stack([mixed[mode][axis][1] for axis in range(2)])
        turn_mean, turn_cov = dense_turn_prediction(joint_mean, joint_cov, 1.0, [turn_q] * 2, omega)
        hypotheses.append(
            (
                mode,
                np.log(predicted[mode]),
                [(turn_mean[axis], turn_cov[axis]) for axis in range(2)],
            )
        )
    log_weights, posteriors = [], []
    for _, log_prior, prediction in hypotheses:
        log_weight, posterior = log_prior, []
        for axis, (mean, cov) in enumerate(prediction):
            if point is None:
                posterior.append((mean, cov))
                continue
            innovation_var = cov[0, 0] + noise_var
            log_weight += norm(mean[0], np.sqrt(innovation_var)).logpdf(point[axis])
            gain = cov[:, 0] / innovation_var
            posterior.append(
                (mean + gain * (point[axis] - mean[0]), cov - innovation_var * np.outer(gain, gain))
            )
        log_weights.append(log_weight)
        posteriors.append(posterior)
    log_weights = np.array(log_weights)
    mode_of = np.array([mode for mode, _, _ in hypotheses])
    weights = np.exp(log_weights - np.logaddexp.reduce(log_weights))
    mode_means, mode_covs = np.empty((count, 2, 2)), np.empty((count, 2, 2, 2))
    for mode in range(count):
        own = np.flatnonzero(mode_of == mode)
        for axis in range(2):
            mode_means[mode, axis], mode_covs[mode, axis] = mixture_moments(
                log_weights[own],
                [posteriors[h][axis][0] for h in own],
                [posteriors[h][axis][1] for h in own],
            )
    mode_probabilities = np.array([weights[mode_of == mode].sum() for mode in range(count)])
    overall = [
        mixture_moments(
            log_weights,
            [posteriors[h][axis][0] for h in range(len(hypotheses))],
            [posteriors[h][axis][1] for h in range(len(hypotheses))],
        )
        for axis in range(2)
    ]
    return (mode_means, mode_covs, mode_probabilities), overall


@pytest.mark.parametrize("with_data", [True, False])
def test_an_imm_step_is_the_dense_mixture_of_its_modes_hypotheses(with_data):
    """From given mode posteriors and probabilities, a step is: the IMM mixing through the
    Markov chain, the NCV mode's two process-noise components and each turn mode's
    prediction, each updated with the step's summary and weighted by its mode's predicted
    probability, its component's prior probability and its likelihood; the modes'
    posteriors are the moments of their hypotheses, the estimate the moments of all."""
    spec = problem_spec(clutter_rate=0.0)
    turn_rates = (0.35, -0.52)
    tracker = StateSpaceDGPT(
        aggregation="rbcm",
        learn_process_noise=False,
        process_noise=2.0,
        turn_rates=turn_rates,
        turn_process_noise=3.0,
        mode_stay_probability=0.7,
    )
    tracker.reset(spec)
    rng = np.random.default_rng(5)
    tracker.update(measurement_obs(0, [[5.0, 3.0]], [0]))  # starts the track
    means, covs = random_axes_state(rng, (3,))
    probabilities = np.array([0.5, 0.3, 0.2])
    tracker.modes_ = (means, covs, probabilities)
    point = np.array([12.0, 4.0]) if with_data else None
    obs = measurement_obs(1, [point] if with_data else np.empty((0, 2)), [0] if with_data else [])
    estimate = tracker.update(obs)
    manoeuvre = (tracker.manoeuvre.intensity, tracker.manoeuvre.probability)
    # stay with probability 0.7, the rest spread evenly over the other two modes
    transition = np.array([[0.7, 0.15, 0.15], [0.15, 0.7, 0.15], [0.15, 0.15, 0.7]])
    (mode_means, mode_covs, mode_probabilities), overall = dense_imm_step(
        (means, covs, probabilities),
        transition,
        np.full(2, 2.0),
        manoeuvre,
        turn_rates,
        3.0,
        point,
        1.0,
    )
    np.testing.assert_allclose(tracker.modes_[2], mode_probabilities, rtol=1e-9)
    np.testing.assert_allclose(tracker.modes_[0], mode_means, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(tracker.modes_[1], mode_covs, rtol=1e-9, atol=1e-9)
    for axis in range(2):
        np.testing.assert_allclose(estimate.mean[axis], overall[axis][0][0], rtol=1e-9)
        np.testing.assert_allclose(estimate.var[axis], overall[axis][1][0, 0], rtol=1e-9)
    # the probabilities moved: the test compares an update, not the starting point
    assert not np.allclose(mode_probabilities, probabilities, atol=0.02)


def arc_track(tracker, omega, n_data, n_gap, seed):
    """Measure a target turning at ``omega`` rad/s at 15 m/s for ``n_data`` steps (one point
    of noise 1 m per step, two sensors), then ``n_gap`` silent steps. Returns the 2-D
    errors in the gap, those of the first turn mode's posterior mean (None without turn
    modes) and the modes' probabilities after the last step with data."""
    rng = np.random.default_rng(seed)
    tracker.reset(problem_spec(sensor_positions=((0.0, 0.0), (30.0, 0.0)), clutter_rate=0.0))
    t = np.arange(n_data + n_gap)
    radius = 15.0 / omega
    truth = radius * np.column_stack([np.sin(omega * t), 1.0 - np.cos(omega * t)])
    errors, mode_errors, probabilities = [], [], None
    for step in t:
        if step < n_data:
            point = truth[step] + rng.normal(0.0, 1.0, 2)
            estimate = tracker.update(measurement_obs(int(step), [point], [0]))
            probabilities = None if tracker.modes_ is None else tracker.modes_[2]
        else:
            estimate = tracker.update(measurement_obs(int(step), np.empty((0, 2)), []))
            errors.append(np.linalg.norm(estimate.mean - truth[step]))
            if tracker.modes_ is not None:
                mode_errors.append(np.linalg.norm(tracker.modes_[0][1][:, 0] - truth[step]))
    return np.array(errors), np.array(mode_errors), probabilities


def test_a_persistent_turn_mode_carries_the_turn_through_a_gap():
    """After 30 steps of a 0.35 rad/s left turn the +0.35 mode holds most of the probability.
    Through a 6-step gap the NCV tracker's prediction runs off along the tangent (after 6 s
    the arc of radius 43 m is about 80 m from it) while the turn mode's posterior follows the
    arc, pulled off it only by the IMM mixing with the other modes (2.5 % of each per step;
    measured 3.6 m at the gap's first step, 11.9 m at its sixth); the mixture's error grows
    as the Markov chain (stay probability 0.95) leaks probability to the other modes, and
    stays under a third of the NCV tracker's from the gap's second step on."""
    turning = StateSpaceDGPT(
        turn_rates=(0.35, -0.35), mode_stay_probability=0.95, learn_process_noise=False
    )
    straight = StateSpaceDGPT(turn_rates=(), learn_process_noise=False)
    turn_errors, mode_errors, probabilities = arc_track(turning, 0.35, 30, 6, seed=11)
    straight_errors, _, _ = arc_track(straight, 0.35, 30, 6, seed=11)
    assert probabilities[1] > 0.9 and probabilities[2] < 0.02, probabilities
    assert np.all(mode_errors < 15.0), mode_errors
    assert straight_errors[-1] > 80.0, straight_errors
    assert np.all(turn_errors[1:] < straight_errors[1:] / 3.0), (turn_errors, straight_errors)
