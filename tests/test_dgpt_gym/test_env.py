import logging
import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from gymnasium.utils.env_checker import check_env as gym_check_env
from hypothesis import given, settings
from hypothesis import strategies as st

from dgpt_gym import DGPTrackEnv, ProblemSpec


def rollout(env, seed, action=(500.0, 500.0)):
    """Observations, rewards and infos of one whole episode with a constant action."""
    observation, info = env.reset(seed=seed)
    observations, rewards, infos = [observation], [], [info]
    truncated = False
    while not truncated:
        observation, reward, terminated, truncated, info = env.step(np.array(action))
        assert not terminated
        observations.append(observation)
        rewards.append(reward)
        infos.append(info)
    return observations, rewards, infos


def assert_same(a, b):
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            assert_same(a[key], b[key])
    elif isinstance(a, ProblemSpec):
        np.testing.assert_array_equal(a.sensor_positions, b.sensor_positions)
    else:
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("scenario", ["S1", "S2", "S3", "S4"])
def test_gymnasium_env_checker(scenario):
    gym_check_env(DGPTrackEnv(scenario=scenario, clutter_rate=5.0), skip_render_check=True)


@pytest.mark.parametrize("scenario", ["S1", "S2", "S3", "S4"])
def test_stable_baselines3_env_checker(scenario):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    with pytest.warns(UserWarning, match="symmetric and normalized Box action space"):
        sb3_check_env(DGPTrackEnv(scenario=scenario, trajectory="random"))


@pytest.mark.parametrize("trajectory", ["fixed", "random"])
def test_same_seed_same_episode_different_seed_different(trajectory):
    env = gym.make("DGPTrack-v0", scenario="S3", clutter_rate=5.0, trajectory=trajectory)
    first = rollout(env, seed=3)
    second = rollout(env, seed=3)
    for a, b in zip(first, second):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            assert_same(x, y)
    other = rollout(env, seed=4)
    assert not all(
        np.array_equal(x["measurements"], y["measurements"]) for x, y in zip(first[0], other[0])
    )
    truth_differs = not np.array_equal(first[2][5]["position"], other[2][5]["position"])
    assert truth_differs == (trajectory == "random")


def test_reward_is_minus_the_euclidean_error():
    env = DGPTrackEnv(scenario="S2")
    env.reset(seed=0)
    for _ in range(5):
        truth = env.trajectory_.positions[env.step_]
        _, reward, _, _, info = env.step(truth + np.array([3.0, -4.0]))
        assert reward == pytest.approx(-5.0)
        assert info["error"] == pytest.approx(5.0)
        np.testing.assert_array_equal(info["position"], truth)


def test_episode_length_and_final_observation():
    env = DGPTrackEnv(scenario="S1")
    observations, rewards, infos = rollout(env, seed=0)
    assert len(rewards) == env.n_steps == env.scenario.n_steps
    assert [obs["t"] for obs in observations] == list(range(env.n_steps + 1))
    assert observations[-1]["mask"].sum() == 0


def test_observation_contents_match_the_info_counts():
    env = DGPTrackEnv(scenario="S4", clutter_rate=5.0)
    observations, _, infos = rollout(env, seed=1)
    spec = infos[0]["problem_spec"]
    for observation, info in zip(observations[:-1], infos[1:]):  # infos[t + 1] scores step t
        mask = observation["mask"].astype(bool)
        assert mask.sum() == info["n_target"] + info["n_clutter"]
        assert np.all(observation["sensor"][~mask] == -1)
        assert np.all(observation["measurements"][~mask] == 0.0)
        sensors = observation["sensor"][mask]
        assert set(sensors) <= set(info["active_sensors"])
        # every sensed target position is within range of each active sensor
        distances = np.linalg.norm(
            spec.sensor_positions[info["active_sensors"]] - info["position"], axis=1
        )
        assert np.all(distances <= spec.sensing_range)


