import gymnasium as gym
import numpy as np
import pytest

from baselines.centroid import GatedCentroidTracker, weighted_centroid
from dgpt_gym import make_tracker, register_tracker, tracker_ids
from dgpt_gym.benchmark.episodes import run_episode, run_monte_carlo, summarize_runs


@pytest.mark.parametrize("scenario", ["S1", "S2", "S3", "S4"])
def test_reference_tracker_runs_end_to_end_with_finite_metrics(scenario):
    env = gym.make("DGPTrack-v0", scenario=scenario, clutter_rate=5.0)
    result = run_episode(env, make_tracker("centroid"), seed=0)
    n = env.unwrapped.n_steps
    assert result.mean.shape == result.truth.shape == (n, 2)
    values = result.metrics()
    for key in (
        "nrmse_x",
        "nrmse_y",
        "rmse_x",
        "rmse_y",
        "ci_coverage_x",
        "ci_width_y",
        "step_time_ms",
    ):
        assert np.isfinite(values[key]), key
    assert np.isnan(values["ucb_coverage_x"])  # the reference tracker has no UCB
    # a sane tracker: well below the error of guessing the area's centre
    centre_rmse = np.sqrt(np.mean((result.truth - 500.0) ** 2, axis=0))
    assert np.all(result.metrics()["rmse_x"] < 0.5 * centre_rmse[0])


def test_run_episode_is_reproducible():
    env = gym.make("DGPTrack-v0", scenario="S2", clutter_rate=5.0, trajectory="random")
    a = run_episode(env, make_tracker("centroid"), seed=5)
    b = run_episode(env, make_tracker("centroid"), seed=5)
    np.testing.assert_array_equal(a.mean, b.mean)
    np.testing.assert_array_equal(a.truth, b.truth)


def test_predict_through_stable_baselines3_evaluate_policy():
    """evaluate_policy drives the tracker through predict(); its episode returns equal
    minus the summed errors of run_episode with the same seed (the second episode
    continues the vector env's generator)."""
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import DummyVecEnv

    def make():
        return gym.make("DGPTrack-v0", scenario="S1", clutter_rate=5.0)

    tracker = make_tracker("centroid")
    _, info = make().reset(seed=0)
    tracker.reset(info["problem_spec"])
    vec_env = DummyVecEnv([make])
    vec_env.seed(21)
    returns, _ = evaluate_policy(tracker, vec_env, n_eval_episodes=2, return_episode_rewards=True)
    result = run_episode(make(), make_tracker("centroid"), seed=21)
    expected = -np.linalg.norm(result.mean - result.truth, axis=1).sum()
    # the VecEnv sums rewards in another order: equal up to rounding
    assert returns[0] == pytest.approx(expected, rel=1e-9)
    assert np.isfinite(returns[1]) and returns[1] < 0


def test_predict_keeps_one_tracker_per_sub_environment():
    envs = [gym.make("DGPTrack-v0", scenario=s) for s in ("S1", "S3")]
    tracker = make_tracker("centroid")
    observations, infos = zip(*(env.reset(seed=i) for i, env in enumerate(envs)))
    tracker.reset(infos[0]["problem_spec"])
    solo = [make_tracker("centroid"), make_tracker("centroid")]
    for single, info in zip(solo, infos):
        single.reset(info["problem_spec"])
    for _ in range(10):
        batch = {key: np.stack([obs[key] for obs in observations]) for key in observations[0]}
        actions, state = tracker.predict(batch, episode_start=np.zeros(2, bool))
        assert state is None and actions.shape == (2, 2)
        for action, single, obs in zip(actions, solo, observations):
            np.testing.assert_array_equal(action, single.update(obs).mean)
        observations = [env.step(a)[0] for env, a in zip(envs, actions)]


def test_predict_before_reset_says_what_to_do():
    observation, _ = gym.make("DGPTrack-v0").reset(seed=0)
    with pytest.raises(RuntimeError, match="problem_spec"):
        make_tracker("centroid").predict(observation)


