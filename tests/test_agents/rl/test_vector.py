"""Batched vector environments (agents/rl/vector.py): ``gymnasium.make_vec(...,
vectorization_mode="vector_entry_point")`` equals N single environments step for step."""

import gymnasium as gym
import numpy as np
import pytest
from conftest import step_vec_envs_alike

import dgpt_gym  # noqa: F401  (registers the environments)
from agents.rl.registration import ENVIRONMENTS

RL_ENVS = [environment.id for environment in ENVIRONMENTS]


def single_rollouts(env_id, n, actions, seed, **env_kwargs):
    """N single environments seeded seed + i, with the next-step autoreset of the vector
    environments: the step after an episode ends resets and returns reward 0."""
    envs = [gym.make(env_id, **env_kwargs) for _ in range(n)]
    observations = [env.reset(seed=seed + i)[0] for i, env in enumerate(envs)]
    done = [False] * n
    trace = [(np.stack(observations), np.zeros(n))]
    for action in actions:
        rewards = np.zeros(n)
        for i, env in enumerate(envs):
            if done[i]:
                observations[i], _ = env.reset()
                done[i] = False
                continue
            observations[i], rewards[i], terminated, truncated, _ = env.step(action[i])
            done[i] = terminated or truncated
        trace.append((np.stack(observations), rewards))
    return trace


@pytest.mark.parametrize(
    "env_id, layout",
    [*((env_id, None) for env_id in RL_ENVS), ("DGPTrackWindow-v0", "per_episode")],
)
def test_the_batched_vector_env_equals_single_envs_step_for_step(env_id, layout):
    """Eight sub-environments over 160 steps, so that the shortest scenario's episodes
    (100 steps) end and autoreset; random actions make the trackers' windows, gates and
    sensors differ, so the batched learning mixes different problems. Bit for bit; with
    per-episode layouts too (the autoreset draws each sub-environment's next layout)."""
    n, steps, env_kwargs = 8, 160, {"scenario": "S3", "clutter_rate": 5.0}
    if layout is not None:
        env_kwargs.update(layout=layout, trajectory="random")
    if env_id == "DGPTrackGating-v0":  # and Gymnasium's time limit, which the batch keeps
        env_kwargs["max_episode_steps"] = 45
    vector = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **env_kwargs)
    vector.action_space.seed(5)
    actions = [vector.action_space.sample() for _ in range(steps)]
    observations, _ = vector.reset(seed=11)
    trace = [(observations, np.zeros(n))]
    for action in actions:
        observations, rewards, *_ = vector.step(action)
        trace.append((observations, rewards))
    expected = single_rollouts(env_id, n, actions, 11, **env_kwargs)
    for (got_obs, got_rewards), (want_obs, want_rewards) in zip(trace, expected):
        np.testing.assert_array_equal(got_obs, want_obs)
        np.testing.assert_array_equal(got_rewards, want_rewards)
    assert vector.unwrapped.envs[0].unwrapped.inner.n_steps < steps  # an autoreset happened


@pytest.mark.parametrize("env_id", [*RL_ENVS, "DGPTrack-v0"])
def test_every_environment_has_a_vector_entry_point(env_id):
    vector = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point")
    sync = gym.make_vec(env_id, num_envs=3, vectorization_mode="sync")
    assert vector.single_observation_space == sync.single_observation_space
    assert vector.single_action_space == sync.single_action_space
    first, _ = vector.reset(seed=2)
    second, _ = sync.reset(seed=2)
    if isinstance(first, dict):
        for key in first:
            np.testing.assert_array_equal(first[key], second[key])
    else:
        np.testing.assert_array_equal(first, second)


def test_the_stable_baselines_vec_env_equals_dummy_vec_env():
    """The batched SB3 VecEnv used for training against SB3's own DummyVecEnv over the same
    environments and seeds: observations, rewards, dones, the tracker's error (a float64
    the float32 observations and rewards would round away), terminal observations and the
    time limit (episodes of 25 steps, so several autoresets happen). Three environments:
    their windows group them differently from step to step, which once changed the last
    bits of the GP's prediction (0.17.0; seed 23 diverged at step 33)."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    from agents.rl.vector import stable_baselines_vec_env

    n, kwargs = 3, {"scenario": "S2", "clutter_rate": 5.0, "max_episode_steps": 25}
    batched = stable_baselines_vec_env("DGPTrackWindow-v0", n, seed=21, env_kwargs=kwargs)
    reference = DummyVecEnv([lambda: gym.make("DGPTrackWindow-v0", **kwargs)] * n)
    reference.seed(21)
    np.testing.assert_array_equal(batched.reset(), reference.reset())
    dones = step_vec_envs_alike(batched, reference, 80, np.random.default_rng(0))
    assert dones == 9  # 80 steps of 25-step episodes, in 3 environments