def test_observation_arrays_are_read_only():
    env = DGPTrackEnv()
    observation, _ = env.reset(seed=0)
    with pytest.raises(ValueError):
        observation["measurements"][0, 0] = 1.0


def test_problem_spec_describes_the_env():
    env = DGPTrackEnv(noise_std=2.0, clutter_rate=5.0, detection_rate=1.5, sensing_range=40.0)
    _, info = env.reset(seed=0)
    spec = info["problem_spec"]
    assert (spec.noise_std, spec.clutter_rate, spec.detection_rate, spec.sensing_range) == (
        2.0,
        5.0,
        1.5,
        40.0,
    )
    assert spec.sensing_area == pytest.approx(math.pi * 1600.0)
    np.testing.assert_array_equal(spec.sensor_positions, env.network.positions)


def test_layout_seed_fixes_the_network_and_reset_option_changes_it():
    a, b = DGPTrackEnv(layout_seed=1), DGPTrackEnv(layout_seed=1)
    np.testing.assert_array_equal(a.network.positions, b.network.positions)
    before = a.network.positions.copy()
    a.reset(seed=0)
    np.testing.assert_array_equal(a.network.positions, before)
    _, info = a.reset(seed=0, options={"layout_seed": 2})
    assert not np.array_equal(a.network.positions, before)
    np.testing.assert_array_equal(
        info["problem_spec"].sensor_positions, DGPTrackEnv(layout_seed=2).network.positions
    )


def test_overflow_is_reported_and_warned_once(caplog):
    env = DGPTrackEnv(clutter_rate=5.0, max_measurements=2)
    with caplog.at_level(logging.WARNING, logger="dgpt_gym.env"):
        _, _, infos = rollout(env, seed=0)
    overflow = [info["overflow"] for info in infos]
    expected = [max(info["n_target"] + info["n_clutter"] - 2, 0) for info in infos]
    assert overflow == expected and sum(overflow) > 0
    assert len([r for r in caplog.records if "max_measurements" in r.getMessage()]) == 1


def test_derived_max_measurements_makes_overflow_rare():
    env = DGPTrackEnv(scenario="S3", clutter_rate=5.0, trajectory="random")
    total = 0
    for seed in range(20):
        _, _, infos = rollout(env, seed)
        total += sum(info["overflow"] for info in infos)
    assert total == 0
    assert DGPTrackEnv(clutter_rate=5.0, clutter_sensors="all").max_measurements > 250 * 5


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"scenario": "S9"}, "scenario"),
        ({"noise_std": -1.0}, "noise_std"),
        ({"noise_std": float("nan")}, "noise_std"),
        ({"clutter_rate": -0.5}, "clutter_rate"),
        ({"clutter_rate": float("inf")}, "clutter_rate"),
        ({"detection_rate": 0.0}, "detection_rate"),
        ({"n_sensors": 0}, "n_sensors"),
        ({"n_sensors": 2.5}, "n_sensors"),
        ({"area": 0.0}, "area"),
        ({"area": 100.0}, "area"),
        ({"sensing_range": -5.0}, "sensing_range"),
        ({"dt": 0.0}, "dt"),
        ({"clutter_sensors": "some"}, "clutter_sensors"),
        ({"trajectory": "loop"}, "trajectory"),
        ({"layout_seed": -1}, "layout_seed"),
        ({"max_measurements": 0}, "max_measurements"),
        ({"render_mode": "ansi"}, "render_mode"),
    ],
)
def test_bad_arguments_name_the_argument(kwargs, name):
    with pytest.raises(ValueError, match=name):
        DGPTrackEnv(**kwargs)


@settings(max_examples=30, deadline=None)
@given(
    name=st.sampled_from(
        ["noise_std", "clutter_rate", "detection_rate", "area", "sensing_range", "dt"]
    ),
    value=st.one_of(st.floats(max_value=-1e-9), st.just(float("nan")), st.just(float("-inf"))),
)
def test_negative_or_nan_values_are_rejected(name, value):
    with pytest.raises(ValueError, match=f"{name} must be"):
        DGPTrackEnv(**{name: value})


