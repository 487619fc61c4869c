"""Batched vector environments of the RL tasks: ``gymnasium.make_vec(id, num_envs=N,
vectorization_mode="vector_entry_point")``.

Every RL environment runs a DGPT tracker inside (:class:`agents.rl.base.TrackerInsideEnv`),
and a step of one sub-environment spends most of its time in the tracker's per-call
overhead. :class:`TrackerInsideVectorEnv` is Gymnasium's :class:`~gymnasium.vector.SyncVectorEnv`
(same spaces, seeding, next-step autoreset and info batching) whose ``step`` runs every
sub-environment's :meth:`~agents.rl.base.TrackerInsideEnv.begin_step`, then one
:meth:`~dgpt_gym.tracker.TrackerBase.update_batch` over all their trackers (each tracker's numbers are bit for
bit those of its episode alone), then each :meth:`~agents.rl.base.TrackerInsideEnv.end_step`.
So the vector environment equals N single environments step for step with the same seeds
(``reset(seed=s)`` seeds sub-environment i with s + i, as the sync mode does).
"""

from __future__ import annotations

from functools import partial

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from gymnasium.vector.utils import concatenate, iterate

from agents.rl.base import TrackerInsideEnv
from agents.rl.sensors_env import DGPTrackSensorsEnv
from agents.rl.sensors_v1 import DGPTrackSensorsV1Env
from agents.rl.tuning_envs import DGPTrackGatingEnv, DGPTrackWindowEnv

__all__ = [
    "TrackerInsideVectorEnv",
    "window_vector_env",
    "gating_vector_env",
    "sensors_vector_env",
    "sensors_v1_vector_env",
    "stable_baselines_vec_env",
    "EpisodeStepLimit",
    "step_in_lockstep",
]


def step_in_lockstep(envs, actions) -> list[tuple]:
    """One step of the RL environments ``envs`` (``TrackerInsideEnv``, unwrapped) with
    ``actions``: every ``begin_step``, one ``update_batch`` of their trackers, every
    ``end_step``; returns their ``(observation, reward, terminated, truncated, info)``."""
    inputs = [env.begin_step(action) for env, action in zip(envs, actions)]
    trackers = [env.tracker for env in envs]
    estimates = type(trackers[0]).update_batch(trackers, inputs)
    return [env.end_step(estimate) for env, estimate in zip(envs, estimates)]


class TrackerInsideVectorEnv(SyncVectorEnv):
    """N sub-environments of one RL task stepped in lockstep, their trackers batched (module
    docstring). Next-step autoreset, as :class:`~gymnasium.vector.SyncVectorEnv` by default:
    the step after an episode ends resets that sub-environment and returns reward 0."""

    def __init__(self, env_fns, copy: bool = True, max_episode_steps: int | None = None) -> None:
        super().__init__(env_fns, copy=copy, autoreset_mode=AutoresetMode.NEXT_STEP)
        for env in self.envs:
            if not isinstance(env.unwrapped, TrackerInsideEnv):
                raise TypeError(
                    f"env_fns must make TrackerInsideEnv environments; got {type(env.unwrapped)}"
                )
        self.time_limit = EpisodeStepLimit(self.num_envs, max_episode_steps)

    def reset(self, *, seed=None, options=None):
        self.time_limit.restart(range(self.num_envs))
        return super().reset(seed=seed, options=options)

    def step(self, actions):
        actions = list(iterate(self.action_space, actions))
        infos: dict = {}
        env_infos: list = [None] * self.num_envs
        stepping = []
        for i, env in enumerate(self.envs):
            if self._autoreset_envs[i]:
                self.time_limit.restart([i])
                self._env_obs[i], env_infos[i] = env.reset()
                self._rewards[i] = 0.0
                self._terminations[i] = False
                self._truncations[i] = False
            else:
                stepping.append(i)
        if stepping:
            results = step_in_lockstep(
                [self.envs[i].unwrapped for i in stepping], [actions[i] for i in stepping]
            )
            for i, result in zip(stepping, results):
                (
                    self._env_obs[i],
                    self._rewards[i],
                    self._terminations[i],
                    self._truncations[i],
                    env_infos[i],
                ) = result
                self._truncations[i] |= self.time_limit.count(i)
        for i, env_info in enumerate(env_infos):
            infos = self._add_info(infos, env_info, i)
        self._observations = concatenate(
            self.single_observation_space, self._env_obs, self._observations
        )
        self._autoreset_envs = np.logical_or(self._terminations, self._truncations)
        return (
            np.copy(self._observations) if self.copy else self._observations,
            np.copy(self._rewards),
            np.copy(self._terminations),
            np.copy(self._truncations),
            infos,
        )


