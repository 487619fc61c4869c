"""DGPTrackSensors-v1 and -v2 (agents/rl/sensors_v1.py): checkers, determinism, held-out
layouts, reward and energy accounting recomputed from what the environment reports, and
re-acquisition of a lost track."""

import gymnasium as gym
import numpy as np
import pytest
from conftest import assert_fixes_every_argument
from gymnasium.utils.env_checker import check_env as gymnasium_check_env
from scipy import stats
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import dgpt_gym  # noqa: F401  (registers the environments)
from agents.rl.evaluation import ModelPolicy, RandomPolicy, evaluate_policy_on_seeds
from agents.rl.sensors_v1 import WAKE_COUNTS, decode_observation

ENV_ID = "DGPTrackSensors-v1"
BOTH = ["DGPTrackSensors-v1", "DGPTrackSensors-v2"]
ALL = len(WAKE_COUNTS) - 1
NEAREST = {count: index for index, count in enumerate(WAKE_COUNTS)}


@pytest.mark.parametrize("env_id", BOTH)
def test_checkers_pass_and_the_same_seed_gives_the_same_episode(env_id):
    env = gym.make(env_id, scenario="S2", clutter_rate=5.0)
    gymnasium_check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=False)
    env.action_space.seed(1)
    actions = [env.action_space.sample() for _ in range(30)]

    def rollout(seed):
        observation, _ = env.reset(seed=seed)
        trace = [observation]
        for action in actions:
            observation, reward, *_ = env.step(action)
            trace.append(np.r_[observation, reward])
        return np.concatenate(trace)

    np.testing.assert_array_equal(rollout(4), rollout(4))
    assert not np.array_equal(rollout(4), rollout(5))


def test_each_seed_has_its_own_layout_and_path():
    env = gym.make(ENV_ID).unwrapped
    env.reset(seed=3)
    layout, path = env.inner.network.positions.copy(), env.inner.trajectory_.positions.copy()
    env.reset(seed=1003)
    assert not np.array_equal(layout, env.inner.network.positions)
    assert not np.array_equal(path[:10], env.inner.trajectory_.positions[:10])
    env.reset(seed=3)
    np.testing.assert_array_equal(layout, env.inner.network.positions)
    env.reset()  # an autoreset without a seed draws a layout above the evaluation seeds
    assert env.inner.layout_seed >= 1000


def test_reward_and_energy_accounting():
    """Known actions; the woken set is checked to be the n charged sensors nearest the
    prediction, and energy, batteries and reward are recomputed from it."""
    env = gym.make(ENV_ID, scenario="S1", wake_energy=0.02, startup_energy=0.05).unwrapped
    env.reset(seed=0)
    positions = env.inner.network.positions
    battery = np.ones(positions.shape[0])
    awake = np.zeros(positions.shape[0], dtype=bool)
    plan = [NEAREST[4], NEAREST[4], NEAREST[0], NEAREST[8], ALL, NEAREST[2]] * 8
    for action in plan:
        predicted = env._predicted.copy()
        count = WAKE_COUNTS[action]
        charged = np.flatnonzero(battery >= 0.02 + np.where(awake, 0.0, 0.05) - 1e-12)
        distance = np.linalg.norm(positions[charged] - predicted, axis=1)
        chosen = charged[np.argsort(distance, kind="stable")]
        expected_woken = np.zeros_like(awake)
        expected_woken[chosen if count is None else chosen[:count]] = True
        _, reward, _, _, info = env.step(action)
        np.testing.assert_array_equal(info["woken"], expected_woken)
        energy = 0.02 * expected_woken.sum() + 0.05 * (expected_woken & ~awake).sum()
        battery = np.maximum(battery - 0.02 * expected_woken - 0.05 * (expected_woken & ~awake), 0)
        awake = expected_woken
        assert info["energy"] == pytest.approx(energy, rel=1e-12)
        np.testing.assert_allclose(info["battery"], battery, rtol=0, atol=1e-12)
        expected_reward = -min(info["error"], 200.0) / 50.0 - 2.0 * energy
        assert reward == pytest.approx(expected_reward, rel=1e-12)
    # waking all five times at 0.07 and 0.02 a step emptied no one, but the budget shows
    assert battery.min() < 1.0 - 5 * 0.02