@settings(max_examples=20, deadline=None)
@given(
    name=st.sampled_from(["scenario", "clutter_sensors", "trajectory"]), value=st.text(max_size=6)
)
def test_unknown_choices_are_rejected(name, value):
    allowed = {
        "scenario": {"S1", "S2", "S3", "S4"},
        "clutter_sensors": {"detecting", "all"},
        "trajectory": {"fixed", "random"},
    }[name]
    if value in allowed:
        return
    with pytest.raises(ValueError, match=f"{name} must be one of"):
        DGPTrackEnv(**{name: value})


@pytest.mark.parametrize(
    "action",
    [
        np.array([1.0, 2.0, 3.0]),
        np.array([np.nan, 1.0]),
        np.array([1.0, np.inf]),
        5.0,
        np.zeros((2, 1)),
    ],
)
def test_bad_actions_raise(action):
    env = DGPTrackEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action must be a finite position estimate"):
        env.step(action)


def test_step_before_reset_and_after_the_end():
    env = DGPTrackEnv()
    with pytest.raises(ResetNeeded):
        env.step(np.zeros(2))
    wrapped = gym.make("DGPTrack-v0")
    with pytest.raises(ResetNeeded):
        wrapped.step(np.zeros(2))
    rollout(env, seed=0)
    with pytest.raises(ResetNeeded, match="episode has ended"):
        env.step(np.zeros(2))


def test_rgb_array_render():
    env = DGPTrackEnv(render_mode="rgb_array", clutter_rate=5.0)
    env.reset(seed=0)
    env.step(np.array([500.0, 500.0]))
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert frame.shape[0] >= 200 and frame.std() > 0
    env.close()


def test_make_vec_runs_four_envs():
    envs = gym.make_vec("DGPTrack-v0", num_envs=4, scenario="S2")
    observations, _ = envs.reset(seed=0)
    assert observations["measurements"].shape[0] == 4
    for _ in range(3):
        observations, rewards, terminated, truncated, _ = envs.step(np.full((4, 2), 500.0))
    assert rewards.shape == (4,) and np.all(rewards < 0)
    envs.close()


@pytest.mark.parametrize(
    "action",
    [np.array([True, False]), np.array([1 + 2j, 3.0]), ["1", "2"], "12", np.array([None, 1.0])],
)
def test_actions_that_are_not_real_numbers_are_refused(action):
    env = gym.make("DGPTrack-v0").unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(action)


@pytest.mark.parametrize("options", [{"layout": 3}, {"layout_seed": 1, "seed": 2}, [1], "x"])
def test_reset_options_are_checked(options):
    env = gym.make("DGPTrack-v0").unwrapped
    with pytest.raises(ValueError, match="options"):
        env.reset(seed=0, options=options)


def test_render_draws_the_annotated_uncertainty():
    env = gym.make("DGPTrack-v0", scenario="S1", render_mode="rgb_array")
    env.reset(seed=0)
    env.step(np.array([500.0, 500.0]))
    plain = env.render()
    env.reset(seed=0)
    env.unwrapped.annotate(var=np.array([400.0, 900.0]), ucb=np.array([80.0, 120.0]))
    env.step(np.array([500.0, 500.0]))
    annotated = env.render()
    assert plain.shape == annotated.shape and np.any(plain != annotated)
    assert env.unwrapped.uncertainties_[-1][1].tolist() == [80.0, 120.0]
    with pytest.raises(ValueError, match="var"):
        env.unwrapped.annotate(var=np.array([-1.0, 1.0]))
    with pytest.raises(ValueError, match="ucb"):
        env.unwrapped.annotate(var=np.array([1.0, 1.0]), ucb=np.array([np.nan, 1.0]))
