"""The adaptive rules of the tuning tasks (agents/rl/tuning_rules.py) on hand-made
observations: which setting each situation gets, and the thresholds and windows through the
environments' own action maps."""

import gymnasium as gym
import numpy as np
import pytest

from agents.rl.features import FEATURE_NAMES
from agents.rl.tuning_rules import (
    TUNING_RULE_GRIDS,
    TUNING_RULES,
    QuietTrackGatePolicy,
    SurpriseWindowPolicy,
)

INDEX = {name: i for i, name in enumerate(FEATURE_NAMES)}


def observation(experts=3, innovation_m=1.0, silent_steps=0, gated_out=0):
    vector = np.zeros(len(FEATURE_NAMES), dtype=np.float32)
    vector[INDEX["n_experts"]] = experts / 10
    vector[INDEX["innovation"]] = innovation_m / 50.0
    vector[INDEX["silent_steps"]] = silent_steps / 10
    vector[INDEX["gated_out"]] = np.log1p(gated_out) / 4
    return vector


@pytest.mark.parametrize(
    "situation, tight",
    [
        (dict(innovation_m=1.9), True),  # quiet: within 2 m
        (dict(innovation_m=2.1), False),  # surprised
        (dict(innovation_m=0.5, silent_steps=1), False),  # the last step had no data
        (dict(experts=0, innovation_m=0.0), False),  # no model yet
        # the gate dropped every measurement: no summary, so no innovation; not quiet
        (dict(innovation_m=0.0, gated_out=6), False),
    ],
)
def test_the_quiet_track_gate_is_tight_only_while_the_track_is_quiet(situation, tight):
    env = gym.make("DGPTrackGating-v0").unwrapped
    policy = QuietTrackGatePolicy(tight=2.34, quiet_m=2.0, loose=30.0)
    threshold = env.threshold(policy.predict(observation(**situation)))
    assert threshold == pytest.approx(2.34 if tight else 30.0, rel=1e-6)


@pytest.mark.parametrize(
    "situation, window",
    [
        (dict(innovation_m=4.9), 2),
        (dict(innovation_m=5.1), 3),
        (dict(innovation_m=0.0, silent_steps=2), 3),
    ],
)
def test_the_surprise_window_follows_the_last_steps_innovation(situation, window):
    env = gym.make("DGPTrackWindow-v0").unwrapped
    policy = SurpriseWindowPolicy(quiet=2, surprised=3, surprise_m=5.0)
    assert env.windows[policy.predict(observation(**situation))] == window


def test_the_rules_take_the_environments_settings():
    """Made by ``make_policy`` as the evaluation scripts make them, the rules read the
    innovation with the environment's sensing range and act in its windows and threshold
    range."""
    from agents.rl.runs import make_policy

    gating = gym.make("DGPTrackGating-v0", sensing_range=80.0, max_threshold=20.0)
    setting = {"tight": 2.34, "quiet_m": 2.0, "loose": 12.0}
    rule = make_policy("quiet-track gate", setting, gating, 0, TUNING_RULES)
    quiet = observation(innovation_m=1.9 * 50.0 / 80.0)  # 1.9 m at a range of 80 m
    assert gating.unwrapped.threshold(rule.predict(quiet)) == pytest.approx(2.34, rel=1e-6)
    surprised = observation(innovation_m=2.1 * 50.0 / 80.0)
    assert gating.unwrapped.threshold(rule.predict(surprised)) == pytest.approx(12.0, rel=1e-6)
    windows = gym.make("DGPTrackWindow-v0", windows=(2, 4, 8), sensing_range=80.0)
    setting = {"quiet": 4, "surprised": 8, "surprise_m": 5.0}
    rule = make_policy("surprise window", setting, windows, 0, TUNING_RULES)
    assert windows.unwrapped.windows[rule.predict(observation(innovation_m=4.9 * 50 / 80))] == 4
    assert windows.unwrapped.windows[rule.predict(observation(innovation_m=5.1 * 50 / 80))] == 8


def test_every_grid_setting_makes_a_rule_that_acts_in_its_environment():
    for env_id, grids in TUNING_RULE_GRIDS.items():
        env = gym.make(env_id)
        for kind, grid in grids.items():
            for setting in grid:
                action = TUNING_RULES[kind](**setting).predict(observation())
                assert env.action_space.contains(action), (env_id, setting, action)


@pytest.mark.parametrize(
    "rule, setting, message",
    [
        (QuietTrackGatePolicy, dict(tight=0.0, quiet_m=2.0, loose=30.0), "tight must be in"),
        (QuietTrackGatePolicy, dict(tight=8.0, quiet_m=2.0, loose=5.0), "tight must be in"),
        (QuietTrackGatePolicy, dict(tight=2.0, quiet_m=2.0, loose=40.0), "loose must be in"),
        (QuietTrackGatePolicy, dict(tight=2.0, quiet_m=0.0, loose=30.0), "quiet_m must be in"),
        (SurpriseWindowPolicy, dict(quiet=7, surprised=3, surprise_m=5.0), "quiet must be one"),
        (SurpriseWindowPolicy, dict(quiet=3, surprised=3, surprise_m=-1.0), "surprise_m must"),
    ],
)
def test_rule_arguments_are_validated(rule, setting, message):
    with pytest.raises(ValueError, match=message):
        rule(**setting)


def test_the_rules_read_the_tracker_as_the_environment_writes_it():
    """The rules' decoding against the tracker itself: after each step the observation's
    innovation, read in metres, is the mean distance of the gated summaries from their
    predictions, the experts and silent steps are the tracker's, and a step without
    summaries is never quiet."""
    from agents.rl.features import decode_features
    from agents.rl.tuning_rules import _quiet

    env = gym.make("DGPTrackGating-v0", scenario="S1", clutter_rate=5.0)
    sensing_range = env.unwrapped.inner.sensing_range
    observation, _ = env.reset(seed=1000)
    checked, silent = 0, 0
    for _ in range(60):
        n_measurements = int(np.sum(env.unwrapped._pending["mask"]))  # the step's own
        observation, *_ = env.step(np.array([1.0], dtype=np.float32))
        tracker = env.unwrapped.tracker
        innovation = tracker.last_innovation_
        expected = float(np.mean(np.hypot(*innovation.T))) if innovation.size else 0.0
        seen = decode_features(observation)
        assert seen.innovation * sensing_range == pytest.approx(expected, rel=1e-5, abs=1e-4)
        assert seen.n_experts == tracker.n_experts_
        silent = 0 if n_measurements else silent + 1
        assert seen.silent_steps == silent
        if not innovation.size:
            assert not _quiet(observation, 1e9, sensing_range)
        checked += innovation.size > 0
    assert checked > 10