def test_an_empty_sensor_cannot_be_woken():
    env = gym.make(ENV_ID, wake_energy=0.6, startup_energy=0.0).unwrapped
    env.reset(seed=0)
    _, _, _, _, first = env.step(NEAREST[3])
    _, _, _, _, second = env.step(NEAREST[3])
    # after one step at 0.6 a sensor has 0.4 left: the three first ones are skipped
    assert not np.any(first["woken"] & second["woken"])
    assert second["woken"].sum() == 3


@pytest.mark.parametrize("env_id", BOTH)
def test_a_lost_track_is_reacquired_by_waking_every_sensor(env_id):
    """Nothing is woken for 25 steps, so the tracker extrapolates blind and loses the
    target; then the search action wakes every charged sensor, only the sensors that sense
    the target report (clutter at detecting sensors), and the track is back within 5 steps.
    Waking the 16 nearest the lost prediction instead (what v0 allowed) does not get it
    back."""

    def run(recovery_action):
        env = gym.make(env_id, scenario="S1", clutter_rate=1.0).unwrapped
        env.reset(seed=2)
        errors = [env.step(NEAREST[8])[4]["error"] for _ in range(10)]
        errors += [env.step(NEAREST[0])[4]["error"] for _ in range(25)]
        lost = errors[-1]
        errors += [env.step(recovery_action)[4]["error"] for _ in range(5)]
        return lost, errors[-1]

    lost, recovered = run(ALL)
    assert lost > 100.0  # two sensing ranges off: no sensor near the prediction senses it
    assert recovered < 5.0  # measured 0.8 m (1.5 m at the first search step)
    _, not_recovered = run(NEAREST[16])
    assert not_recovered > 150.0  # measured 212 m and growing


def test_v2_is_v1_with_the_distributed_ncv_tracker_inside():
    """The same class; v2 fixes ``tracker="dgpt-bcm"`` (window 20) as 0.9.0 built it (eq.
    (27) association, manoeuvre probability 0.5, no turn modes, a summary's variance
    sigma_n^2 + its spread, each expert updating with its summary, no silence particles),
    so the same seed and actions give the episode of v1 made with those arguments, and not
    the one of today's ``dgpt-bcm`` defaults."""
    from agents.state_space_dgpt import StateSpaceDGPT

    options = {
        "association": "local",
        "manoeuvre_probability": 0.5,
        "turn_rates": (),
        "summary_variance": "point",
        "expert_update": "summary",
        "silence_particles": 0,
    }
    v2 = gym.make("DGPTrackSensors-v2", scenario="S3").unwrapped
    v1, v1_mixture = (
        gym.make(
            ENV_ID, scenario="S3", tracker="dgpt-bcm", window=20, tracker_options=chosen
        ).unwrapped
        for chosen in (options, {**options, "expert_update": "mixture"})
    )
    assert isinstance(v2.tracker, StateSpaceDGPT) and v2.tracker.window == 20
    assert v2.tracker.association == "local" and v2.tracker.manoeuvre.probability == 0.5
    assert v2.tracker.silence_particles == 0 and v2.tracker.expert_update == "summary"
    assert type(gym.make(ENV_ID).unwrapped.tracker).__name__ == "DGPT"
    for env in (v1, v2, v1_mixture):
        env.reset(seed=7)
    rewards = []
    for action in [NEAREST[8]] * 20 + [NEAREST[2]] * 10:
        first, second, third = v1.step(action), v2.step(action), v1_mixture.step(action)
        np.testing.assert_array_equal(first[0], second[0])
        assert first[1] == second[1]
        rewards.append((second[1], third[1]))
    assert any(pinned != mixture for pinned, mixture in rewards)  # the pin matters here