def test_monte_carlo_summary():
    rows = run_monte_carlo(
        lambda: gym.make("DGPTrack-v0", scenario="S4"),
        lambda: make_tracker("centroid"),
        seeds=[0, 1, 2],
        progress=False,
    )
    assert [row["seed"] for row in rows] == [0, 1, 2]
    summary = summarize_runs(rows)
    assert summary["n_runs"] == 3
    assert summary["nrmse_x"] == pytest.approx(np.mean([row["nrmse_x"] for row in rows]))
    assert summary["rmse_std_y"] == pytest.approx(np.std([row["rmse_y"] for row in rows], ddof=1))
    assert np.isnan(summary["ucb_coverage_x"])


def test_registry():
    assert "centroid" in tracker_ids()
    assert make_tracker("centroid", gate_radius=12.0).gate_radius == 12.0
    register_tracker(
        "centroid-wide", entry_point="baselines.centroid:GatedCentroidTracker", gate_radius=80.0
    )
    assert make_tracker("centroid-wide").gate_radius == 80.0
    with pytest.raises(ValueError, match=r"tracker must be one of \[.*'centroid'"):
        make_tracker("kalman")
    with pytest.raises(ValueError, match="entry_point"):
        register_tracker("bad", entry_point="baselines.centroid")


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"gate_radius": 0.0}, "gate_radius"),
        ({"alpha": 1.5}, "alpha"),
        ({"beta": -0.1}, "beta"),
        ({"reacquire_after": 0}, "reacquire_after"),
    ],
)
def test_reference_tracker_validates_its_arguments(kwargs, name):
    with pytest.raises(ValueError, match=name):
        GatedCentroidTracker(**kwargs)


def test_weighted_centroid_by_hand():
    points = np.array([[0.0, 0.0], [2.0, 0.0], [100.0, 100.0]])
    centroid, spread, count = weighted_centroid(points, np.array([1.0, 0.0]), gate_radius=10.0)
    # the two gated points are equidistant from the centre: equal weights
    np.testing.assert_allclose(centroid, [1.0, 0.0])
    assert spread == pytest.approx(0.5) and count == pytest.approx(2.0)
    assert weighted_centroid(points, np.array([50.0, 50.0]), gate_radius=10.0) is None


def test_coasting_through_empty_steps_grows_the_variance():
    env = gym.make("DGPTrack-v0")
    observation, info = env.reset(seed=0)
    tracker = make_tracker("centroid")
    tracker.reset(info["problem_spec"])
    first = tracker.update(observation)
    empty = {key: np.zeros_like(value) for key, value in observation.items()}
    variances = [tracker.update(empty).var for _ in range(30)]
    assert np.all(np.diff(np.array(variances), axis=0) > 0)
    assert np.all(np.isfinite(variances)) and np.all(variances[0] > first.var)


def test_installed_packages_register_trackers_through_entry_points(monkeypatch):
    import importlib.metadata

    from dgpt_gym import registry

    point = importlib.metadata.EntryPoint(
        name="their-centroid",
        value="baselines.centroid:GatedCentroidTracker",
        group=registry.ENTRY_POINT_GROUP,
    )
    monkeypatch.setattr(
        registry,
        "entry_points",
        lambda group=None: [point] if group == registry.ENTRY_POINT_GROUP else [],
    )
    monkeypatch.setattr(registry, "_tables_loaded", False)
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))  # leave no trace
    assert "their-centroid" in tracker_ids()
    assert isinstance(make_tracker("their-centroid"), GatedCentroidTracker)


def test_a_class_path_is_a_tracker_id(monkeypatch):
    from dgpt_gym import registry

    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))  # leave no trace
    tracker = make_tracker("baselines.centroid:GatedCentroidTracker")
    assert isinstance(tracker, GatedCentroidTracker)
    assert "baselines.centroid:GatedCentroidTracker" in tracker_ids()
    with pytest.raises(ValueError, match="names no importable class"):
        make_tracker("baselines.centroid:NoSuchTracker")
