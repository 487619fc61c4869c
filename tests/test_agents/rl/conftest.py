"""Shared fixtures of the RL tests."""

import pytest

from agents.rl.training import train_agent


@pytest.fixture
def short_ppo(tmp_path):
    """``short_ppo(env_id, env_kwargs, timesteps)``: a PPO agent trained on 2 sub-environments
    with seed 0 and small rollouts (256 steps, batches of 64), saved under ``tmp_path``."""

    def train(env_id: str, env_kwargs: dict, timesteps: int):
        return train_agent(
            env_id,
            "ppo",
            timesteps=timesteps,
            seed=0,
            n_envs=2,
            out=tmp_path,
            env_kwargs=env_kwargs,
            algo_kwargs={"n_steps": 256, "batch_size": 64},
            progress=False,
        )

    return train