def test_v2_fixes_every_argument_of_its_tracker():
    """A new argument of ``StateSpaceDGPT``, or a changed default, must not move v2 under
    the agents committed for it: v2 passes every argument but ``window`` (its own,
    fixed at 20) explicitly."""
    from agents.rl.registration import SENSORS_V2_TRACKER_OPTIONS
    from agents.state_space_dgpt import StateSpaceDGPT

    tracker = gym.make("DGPTrackSensors-v2").unwrapped.tracker
    assert type(tracker) is StateSpaceDGPT and tracker.window == 20
    assert_fixes_every_argument(tracker, SENSORS_V2_TRACKER_OPTIONS, {"window"})


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"tracker": "no-such-tracker"}, "tracker must be one of"),
        ({"tracker": "imm-pda", "tracker_options": None}, "does not take the arguments"),
        ({"tracker": "dgpt-gpoe-trend"}, "fixes tracker_options for tracker 'dgpt-rbcm-trend'"),
        ({"window": 0}, "window must be an integer >= 1"),
    ],
)
def test_bad_tracker_arguments_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        gym.make(ENV_ID, **kwargs)


def test_another_tracker_does_not_take_the_options_an_id_fixes_for_its_own():
    """v2 fixes aggregation "bcm" for its dgpt-bcm: asked for dgpt-rbcm it refuses rather
    than build BCM under that name; with the user's own options (None: the id's registered
    ones) it builds what was asked for."""
    with pytest.raises(ValueError, match="fixes tracker_options for tracker 'dgpt-bcm'"):
        gym.make("DGPTrackSensors-v2", tracker="dgpt-rbcm")
    tracker = gym.make("DGPTrackSensors-v2", tracker="dgpt-rbcm", tracker_options=None)
    assert tracker.unwrapped.tracker.aggregation == "rbcm"
    assert gym.make(ENV_ID, tracker="dgpt-rbcm-trend").unwrapped.tracker.aggregation == "rbcm"


@pytest.mark.parametrize("action", [-1, len(WAKE_COUNTS), 1.5, "2", np.array([1, 2])])
def test_bad_actions_are_refused(action):
    env = gym.make(ENV_ID).unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action must be an integer"):
        env.step(action)


@pytest.mark.parametrize("env_id", BOTH)
def test_the_committed_agents_load_and_act(env_id):
    """models/ holds the trained agents the docs quote; they load with their frozen
    normaliser and act on raw observations of the environment they were trained on."""
    from pathlib import Path

    from agents.rl.training import load_agent

    version = env_id.rsplit("-", 1)[1]
    models = Path(__file__).parents[3] / "models"
    folders = sorted(models.glob(f"sensors-{version}-ppo-seed*"))
    assert len(folders) == 5
    for folder in folders:
        assert sum(f.stat().st_size for f in folder.iterdir()) <= 1_000_000
    model, config = load_agent(folders[0])
    assert config["env"] == env_id and config["normalizer"] is not None
    policy = ModelPolicy(model, config["normalizer"])
    env = gym.make(env_id, **config["env_kwargs"])
    observation, _ = env.reset(seed=0)
    for _ in range(5):
        action = policy.predict(observation)
        assert env.action_space.contains(int(action))
        observation, *_ = env.step(action)


