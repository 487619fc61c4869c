"""The RL environments (agents/rl): checkers, determinism, reward accounting, sensor
filtering, a short PPO run against a random policy, and saving and loading a model."""

import json
import shutil
import tempfile

import gymnasium as gym
import numpy as np
import pytest
from conftest import assert_fixes_every_argument
from gymnasium.utils.env_checker import check_env as gymnasium_check_env
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from agents.rl.evaluation import (
    ConstantPolicy,
    ModelPolicy,
    RandomPolicy,
    baseline_policies,
    evaluate_policy_on_seeds,
)
from agents.rl.sensors_env import filter_reports
from agents.rl.training import load_agent, train_agent

RL_ENVS = ["DGPTrackWindow-v0", "DGPTrackGating-v0", "DGPTrackSensors-v0"]


def rollout(env, actions, seed):
    observation, _ = env.reset(seed=seed)
    observations, rewards, infos = [observation], [], []
    for action in actions:
        observation, reward, terminated, truncated, info = env.step(action)
        observations.append(observation)
        rewards.append(reward)
        infos.append(info)
        if terminated or truncated:
            break
    return np.array(observations), np.array(rewards), infos


@pytest.mark.parametrize("env_id", RL_ENVS)
def test_checkers_pass_and_the_same_seed_gives_the_same_episode(env_id):
    env = gym.make(env_id, scenario="S3", clutter_rate=5.0)
    gymnasium_check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=False)
    env.action_space.seed(3)
    actions = [env.action_space.sample() for _ in range(40)]
    first = rollout(env, actions, seed=7)
    second = rollout(env, actions, seed=7)
    np.testing.assert_array_equal(first[0], second[0])
    np.testing.assert_array_equal(first[1], second[1])
    other = rollout(env, actions, seed=8)
    assert not np.array_equal(first[1], other[1])


@pytest.mark.parametrize("env_id", RL_ENVS)
def test_vector_envs(env_id):
    envs = gym.make_vec(env_id, num_envs=2, vectorization_mode="sync")
    observations, _ = envs.reset(seed=0)
    assert observations.shape == (2, *envs.single_observation_space.shape)
    observations, rewards, *_ = envs.step(envs.action_space.sample())
    assert rewards.shape == (2,) and np.all(np.isfinite(rewards))
    envs.close()


@pytest.mark.parametrize(
    "env_id, kwargs, name",
    [
        ("DGPTrackWindow-v0", {"windows": [0]}, "windows"),
        ("DGPTrackWindow-v0", {"compute_weight": -1.0}, "compute_weight"),
        ("DGPTrackWindow-v0", {"layout": "random"}, "layout"),
        ("DGPTrackGating-v0", {"min_threshold": 0.0}, "min_threshold"),
        ("DGPTrackGating-v0", {"min_threshold": 5.0, "max_threshold": 2.0}, "max_threshold"),
        ("DGPTrackSensors-v0", {"n_candidates": 0}, "n_candidates"),
        ("DGPTrackSensors-v0", {"n_candidates": 251}, "n_candidates"),
        ("DGPTrackSensors-v0", {"energy_cost": -0.1}, "energy_cost"),
        ("DGPTrackSensors-v0", {"error_scale": 0.0}, "error_scale"),
        ("DGPTrackSensors-v0", {"clutter_rate": -1.0}, "clutter_rate"),
    ],
)
def test_arguments_are_validated(env_id, kwargs, name):
    with pytest.raises(ValueError, match=name):
        gym.make(env_id, **kwargs)


@pytest.mark.parametrize("env_id", RL_ENVS)
def test_the_tracker_inside_fixes_every_argument_of_dgpt(env_id):
    """A new argument of ``DGPT``, or a changed default, must not move these tasks under
    their committed agents: what the environment does not set from its own arguments comes
    from ``TREND_TRACKER_OPTIONS``, which names every other argument of ``DGPT``."""
    from agents.dgpt import DGPT
    from agents.rl.registration import TREND_TRACKER_OPTIONS

    tracker = gym.make(env_id).unwrapped.tracker
    assert type(tracker) is DGPT
    own = {"aggregation", "inputs", "window", "gate_threshold"}
    assert_fixes_every_argument(tracker, TREND_TRACKER_OPTIONS, own)