class EpisodeStepLimit:
    """Gymnasium's ``TimeLimit`` for batched sub-environments, whose ``begin_step`` /
    ``end_step`` bypass the wrapper: counts each one's steps since its reset."""

    def __init__(self, num_envs: int, max_episode_steps: int | None) -> None:
        self.max_episode_steps = max_episode_steps
        self.elapsed = np.zeros(num_envs, dtype=int)

    def restart(self, indices) -> None:
        self.elapsed[list(indices)] = 0

    def count(self, index: int) -> bool:
        """One more step of sub-environment ``index``; True when that reaches the limit."""
        self.elapsed[index] += 1
        return self.max_episode_steps is not None and self.elapsed[index] >= self.max_episode_steps


def _creator(env_class):
    def create(
        num_envs: int = 1, copy: bool = True, max_episode_steps: int | None = None, **env_kwargs
    ) -> TrackerInsideVectorEnv:
        return TrackerInsideVectorEnv(
            [partial(env_class, **env_kwargs)] * num_envs, copy, max_episode_steps
        )

    create.__doc__ = (
        f"``num_envs`` :class:`~{env_class.__module__}.{env_class.__name__}` stepped in "
        "lockstep (:class:`TrackerInsideVectorEnv`); ``env_kwargs`` go to each."
    )
    return create


window_vector_env = _creator(DGPTrackWindowEnv)
gating_vector_env = _creator(DGPTrackGatingEnv)
sensors_vector_env = _creator(DGPTrackSensorsEnv)
sensors_v1_vector_env = _creator(DGPTrackSensorsV1Env)


def stable_baselines_vec_env(env_id: str, n_envs: int, seed: int, env_kwargs: dict | None = None):
    """A Stable-Baselines3 ``VecEnv`` over ``n_envs`` environments ``env_id`` whose trackers
    step in lockstep, as :class:`TrackerInsideVectorEnv` does: SB3's ``DummyVecEnv``
    (seeding, buffers, attribute access) with a ``step_wait`` that runs every
    sub-environment's ``begin_step``, one ``update_batch``, then each ``end_step``, and
    SB3's same-step autoreset (``terminal_observation`` and ``TimeLimit.truncated`` in the
    infos). Sub-environment i is seeded ``seed + i`` at the first reset. Episode statistics
    come from ``VecMonitor`` on top (the sub-environments carry no ``Monitor``, whose
    ``step`` the batched step bypasses). Needs the 'rl' extra."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    class BatchedDummyVecEnv(DummyVecEnv):
        def reset(self):
            self.time_limit.restart(range(self.num_envs))
            return super().reset()

        def step_wait(self):
            results = step_in_lockstep([env.unwrapped for env in self.envs], self.actions)
            for index, result in enumerate(results):
                observation, reward, terminated, truncated, info = result
                truncated = truncated or self.time_limit.count(index)
                self.buf_rews[index] = reward
                self.buf_infos[index] = info
                self.buf_dones[index] = terminated or truncated
                info["TimeLimit.truncated"] = truncated and not terminated
                if self.buf_dones[index]:
                    info["terminal_observation"] = observation
                    self.time_limit.restart([index])
                    observation, self.reset_infos[index] = self.envs[index].reset()
                self._save_obs(index, observation)
            return (
                self._obs_from_buf(),
                np.copy(self.buf_rews),
                np.copy(self.buf_dones),
                [dict(info) for info in self.buf_infos],
            )

    env_kwargs = dict(env_kwargs or {})
    venv = BatchedDummyVecEnv([partial(gym.make, env_id, **env_kwargs)] * n_envs)
    for env in venv.envs:
        if not isinstance(env.unwrapped, TrackerInsideEnv):
            raise ValueError(f"env_id must name an RL environment of agents.rl; got {env_id!r}")
    venv.time_limit = EpisodeStepLimit(n_envs, venv.envs[0].spec.max_episode_steps)
    venv.seed(seed)
    return venv