@pytest.mark.parametrize("env_id", BOTH)
def test_the_observation_describes_the_prediction_and_the_sensors(env_id):
    """Every field of the observation recomputed from the tracker's prediction, the
    sensor layout and what ``info`` reports."""
    env = gym.make(env_id, scenario="S4").unwrapped
    env.reset(seed=6)
    positions, silent = env.inner.network.positions, 0
    for step, action in enumerate([NEAREST[8]] * 12 + [NEAREST[0]] * 3 + [NEAREST[4]] * 3):
        observation, _, _, _, info = env.step(action)
        mean, var = env.tracker.prior_next_
        n_reports = int(info["reports"]["mask"].sum())
        silent = 0 if n_reports else silent + 1
        std = np.sqrt(var)
        cost = 0.01 + np.where(info["woken"], 0.0, 0.01)
        charged = np.flatnonzero(info["battery"] >= cost - 1e-12)
        distance = np.sort(np.linalg.norm(positions[charged] - mean, axis=1))
        expected = np.r_[
            np.column_stack([distance[:16] / 50.0, np.zeros(16), np.zeros(16)]).ravel(),
            np.log1p(std) / 6.0,
            (mean - info["estimate"]) / 25.0,
            1.0 - (step + 1) / env.inner.n_steps,
            min(silent / 10.0, 1.0),
            np.log1p(n_reports) / 6.0,
            info["battery"].mean(),
            np.sum(distance <= 50.0 + 2.0 * std.max()) / 64.0,
        ]
        nearest = charged[np.argsort(np.linalg.norm(positions[charged] - mean, axis=1))][:16]
        expected[1:48:3] = info["battery"][nearest]
        expected[2:48:3] = info["woken"][nearest]
        np.testing.assert_allclose(observation, np.clip(expected, -10, 10), rtol=1e-6, atol=1e-6)
        seen = decode_observation(observation)  # what the rules read, in physical units
        np.testing.assert_allclose(seen.distances, distance[:16] / 50.0, rtol=1e-6)
        assert seen.sigma == pytest.approx(std.max(), rel=1e-5)
        assert seen.silent_steps == min(silent, 10)
        assert seen.within_reach == np.sum(distance <= 50.0 + 2.0 * std.max())


def test_the_error_term_is_capped():
    """Nothing woken: the tracker never learns where the target is. Each step's reward is
    -error / 50 m up to an error of 200 m and -4 beyond (no energy is spent)."""
    env = gym.make(ENV_ID, scenario="S2").unwrapped
    env.reset(seed=1)
    capped = 0
    for _ in range(60):
        _, reward, _, _, info = env.step(NEAREST[0])
        assert reward == pytest.approx(-min(info["error"], 200.0) / 50.0, rel=1e-12)
        capped += info["error"] > 200.0
    assert 0 < capped < 60  # both sides of the cap were met


EASY = {"scenario": "S1", "clutter_rate": 1.0, "energy_weight": 20.0, "max_episode_steps": 30}


def test_short_ppo_run_beats_a_random_policy_on_held_out_seeds_and_layouts(short_ppo):
    """An easy configuration: energy weighs 10x the default, so the large wake counts a
    random policy often picks (24 to all) cost several units of reward per step while
    waking a few nearest sensors keeps the track. 4096 PPO steps on 2 sub-environments
    must learn to wake few: over 12 held-out seeds (new paths and layouts) Welch's one-sided
    t-test must reject "PPO no better than random" at p < 1e-3, and the agent must wake
    fewer sensors per step than random does on average."""
    agent = short_ppo(ENV_ID, EASY, timesteps=4096)
    env = gym.make(ENV_ID, **EASY)
    seeds = range(12)
    trained = evaluate_policy_on_seeds(env, ModelPolicy(agent.model, agent.normalizer), seeds)
    random = evaluate_policy_on_seeds(env, RandomPolicy(env.action_space, 0), seeds)
    trained_returns = [episode["return"] for episode in trained]
    random_returns = [episode["return"] for episode in random]
    test = stats.ttest_ind(trained_returns, random_returns, equal_var=False, alternative="greater")
    assert test.pvalue < 1e-3, (np.mean(trained_returns), np.mean(random_returns), test)
    assert np.mean([e["per_step"] for e in trained]) < np.mean([e["per_step"] for e in random])


def test_v1_fixes_every_argument_of_its_tracker():
    """As v2: a new argument of ``DGPT``, a changed default or a changed registration of
    ``dgpt-rbcm-trend`` must not move v1 under its committed agents."""
    from agents.dgpt import DGPT
    from agents.rl.registration import SENSORS_V1_TRACKER_OPTIONS

    tracker = gym.make(ENV_ID).unwrapped.tracker
    assert type(tracker) is DGPT and tracker.window == 3
    assert_fixes_every_argument(tracker, SENSORS_V1_TRACKER_OPTIONS, {"window"})