@pytest.mark.parametrize("env_id", ["DGPTrackWindow-v0", "DGPTrackGating-v0"])
def test_a_per_episode_layout_comes_from_the_reset_seed(env_id):
    """layout="per_episode": seed s's layout is DGPTrack-v0's with layout_seed=s, another
    seed gives another, the same seed the same, and a reset without a seed (an autoreset)
    draws a layout seed above the evaluation seeds; layout="fixed" (the default) keeps
    one layout whatever the seed."""
    env = gym.make(env_id, scenario="S3", trajectory="random", layout="per_episode").unwrapped
    env.reset(seed=3)
    layout = env.inner.network.positions.copy()
    reference = gym.make("DGPTrack-v0", scenario="S3", layout_seed=3).unwrapped
    reference.reset(seed=0)
    np.testing.assert_array_equal(layout, reference.network.positions)
    env.reset(seed=4)
    assert not np.array_equal(layout, env.inner.network.positions)
    env.reset(seed=3)
    np.testing.assert_array_equal(layout, env.inner.network.positions)
    env.reset()
    assert env.inner.layout_seed >= 1000
    fixed = gym.make(env_id, scenario="S3").unwrapped
    fixed.reset(seed=3)
    first = fixed.inner.network.positions.copy()
    fixed.reset(seed=4)
    np.testing.assert_array_equal(first, fixed.inner.network.positions)
    assert fixed.inner.layout_seed == 0


def test_window_reward_is_error_plus_cubic_compute_cost():
    windows, weight = (2, 5, 12), 0.3
    env = gym.make("DGPTrackWindow-v0", windows=windows, compute_weight=weight, clutter_rate=5.0)
    actions = [0, 2, 1, 2, 2, 0, 1] * 6
    _, rewards, infos = rollout(env, actions, seed=2)
    tracker = env.unwrapped.tracker
    for action, reward, info in zip(actions, rewards, infos):
        error = np.linalg.norm(info["estimate"] - info["position"])
        c = windows[action]
        expected = -error / 50.0 - weight * info["n_experts"] * (c / 12) ** 3
        assert info["window"] == c
        assert reward == pytest.approx(expected, rel=1e-12, abs=1e-12)
    # the expert count the cost uses is that of the last step's window: sensors with a
    # summary in the last C steps of data
    records = tracker.window_.records
    latest = records[-1].step
    sensors = {int(s) for r in records if r.step > latest - windows[actions[-1]] for s in r.sensors}
    assert infos[-1]["n_experts"] == len(sensors)
    assert any(info["n_experts"] > 0 for info in infos)


def test_gating_action_maps_log_linearly_and_rewards_add_up():
    env = gym.make("DGPTrackGating-v0", min_threshold=2.0, max_threshold=18.0, compute_weight=0.5)
    inner = env.unwrapped
    assert inner.threshold([-1.0]) == pytest.approx(2.0)
    assert inner.threshold([0.0]) == pytest.approx(6.0)  # the geometric mean
    assert inner.threshold([1.0]) == pytest.approx(18.0)
    assert inner.threshold([7.0]) == pytest.approx(18.0)  # clipped
    actions = [np.array([a], dtype=np.float32) for a in np.linspace(-1, 1, 30)]
    _, rewards, infos = rollout(env, actions, seed=4)
    for action, reward, info in zip(actions, rewards, infos):
        assert info["gate_threshold"] == pytest.approx(inner.threshold(action))
        error = np.linalg.norm(info["estimate"] - info["position"])
        expected = -error / 50.0 - 0.5 * info["n_experts"] * (3 / 3) ** 3
        assert reward == pytest.approx(expected, rel=1e-12, abs=1e-12)


def test_hard_gate_drops_measurements_beyond_the_threshold():
    env = gym.make("DGPTrackGating-v0", min_threshold=1.0, max_threshold=3.0, clutter_rate=5.0)
    tight = rollout(env, [np.array([-1.0], dtype=np.float32)] * 60, seed=1)
    loose = rollout(env, [np.array([1.0], dtype=np.float32)] * 60, seed=1)
    # feature 7 is log1p(measurements the hard gate dropped) / 4
    gated_out_tight = sum(np.expm1(4 * obs[7]) for obs in tight[0][1:])
    gated_out_loose = sum(np.expm1(4 * obs[7]) for obs in loose[0][1:])
    assert gated_out_tight > gated_out_loose  # a 1-sigma gate drops more than a 3-sigma one


def test_sensor_reward_is_error_plus_energy():
    env = gym.make("DGPTrackSensors-v0", n_candidates=6, energy_cost=0.07, error_scale=20.0)
    rng = np.random.default_rng(0)
    actions = rng.integers(0, 2, size=(50, 6)).astype(np.int8)
    _, rewards, infos = rollout(env, actions, seed=5)
    for action, reward, info in zip(actions, rewards, infos):
        error = np.linalg.norm(info["estimate"] - info["position"])
        assert info["n_woken"] == action.sum() == info["woken"].sum()
        assert reward == pytest.approx(-error / 20.0 - 0.07 * action.sum(), rel=1e-12, abs=1e-12)
        reporting = info["reports"]["sensor"][info["reports"]["mask"].astype(bool)]
        assert set(reporting.tolist()) <= set(np.flatnonzero(info["woken"]).tolist())


