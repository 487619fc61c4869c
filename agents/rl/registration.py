"""The Gymnasium ids of the RL environments, as data: ``import dgpt_gym`` registers
:data:`ENVIRONMENTS` with Gymnasium as entry-point strings, so nothing here is imported until
an environment is made. A new RL environment is registered here and nowhere else."""

from __future__ import annotations

from typing import NamedTuple

__all__ = [
    "FixedTrackerOptions",
    "RLEnvironment",
    "ENVIRONMENTS",
    "TREND_TRACKER_OPTIONS",
    "SENSORS_V1_TRACKER_OPTIONS",
    "SENSORS_V2_TRACKER_OPTIONS",
]


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


class FixedTrackerOptions(dict):
    """``tracker_options`` that an environment id fixes for the tracker it names
    (``tracker``). Gymnasium passes an id's fixed arguments with the user's, so a user who
    picks another ``tracker`` would silently build it with options meant for this one (v2's
    ``aggregation="bcm"`` for ``tracker="dgpt-rbcm"``); the environment refuses that
    instead (:class:`agents.rl.sensors_v1.DGPTrackSensorsV1Env`). Built like a dict (what
    ``dataclasses.asdict``, which ``EnvSpec.to_json`` uses, does), it fixes no tracker."""

    def __init__(self, options=(), /, tracker: str | None = None) -> None:
        super().__init__(options)
        self.tracker = tracker


TREND_TRACKER_OPTIONS = {
    "delta": 0.003,
    "mean": "linear",
    "max_iterations": 5,
    "anytime_ucb": False,
    "gating": True,
    "kernel": "se",
    "hyperparameter_bounds": "tracking",
    "admission_probability": 0.5,
}
"""Every argument of :class:`agents.dgpt.DGPT` that the window, gating and v0 sensor tasks
do not take from their own arguments (``aggregation``, ``inputs``, ``window``,
``gate_threshold``), with which they build their tracker, so that no later default of
``DGPT`` moves these tasks under the agents committed for window and gating (v0 has none):
``DGPT``'s defaults, unchanged since 0.5.0, with which those agents were trained and
evaluated. A new argument of ``DGPT`` must be added here (a test checks that none is
missing; the values are guarded by ``scripts/fingerprint.py``'s lines of the tasks)."""

SENSORS_V1_TRACKER_OPTIONS = {
    "aggregation": "rbcm",
    "inputs": "tgp",
    "gate_threshold": None,
    **TREND_TRACKER_OPTIONS,
}
"""Every argument of ``DGPT`` but ``window`` (the environment's own, 3), as
``DGPTrackSensors-v1`` builds its ``dgpt-rbcm-trend``: the registered id's arguments and
:data:`TREND_TRACKER_OPTIONS`, so that neither the id's registration nor ``DGPT``'s
defaults can move the task under its committed agents."""

SENSORS_V2_TRACKER_OPTIONS = {
    # dgpt-bcm as 0.9.0 built it:
    "association": "local",
    "manoeuvre_probability": 0.5,
    "turn_rates": (),
    "summary_variance": "point",
    "silence_particles": 0,
    "expert_update": "summary",
    # the defaults with which the committed v2 agents were trained (0.23.1):
    "aggregation": "bcm",
    "delta": 0.003,
    "gating": True,
    "manoeuvre_intensity": 400.0,
    "admission_probability": 0.5,
    "start_gate": None,
    "process_noise": 1.0,
    "learn_process_noise": True,
    "turn_process_noise": 5.0,
    "mode_stay_probability": 0.9,
    "process_noise_prior": "none",
    "gap_end": "reports",
    "gap_restart_probability": 0.1,
    "gap_end_evidence": "scans",
    "gap_region_cell": 10.0,
    "search_particles": 2000,
    "search_settle_std": 3.0,
    "search_birth_probability": 0.1,
    "gap_birth_probability": 0.003,
    "learning": "window",
    "learning_memory": 50.0,
}
"""Every argument of ``StateSpaceDGPT`` but ``window`` (the environment's own), as
``DGPTrackSensors-v2`` builds its tracker, so that no later default moves the task under its
committed agents. A new argument of the tracker must be added here (a test checks that none is
missing)."""

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
        (
            ("tracker", "dgpt-rbcm-trend"),
            ("window", 3),
            (
                "tracker_options",
                FixedTrackerOptions(SENSORS_V1_TRACKER_OPTIONS, tracker="dgpt-rbcm-trend"),
            ),
        ),
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
            (
                "tracker_options",
                FixedTrackerOptions(SENSORS_V2_TRACKER_OPTIONS, tracker="dgpt-bcm"),
            ),
        ),
    ),
)
"""Every RL environment in ``agents/rl/``."""
