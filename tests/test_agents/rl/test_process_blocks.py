"""The worker-process VecEnv (agents/rl/process_blocks.py): the same numbers as the
one-process batched VecEnv, whatever the blocks; worker errors reach the parent; training
with workers gives the same model."""

import os

import numpy as np
import pytest
from conftest import step_vec_envs_alike
from hypothesis import given
from hypothesis import strategies as st

import dgpt_gym  # noqa: F401  (registers the environments)
from agents.rl.process_blocks import block_bounds, process_blocks_vec_env, worker_cores
from agents.rl.training import train_agent
from agents.rl.vector import stable_baselines_vec_env

pytest.importorskip("stable_baselines3")


def test_block_bounds_by_hand():
    assert block_bounds(7, 3) == [(0, 3), (3, 5), (5, 7)]
    assert block_bounds(32, 2) == [(0, 16), (16, 32)]
    assert block_bounds(3, 3) == [(0, 1), (1, 2), (2, 3)]
    assert block_bounds(5, 1) == [(0, 5)]


@given(st.integers(1, 200), st.integers(1, 200))
def test_blocks_cover_the_environments_in_order_and_differ_by_at_most_one(n_envs, workers):
    if workers > n_envs:
        with pytest.raises(ValueError, match="workers must be at most n_envs"):
            block_bounds(n_envs, workers)
        return
    blocks = block_bounds(n_envs, workers)
    assert len(blocks) == workers
    assert [start for start, _ in blocks] == [0] + [stop for _, stop in blocks[:-1]]
    assert blocks[-1][1] == n_envs
    sizes = [stop - start for start, stop in blocks]
    assert min(sizes) >= 1 and max(sizes) - min(sizes) <= 1


def test_bad_workers_are_named():
    with pytest.raises(ValueError, match="workers must be an integer >= 1"):
        block_bounds(4, 0)


def test_workers_are_pinned_to_distinct_cores_when_there_are_enough():
    if not hasattr(os, "sched_setaffinity"):
        assert worker_cores(1) == [None]
        return
    cores = sorted(os.sched_getaffinity(0))
    assert worker_cores(len(cores)) == cores
    assert worker_cores(1) == cores[:1]
    assert worker_cores(len(cores) + 1) == [None] * (len(cores) + 1)


def test_process_blocks_equal_the_one_process_vec_env():
    """Five environments in two workers (blocks of 3 and 2) against the one-process batched
    VecEnv with the same seeds (:func:`conftest.step_vec_envs_alike`) over 80 steps of
    25-step episodes (so several autoresets), then again after a reseeding reset. Each worker
    is pinned to its core; attribute access returns each environment's own value in the
    order asked for, across the blocks."""
    n, seed = 5, 21
    kwargs = {"scenario": "S2", "clutter_rate": 5.0, "max_episode_steps": 25}
    reference = stable_baselines_vec_env("DGPTrackWindow-v0", n, seed, kwargs)
    blocks = process_blocks_vec_env("DGPTrackWindow-v0", n, seed, kwargs, workers=2)
    try:
        if hasattr(os, "sched_getaffinity"):  # each worker runs where worker_cores put it
            for process, core in zip(blocks.processes, worker_cores(2)):
                expected = os.sched_getaffinity(0) if core is None else {core}
                assert os.sched_getaffinity(process.pid) == expected
        rng = np.random.default_rng(0)
        for reset_seed in (None, 7):
            if reset_seed is not None:
                reference.seed(reset_seed)
                blocks.seed(reset_seed)
            np.testing.assert_array_equal(blocks.reset(), reference.reset())
            dones = step_vec_envs_alike(blocks, reference, 80, rng)
            assert dones == 15  # 80 steps of 25-step episodes, in 5 environments
        # the seeds of the last reset, per environment, asked for across both blocks
        assert blocks.get_attr("np_random_seed", [4, 0, 2]) == [7 + 4, 7, 7 + 2]
        blocks.set_attr("label", "b", indices=[1, 3])
        assert blocks.get_attr("label", [3, 1]) == ["b", "b"]
        assert blocks.has_attr("np_random_seed") and not blocks.has_attr("no_such_attribute")
    finally:
        blocks.close()
        reference.close()


def test_a_worker_error_is_raised_in_the_parent_and_the_pipes_stay_in_step():
    with pytest.raises(ValueError, match="scenario"):
        process_blocks_vec_env("DGPTrackWindow-v0", 2, 0, {"scenario": "S9"}, workers=2)
    blocks = process_blocks_vec_env("DGPTrackWindow-v0", 3, 0, {"scenario": "S1"}, workers=2)
    try:
        with pytest.raises(AttributeError, match="no_such_attribute"):
            blocks.get_attr("no_such_attribute")
        blocks.set_attr("label", "first block", indices=[0, 1])
        with pytest.raises(AttributeError, match="label"):  # only the second worker fails
            blocks.get_attr("label")
        observations = blocks.reset()  # every worker still answers its own command
        assert observations.shape == (3,) + blocks.observation_space.shape
        assert blocks.step(np.zeros(3, dtype=int))[0].shape == observations.shape
    finally:
        blocks.close()


def test_training_with_workers_gives_the_same_model(tmp_path):
    """PPO on four environments in one process and in two workers: the environments'
    numbers do not depend on the blocks, so the trained networks are equal."""
    settings = {
        "timesteps": 128,
        "seed": 2,
        "n_envs": 4,
        "env_kwargs": {"scenario": "S1", "max_episode_steps": 20},
        "algo_kwargs": {"n_steps": 16, "batch_size": 32, "n_epochs": 2},
        "progress": False,
    }
    one = train_agent("DGPTrackSensors-v2", out=tmp_path / "one", **settings)
    two = train_agent("DGPTrackSensors-v2", out=tmp_path / "two", workers=2, **settings)
    one_state, two_state = one.model.policy.state_dict(), two.model.policy.state_dict()
    assert one_state.keys() == two_state.keys()
    for name, tensor in one_state.items():
        np.testing.assert_array_equal(tensor.numpy(), two_state[name].numpy(), err_msg=name)
    np.testing.assert_array_equal(one.normalizer.obs_rms.mean, two.normalizer.obs_rms.mean)
    with pytest.raises(ValueError, match="workers must be at most n_envs"):
        train_agent("DGPTrackSensors-v2", out=tmp_path / "bad", workers=5, **settings)