def test_all_sensors_woken_reproduce_dgptrack_and_none_woken_report_nothing():
    env = gym.make(
        "DGPTrackSensors-v0", n_candidates=250, clutter_sensors="detecting", clutter_rate=5.0
    )
    reference = gym.make("DGPTrack-v0", clutter_sensors="detecting", clutter_rate=5.0)
    _, _, infos = rollout(env, [np.ones(250, dtype=np.int8)] * 200, seed=11)
    observation, _ = reference.reset(seed=11)
    for info in infos:
        for key in ("measurements", "sensor", "mask"):
            np.testing.assert_array_equal(info["reports"][key], observation[key])
        observation, *_ = reference.step(info["estimate"])
    assert sum(int(info["reports"]["mask"].sum()) for info in infos) > 100
    _, _, silent = rollout(env, [np.zeros(250, dtype=np.int8)] * 200, seed=11)
    assert all(info["reports"]["mask"].sum() == 0 for info in silent)


def test_baselines_cover_the_issue():
    policies, default = baseline_policies(gym.make("DGPTrackSensors-v0", n_candidates=4))
    assert list(policies) == ["nearest 1", "nearest 2", "nearest 3", "nearest 4"]
    assert default == "nearest 4"
    np.testing.assert_array_equal(policies["nearest 2"].predict(None), [1, 1, 0, 0])
    policies, default = baseline_policies(gym.make("DGPTrackWindow-v0"))
    assert default == "fixed C=4" and "fixed C=20" in policies
    policies, default = baseline_policies(gym.make("DGPTrackGating-v0"))
    assert default == "fixed threshold 30" and len(policies) == 9


EASY = {
    "windows": (2, 20),
    "compute_weight": 1.0,
    "scenario": "S1",
    "max_episode_steps": 30,
}


def test_short_ppo_run_beats_a_random_policy_on_held_out_seeds(short_ppo):
    """An easy task: a compute cost that makes C = 20 expensive. 6144 PPO steps (about 25 s;
    with the default VecNormalize, 3072 were not enough for the running statistics to
    settle, without it they were) must learn to prefer C = 2. Over 12 held-out episodes, Welch's one-sided t-test of the
    returns must reject "PPO no better than random" at p < 1e-3 (the returns differ by many
    standard deviations when the task is learned, so the test is far from its threshold)."""
    agent = short_ppo("DGPTrackWindow-v0", EASY, timesteps=6144)
    env = gym.make("DGPTrackWindow-v0", **EASY)
    seeds = range(12)
    policy = ModelPolicy(agent.model, agent.normalizer)
    trained = [e["return"] for e in evaluate_policy_on_seeds(env, policy, seeds)]
    random = [
        e["return"] for e in evaluate_policy_on_seeds(env, RandomPolicy(env.action_space, 0), seeds)
    ]
    test = stats.ttest_ind(trained, random, equal_var=False, alternative="greater")
    assert test.pvalue < 1e-3, (np.mean(trained), np.mean(random), test)
    # and it is about as good as the best fixed choice, C = 2
    best = [e["return"] for e in evaluate_policy_on_seeds(env, ConstantPolicy(0), seeds)]
    assert np.mean(trained) >= np.mean(best) - 3 * np.std(best, ddof=1) / np.sqrt(len(best))


def test_saved_model_loads_and_reproduces_its_actions(tmp_path, monkeypatch):
    temporary = tmp_path / "temporary"
    temporary.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temporary))
    agent = train_agent(
        "DGPTrackSensors-v0",
        "a2c",
        timesteps=200,
        seed=1,
        n_envs=1,
        out=tmp_path / "agent",
        env_kwargs={"n_candidates": 4, "max_episode_steps": 20},
        progress=False,
    )
    # Stable-Baselines3's default logger would have made an empty folder there
    assert not list(temporary.glob("SB3-*"))
    model, config = load_agent(tmp_path / "agent")
    assert config["algo"] == "a2c" and config["env"] == "DGPTrackSensors-v0"
    # the observation statistics of training are saved and frozen for evaluation
    saved = config["normalizer"]
    np.testing.assert_array_equal(saved.obs_rms.mean, agent.normalizer.obs_rms.mean)
    assert saved.obs_rms.count == agent.normalizer.obs_rms.count > 200
    assert not saved.training
    env = gym.make("DGPTrackSensors-v0", n_candidates=4)
    observation, _ = env.reset(seed=3)
    trained, reloaded = ModelPolicy(agent.model, agent.normalizer), ModelPolicy(model, saved)
    for _ in range(30):
        expected = trained.predict(observation)
        loaded = reloaded.predict(observation)
        np.testing.assert_array_equal(expected, loaded)
        observation, *_ = env.step(loaded)
    assert saved.obs_rms.count == agent.normalizer.obs_rms.count  # acting changed no statistic


