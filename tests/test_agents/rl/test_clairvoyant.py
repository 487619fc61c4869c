"""The clairvoyant references of the tuning tasks (agents/rl/clairvoyant.py): the greedy
policy's trial rewards against replays from a fresh reset, and the hindsight choice against
hand-made rows."""

import gymnasium as gym
import numpy as np
import pytest

from agents.rl.clairvoyant import GreedyClairvoyantPolicy, hindsight_best_per_seed


@pytest.mark.parametrize("env_id", ["DGPTrackWindow-v0", "DGPTrackGating-v0"])
def test_the_greedy_policy_scores_each_action_as_a_replay_from_reset_would(env_id):
    """At step 6 of an episode the greedy policy's reward for each action must equal the
    reward of a replay that resets with the same seed, repeats the first five choices and
    then takes that action: the copies meet the same measurements and random draws as the
    real environment. It must then take the action with the highest of those rewards."""
    kwargs = dict(scenario="S1", clutter_rate=5.0, trajectory="random", layout="per_episode")
    env = gym.make(env_id, **kwargs)
    policy = GreedyClairvoyantPolicy(env)
    observation, _ = env.reset(seed=1003)
    chosen = []
    for _ in range(5):
        action = policy.predict(observation)
        observation, reward, *_ = env.step(action)
        assert reward == policy.last_rewards.max()
        chosen.append(action)
    policy.predict(observation)
    trial_rewards = policy.last_rewards
    candidates = list(env.unwrapped.fixed_actions()[0].values())
    assert len(trial_rewards) == len(candidates) == 9

    replay = gym.make(env_id, **kwargs)
    replayed = []
    for action in candidates:
        replay.reset(seed=1003)
        for earlier in chosen:
            replay.step(earlier)
        replayed.append(replay.step(action)[1])
    np.testing.assert_array_equal(trial_rewards, replayed)
    # the actions differ in what they score, so the choice is not a tie broken by order
    assert np.ptp(trial_rewards) > 0


def test_the_greedy_policy_needs_candidate_actions():
    env = gym.make("DGPTrack-v0")
    with pytest.raises(ValueError, match="actions must be given"):
        GreedyClairvoyantPolicy(env)
    with pytest.raises(ValueError, match="at least one candidate"):
        GreedyClairvoyantPolicy(env, actions=[])


def _rows(seed_returns, knob):
    return [{"seed": seed, "return": value, "per_step": knob} for seed, value in seed_returns]


def test_hindsight_takes_each_seeds_best_setting():
    rows = {
        "fixed 2": _rows([(0, -5.0), (1, -1.0), (2, -3.0)], 2),
        "fixed 3": _rows([(0, -4.0), (1, -2.0), (2, -3.0)], 3),
        "fixed 4": _rows([(0, -6.0), (1, -1.5), (2, -2.5)], 4),
    }
    chosen = hindsight_best_per_seed(rows)
    assert [row["setting"] for row in chosen] == ["fixed 3", "fixed 2", "fixed 4"]
    assert [row["return"] for row in chosen] == [-4.0, -1.0, -2.5]
    assert [row["per_step"] for row in chosen] == [3, 2, 4]
    # a tie goes to the first setting
    tied = hindsight_best_per_seed({"a": _rows([(0, 1.0)], 1), "b": _rows([(0, 1.0)], 2)})
    assert tied[0]["setting"] == "a"


@pytest.mark.parametrize(
    "rows, message",
    [
        ({}, "at least one setting"),
        ({"a": _rows([(0, 1.0)], 1), "b": _rows([(0, 1.0), (1, 2.0)], 2)}, "same seeds"),
        ({"a": _rows([(0, 1.0)], 1), "b": _rows([(1, 1.0)], 2)}, "same seed"),
    ],
)
def test_hindsight_rejects_rows_that_do_not_pair(rows, message):
    with pytest.raises(ValueError, match=message):
        hindsight_best_per_seed(rows)


def test_among_ties_the_greedy_policy_keeps_the_preferred_setting():
    """On the first step of this S1 episode every gate threshold gives the same reward (the
    tracker has no model yet to gate with): the policy must keep the preferred threshold,
    and without a preference the first candidate."""
    env = gym.make("DGPTrackGating-v0", scenario="S1", clutter_rate=5.0)
    candidates = list(env.unwrapped.fixed_actions()[0].values())
    observation, _ = env.reset(seed=1000)
    assert observation[0] == 0  # no active experts before the first step
    preferred = GreedyClairvoyantPolicy(env, prefer=candidates[5])
    action = preferred.predict(observation)
    assert np.ptp(preferred.last_rewards) == 0
    np.testing.assert_array_equal(action, candidates[5])
    np.testing.assert_array_equal(GreedyClairvoyantPolicy(env).predict(observation), candidates[0])
    with pytest.raises(ValueError, match="prefer must be one of"):
        GreedyClairvoyantPolicy(env, prefer=np.array([0.3], dtype=np.float32))


class _TableEnv(gym.Env):
    """A one-step stand-in whose reward for action a is ``rewards[a]``."""

    def __init__(self, rewards):
        self.rewards = rewards

    def step(self, action):
        return None, self.rewards[action], False, False, {}


@pytest.mark.parametrize(
    "rewards, prefer, expected",
    [
        ([1.0, 1.0, 0.0, 0.0, 0.0], 3, 1),  # tied at 0 and 1: the nearer to 3
        ([0.0, 1.0, 0.0, 1.0, 0.0], 4, 3),
        ([0.0, 1.0, 0.0, 1.0, 0.0], 2, 1),  # equally near: the first
        ([0.0, 1.0, 2.0, 0.0, 0.0], 4, 2),  # no tie: the best
        ([1.0, 1.0, 0.0, 0.0, 0.0], None, 0),
    ],
)
def test_among_tied_candidates_the_one_nearest_the_preferred_is_taken(rewards, prefer, expected):
    policy = GreedyClairvoyantPolicy(_TableEnv(rewards), actions=range(5), prefer=prefer)
    assert policy.predict(None) == expected


def test_the_greedy_policy_refuses_a_rendering_env():
    env = gym.make("DGPTrackGating-v0", render_mode="rgb_array")
    with pytest.raises(ValueError, match="must not render"):
        GreedyClairvoyantPolicy(env)
