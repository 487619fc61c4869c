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

import numpy as np
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from gymnasium.vector.utils import concatenate, iterate

from agents.rl.base import TrackerInsideEnv
from agents.rl.sensors_env import DGPTrackSensorsEnv
from agents.rl.tuning_envs import DGPTrackGatingEnv, DGPTrackWindowEnv

__all__ = [
    "TrackerInsideVectorEnv",
    "window_vector_env",
    "gating_vector_env",
    "sensors_vector_env",
]


class TrackerInsideVectorEnv(SyncVectorEnv):
    """N sub-environments of one RL task stepped in lockstep, their trackers batched (module
    docstring). Next-step autoreset, as :class:`~gymnasium.vector.SyncVectorEnv` by default:
    the step after an episode ends resets that sub-environment and returns reward 0."""

    def __init__(self, env_fns, copy: bool = True) -> None:
        super().__init__(env_fns, copy=copy, autoreset_mode=AutoresetMode.NEXT_STEP)
        for env in self.envs:
            if not isinstance(env.unwrapped, TrackerInsideEnv):
                raise TypeError(
                    f"env_fns must make TrackerInsideEnv environments; got {type(env.unwrapped)}"
                )

    def step(self, actions):
        actions = list(iterate(self.action_space, actions))
        infos: dict = {}
        env_infos: list = [None] * self.num_envs
        stepping, tracker_observations = [], []
        for i, env in enumerate(self.envs):
            if self._autoreset_envs[i]:
                self._env_obs[i], env_infos[i] = env.reset()
                self._rewards[i] = 0.0
                self._terminations[i] = False
                self._truncations[i] = False
            else:
                tracker_observations.append(env.unwrapped.begin_step(actions[i]))
                stepping.append(i)
        if stepping:
            trackers = [self.envs[i].unwrapped.tracker for i in stepping]
            estimates = type(trackers[0]).update_batch(trackers, tracker_observations)
            for i, estimate in zip(stepping, estimates):
                (
                    self._env_obs[i],
                    self._rewards[i],
                    self._terminations[i],
                    self._truncations[i],
                    env_infos[i],
                ) = self.envs[i].unwrapped.end_step(estimate)
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


def _creator(env_class):
    def create(num_envs: int = 1, copy: bool = True, **env_kwargs) -> TrackerInsideVectorEnv:
        return TrackerInsideVectorEnv([partial(env_class, **env_kwargs)] * num_envs, copy=copy)

    create.__doc__ = (
        f"``num_envs`` :class:`~{env_class.__module__}.{env_class.__name__}` stepped in "
        "lockstep (:class:`TrackerInsideVectorEnv`); ``env_kwargs`` go to each."
    )
    return create


window_vector_env = _creator(DGPTrackWindowEnv)
gating_vector_env = _creator(DGPTrackGatingEnv)
sensors_vector_env = _creator(DGPTrackSensorsEnv)
