"""dgpt-gym: distributed Gaussian-process target tracking in wireless sensor networks.

The package is the world (scenarios, network, measurements, the environment) and the tracker
contract (:mod:`dgpt_gym.tracker`, :mod:`dgpt_gym.registry`); :mod:`dgpt_gym.benchmark` is
the evaluation harness. Importing it registers ``DGPTrack-v0`` and the RL environments
declared in :mod:`agents.rl.registration` with Gymnasium, as entry-point strings: no tracker
or environment module is imported until one is built. Tracker ids are declared beside their
code (:mod:`agents.registration`, :mod:`baselines.registration`) and read by the registry on
first use.
"""

from importlib.metadata import PackageNotFoundError, version

import gymnasium

from dgpt_gym.env import DGPTrackEnv
from dgpt_gym.problem import ProblemSpec
from dgpt_gym.registry import load_table, make_tracker, register_tracker, tracker_ids
from dgpt_gym.scenarios import SCENARIOS, get_scenario
from dgpt_gym.tracker import Estimate, TrackerBase

RL_ENVIRONMENT_TABLE = "agents.rl.registration:ENVIRONMENTS"
"""Where the RL environments' Gymnasium ids are declared (beside their code)."""

try:
    __version__ = version("dgpt-gym")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0+unknown"

__all__ = [
    "DGPTrackEnv",
    "Estimate",
    "TrackerBase",
    "ProblemSpec",
    "SCENARIOS",
    "get_scenario",
    "make_tracker",
    "register_tracker",
    "tracker_ids",
    "__version__",
]

if "DGPTrack-v0" not in gymnasium.registry:
    gymnasium.register(
        id="DGPTrack-v0",
        entry_point="dgpt_gym.env:DGPTrackEnv",
        vector_entry_point="dgpt_gym.env:vector_env",
    )
for _environment in load_table(RL_ENVIRONMENT_TABLE):
    if _environment.id not in gymnasium.registry:
        gymnasium.register(
            id=_environment.id,
            entry_point=_environment.entry_point,
            vector_entry_point=_environment.vector_entry_point,
            kwargs=dict(_environment.kwargs),
        )