def test_dqn_needs_a_discrete_action_space(tmp_path):
    with pytest.raises(ValueError, match="dqn"):
        train_agent("DGPTrackSensors-v0", "dqn", timesteps=10, out=tmp_path, progress=False)


@pytest.mark.parametrize(
    "name, env_id", [("window", "DGPTrackWindow-v0"), ("gating", "DGPTrackGating-v0")]
)
def test_the_committed_tuning_agents_load_and_act(name, env_id):
    """models/ holds the five window (1e6 steps) and five gating (40000) agents docs/rl.md
    quotes, each at most 1 MB; they load with their frozen normaliser, were trained on random paths in
    per-episode layouts, and act on raw observations of that environment."""
    from pathlib import Path

    models = Path(__file__).parents[3] / "models"
    folders = sorted(models.glob(f"{name}-ppo-seed*"))
    assert [folder.name for folder in folders] == [f"{name}-ppo-seed{s}" for s in range(5)]
    for folder in folders:
        assert sum(f.stat().st_size for f in folder.iterdir()) <= 1_000_000
        config = json.loads((folder / "config.json").read_text())
        assert config["env"] == env_id
        assert config["timesteps"] == (1_000_000 if name == "window" else 40000)
        n_envs = 32 if name == "window" else 4  # models/README.md's commands
        seed = int(folder.name.rsplit("seed", 1)[1])
        assert (config["n_envs"], config["training_env_seed"]) == (n_envs, 10000 + n_envs * seed)
        assert config["env_kwargs"] == {
            "scenario": "S3",
            "clutter_rate": 5,
            "trajectory": "random",
            "layout": "per_episode",
        }
    model, config = load_agent(folders[0])
    assert config["normalizer"] is not None
    policy = ModelPolicy(model, config["normalizer"])
    env = gym.make(env_id, **config["env_kwargs"])
    observation, _ = env.reset(seed=0)
    for _ in range(5):
        action = policy.predict(observation)
        assert env.action_space.contains(action)
        observation, *_ = env.step(action)


def test_a_rule_without_from_env_is_called_with_its_setting():
    """Rules written before ``from_env`` existed (a class called with the setting) still
    work in ``make_policy``."""
    from agents.rl.runs import make_policy

    class Always:
        def __init__(self, action):
            self.action = action

        def predict(self, observation):
            return self.action

    env = gym.make("DGPTrackWindow-v0")
    policy = make_policy("always", {"action": 2}, env, 0, {"always": Always})
    assert policy.predict(None) == 2


def test_run_policies_keeps_each_policys_episodes_and_reads_them_back(tmp_path, monkeypatch):
    """With a cache folder, a policy's rows are written once and a second call with the same
    policy, environment and seeds reads them back without running an episode; other seeds
    are another key and run."""
    from agents.rl import runs

    arguments = ("DGPTrackWindow-v0", {"scenario": "S3", "max_episode_steps": 5})
    rows = runs.run_policies([("constant", 1)], *arguments, [0, 1], 1, cache=tmp_path)
    assert len(list(tmp_path.glob("*.json"))) == 1 and len(rows[0]) == 2

    def no_episodes(task):
        raise AssertionError("ran an episode")

    monkeypatch.setattr(runs, "_run_block", no_episodes)
    again = runs.run_policies([("constant", 1)], *arguments, [0, 1], 1, cache=tmp_path)
    assert again == rows
    with pytest.raises(AssertionError, match="ran an episode"):
        runs.run_policies([("constant", 1)], *arguments, [0, 2], 1, cache=tmp_path)


def test_cached_episodes_are_keyed_by_the_code(tmp_path, monkeypatch):
    """Rows cached under one version of the code are not read back under another."""
    from agents.rl import runs

    arguments = ("DGPTrackWindow-v0", {"scenario": "S3", "max_episode_steps": 3})
    runs.run_policies([("constant", 1)], *arguments, [0], 1, cache=tmp_path)
    monkeypatch.setattr(runs, "code_digest", lambda: "edited")
    runs.run_policies([("constant", 1)], *arguments, [0], 1, cache=tmp_path)
    assert len(list(tmp_path.glob("*.json"))) == 2


