"""The Gymnasium ids of the RL environments, as data: ``import dgpt_gym`` registers
:data:`ENVIRONMENTS` with Gymnasium as entry-point strings, so nothing here is imported until
an environment is made. A new RL environment is registered here and nowhere else."""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["RLEnvironment", "ENVIRONMENTS"]


class RLEnvironment(NamedTuple):
    """An RL environment: its Gymnasium id and entry point, its short name for
    ``dgpt-train-rl --env`` and what its comparison table averages per step."""

    id: str
    entry_point: str
    alias: str
    per_step: str


ENVIRONMENTS: tuple[RLEnvironment, ...] = (
    RLEnvironment(
        "DGPTrackWindow-v0", "agents.rl.tuning_envs:DGPTrackWindowEnv", "window", "mean window C"
    ),
    RLEnvironment(
        "DGPTrackGating-v0",
        "agents.rl.tuning_envs:DGPTrackGatingEnv",
        "gating",
        "mean gate threshold",
    ),
    RLEnvironment(
        "DGPTrackSensors-v0",
        "agents.rl.sensors_env:DGPTrackSensorsEnv",
        "sensors",
        "sensors woken per step",
    ),
)
"""Every RL environment in ``agents/rl/``."""
