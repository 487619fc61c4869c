"""The adaptive rules of DGPTrackSensors-v1 (agents/rl/heuristics.py), checked against what
the environment's own state says they should wake."""

import gymnasium as gym
import numpy as np
import pytest

import dgpt_gym  # noqa: F401  (registers the environments)
from agents.rl.heuristics import SilenceSearchPolicy, UncertaintyRadiusPolicy, level_for
from agents.rl.sensors_v1 import WAKE_COUNTS

ALL = len(WAKE_COUNTS) - 1


def test_level_for_takes_the_fewest_sensors_that_suffice():
    assert [level_for(n) for n in (0, 1, 5, 6, 7, 64, 65, 250, 1000)] == [
        0,
        1,
        5,
        5,
        6,
        12,
        ALL,
        ALL,
        ALL,
    ]


def within(env, radius):
    """Charged sensors (as the environment counts them) within ``radius`` of the prediction."""
    cost = env.wake_energy + np.where(env._awake, 0.0, env.startup_energy)
    charged = env.battery_ >= cost - 1e-12
    distance = np.linalg.norm(env.inner.network.positions - env._predicted, axis=1)
    return int(np.sum(charged & (distance <= radius)))


@pytest.mark.parametrize(
    "sensing_range, branches", [(50.0, {"near": 17, "wide": 38}), (80.0, None)]
)
def test_the_uncertainty_radius_rule_wakes_the_sensors_within_its_radius(sensing_range, branches):
    """At the default sensing range, and at another one, which the rule takes from the
    environment (``from_env``, as the evaluation scripts make it)."""
    env = gym.make("DGPTrackSensors-v1", scenario="S3", sensing_range=sensing_range).unwrapped
    observation, _ = env.reset(seed=4)
    checked = {"near": 0, "wide": 0}
    for step in range(40):
        sigma = float(np.max(env._predicted_std))
        for k in (0.5, 3.0):
            count = within(env, sensing_range + k * sigma)
            action = UncertaintyRadiusPolicy.from_env(env, k=k).predict(observation)
            if count < 16:
                assert action == level_for(max(count, 1)), (step, k, count)
                checked["near"] += 1
            elif k >= 2.0:  # beyond the 16 observed sensors: at least the r + 2 sigma count
                assert action == level_for(max(16, within(env, sensing_range + 2.0 * sigma)))
                checked["wide"] += 1
        # blind for a while from step 10, so that the prediction widens
        observation, *_ = env.step(level_for(8) if step < 10 or step > 25 else 0)
    if branches is not None:
        assert checked == branches
    assert min(checked.values()) > 0  # both branches of the rule were checked


def test_the_silence_search_rule_searches_after_its_silent_steps():
    env = gym.make("DGPTrackSensors-v1", scenario="S1", clutter_rate=1.0).unwrapped
    observation, _ = env.reset(seed=2)
    rule = SilenceSearchPolicy(n=4, silent=2)
    for _ in range(5):
        assert rule.predict(observation) == level_for(4)
        observation, _, _, _, info = env.step(level_for(4))
    silent = 0
    for _ in range(4):  # nothing woken: no reports
        observation, *_ = env.step(0)
        silent += 1
        assert rule.predict(observation) == (ALL if silent >= 2 else level_for(4))