def test_source_digest_follows_each_source_file_and_its_path(tmp_path):
    """The digest changes with a source file's bytes or its path, and not with compiled
    files or files of other kinds."""
    from agents.rl.runs import source_digest

    package = tmp_path / "package"
    (package / "sub").mkdir(parents=True)
    (package / "a.py").write_text("x = 1\n")
    (package / "sub" / "windows.json").write_text("{}")
    first = source_digest([package])
    (package / "__pycache__").mkdir()
    (package / "__pycache__" / "a.py").write_text("compiled")
    (package / "notes.txt").write_text("not code")
    assert source_digest([package]) == first
    (package / "sub" / "windows.json").write_text('{"S1": 3}')
    second = source_digest([package])
    assert second != first
    (package / "sub" / "windows.json").rename(package / "windows.json")
    assert source_digest([package]) not in (first, second)


def test_an_agents_cached_episodes_are_keyed_by_its_saved_files(tmp_path):
    """An agent folder as train_rl.py leaves it (with its monitor/ folder) is cached by its
    saved files: the same files read back the same rows, a changed model.zip is another
    key; a folder without model.zip or trained elsewhere is refused by name."""
    from pathlib import Path

    from agents.rl import runs

    source = Path(__file__).parents[3] / "models" / "window-ppo-seed0"
    folder = tmp_path / "agent"
    shutil.copytree(source, folder)
    (folder / "monitor").mkdir()
    (folder / "monitor" / "train.monitor.csv").write_text("#\n")
    config = json.loads((folder / "config.json").read_text())
    kwargs = {**config["env_kwargs"], "max_episode_steps": 3}
    cache = tmp_path / "cache"
    first = runs.run_policies([("agent", folder)], config["env"], kwargs, [0], 1, cache=cache)
    again = runs.run_policies([("agent", folder)], config["env"], kwargs, [0], 1, cache=cache)
    assert again == first and len(list(cache.glob("*.json"))) == 1
    with (folder / "model.zip").open("ab") as handle:
        handle.write(b"\0")  # still a valid zip: the archive's end is found from the back
    runs.run_policies([("agent", folder)], config["env"], kwargs, [0], 1, cache=cache)
    assert len(list(cache.glob("*.json"))) == 2
    runs.check_agent_folders([folder], config["env"], config["env_kwargs"])
    with pytest.raises(ValueError, match="was trained on"):
        runs.check_agent_folders([folder], config["env"], {"scenario": "S1"})
    with pytest.raises(ValueError, match="not a trained agent's folder"):
        runs.check_agent_folders([tmp_path / "cache"], config["env"], {})
    namesake = tmp_path / "other" / "agent"
    shutil.copytree(folder, namesake)
    with pytest.raises(ValueError, match="same name"):
        runs.check_agent_folders([folder, namesake], config["env"], config["env_kwargs"])


@settings(max_examples=60, deadline=None)
@given(
    sensor=st.lists(st.integers(0, 9), max_size=12),
    padding=st.integers(0, 4),
    woken=st.lists(st.booleans(), min_size=10, max_size=10),
)
def test_filter_reports_keeps_the_woken_sensors_rows_in_order(sensor, padding, woken):
    """``filter_reports`` against a plain reference (np.isin over the woken sensors' ids):
    the woken sensors' rows first, in their order, then padding (sensor -1, mask 0)."""
    n, k = len(sensor), len(sensor) + padding
    sensors = np.full(k, -1)
    sensors[:n] = sensor
    measurements = np.zeros((k, 2))
    measurements[:n] = np.arange(2 * n).reshape(n, 2) + 0.5
    mask = (np.arange(k) < n).astype(np.int8)
    woken = np.array(woken)
    reports = filter_reports(
        {"measurements": measurements, "sensor": sensors, "mask": mask, "t": 3}, woken
    )
    keep = (mask == 1) & np.isin(sensors, np.flatnonzero(woken))
    m = int(keep.sum())
    np.testing.assert_array_equal(reports["mask"], (np.arange(k) < m).astype(np.int8))
    np.testing.assert_array_equal(reports["sensor"][:m], sensors[keep])
    np.testing.assert_array_equal(reports["sensor"][m:], -1)
    np.testing.assert_array_equal(reports["measurements"][:m], measurements[keep])
    np.testing.assert_array_equal(reports["measurements"][m:], 0.0)
    np.testing.assert_array_equal(reports["awake"], woken)
    assert reports["t"] == 3
