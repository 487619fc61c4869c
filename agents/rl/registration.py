"""The Gymnasium ids of the RL environments, as data: ``import dgpt_gym`` registers
:data:`ENVIRONMENTS` with Gymnasium as entry-point strings, so nothing here is imported until
an environment is made. A new RL environment is registered here and nowhere else."""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["RLEnvironment", "ENVIRONMENTS"]


class RLEnvironment(NamedTuple):
    """An RL environment: its Gymnasium id and entry point, its short name for
    ``dgpt-train-rl --env``, what its comparison table averages per step, and the creator of
    its batched vector environment (``gymnasium.make_vec(id, num_envs,
    vectorization_mode="vector_entry_point")``, :mod:`agents.rl.vector`) and the keyword
    arguments the id fixes (Gymnasium passes them to both entry points; a user's own
    override them)."""

    id: str
    entry_point: str
    alias: str
    per_step: str
    vector_entry_point: str
    kwargs: tuple[tuple[str, object], ...] = ()


ENVIRONMENTS: tuple[RLEnvironment, ...] = (
    RLEnvironment(
        "DGPTrackWindow-v0",
        "agents.rl.tuning_envs:DGPTrackWindowEnv",
        "window",
        "mean window C",
        "agents.rl.vector:window_vector_env",
    ),
    RLEnvironment(
        "DGPTrackGating-v0",
        "agents.rl.tuning_envs:DGPTrackGatingEnv",
        "gating",
        "mean gate threshold",
        "agents.rl.vector:gating_vector_env",
    ),
    RLEnvironment(
        "DGPTrackSensors-v0",
        "agents.rl.sensors_env:DGPTrackSensorsEnv",
        "sensors",
        "sensors woken per step",
        "agents.rl.vector:sensors_vector_env",
    ),
    RLEnvironment(
        "DGPTrackSensors-v1",
        "agents.rl.sensors_v1:DGPTrackSensorsV1Env",
        "sensors-v1",
        "sensors woken per step",
        "agents.rl.vector:sensors_v1_vector_env",
    ),
    RLEnvironment(
        "DGPTrackSensors-v2",
        "agents.rl.sensors_v1:DGPTrackSensorsV1Env",
        "sensors-v2",
        "sensors woken per step",
        "agents.rl.vector:sensors_v1_vector_env",
        (
            ("tracker", "dgpt-bcm"),
            ("window", 20),
            # dgpt-bcm as 0.9.0 built it, with which the committed v2 agents were trained
            (
                "tracker_options",
                {
                    "association": "local",
                    "manoeuvre_probability": 0.5,
                    "turn_rates": (),
                    "summary_variance": "point",
                    "silence_particles": 0,
                },
            ),
        ),
    ),
)
"""Every RL environment in ``agents/rl/``."""
