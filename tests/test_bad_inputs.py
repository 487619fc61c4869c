"""Every invalid input a user can give gets one clear error naming the argument: env
arguments, actions, reset options, tracker arguments and both command lines. Nothing is
silently accepted and nothing ends in a raw traceback (the commands return 2 with a one-line
``error:`` message)."""

import math

import gymnasium as gym
import numpy as np
import pytest
from conftest import problem_spec

from dgpt_gym import make_tracker
from dgpt_gym.benchmark import cli as evaluate_cli

# (keyword arguments of DGPTrack-v0, the name the error must contain)
ENV_ARGUMENTS = [
    ({"scenario": "S7"}, "scenario"),
    ({"scenario": 3}, "scenario"),
    ({"scenario": None}, "scenario"),
    ({"noise_std": -1.0}, "noise_std"),
    ({"noise_std": math.inf}, "noise_std"),
    ({"noise_std": math.nan}, "noise_std"),
    ({"noise_std": "1"}, "noise_std"),
    ({"noise_std": 1 + 2j}, "noise_std"),
    ({"clutter_rate": -1.0}, "clutter_rate"),
    ({"clutter_rate": math.nan}, "clutter_rate"),
    ({"clutter_rate": "five"}, "clutter_rate"),
    ({"detection_rate": 0.0}, "detection_rate"),
    ({"detection_rate": -2.0}, "detection_rate"),
    ({"n_sensors": 0}, "n_sensors"),
    ({"n_sensors": 2.5}, "n_sensors"),
    ({"n_sensors": "250"}, "n_sensors"),
    ({"n_sensors": True}, "n_sensors"),
    ({"area": 0.0}, "area"),
    ({"area": -5.0}, "area"),
    ({"sensing_range": 0.0}, "sensing_range"),
    ({"sensing_range": math.nan}, "sensing_range"),
    ({"dt": 0.0}, "dt"),
    ({"dt": -1.0}, "dt"),
    ({"clutter_sensors": "some"}, "clutter_sensors"),
    ({"clutter_sensors": 1}, "clutter_sensors"),
    ({"trajectory": "circle"}, "trajectory"),
    ({"trajectory": None}, "trajectory"),
    ({"layout_seed": -1}, "layout_seed"),
    ({"layout_seed": 1.5}, "layout_seed"),
    ({"layout_seed": "a"}, "layout_seed"),
    ({"max_measurements": 0}, "max_measurements"),
    ({"max_measurements": 1.5}, "max_measurements"),
    ({"render_mode": "video"}, "render_mode"),
]


@pytest.mark.parametrize("kwargs, name", ENV_ARGUMENTS, ids=lambda v: repr(v)[:40])
def test_bad_env_arguments(kwargs, name):
    with pytest.raises(ValueError, match=name):
        gym.make("DGPTrack-v0", **kwargs)


ACTIONS = [
    "1,2",
    np.array(["a", "b"]),
    np.array([1 + 2j, 3.0]),
    True,
    np.array([True, False]),
    [1.0, 2.0, 3.0],
    None,
    np.array([math.nan, 1.0]),
    np.array([math.inf, 1.0]),
    {"x": 1.0, "y": 2.0},
    np.zeros((2, 2)),
]


@pytest.fixture(scope="module")
def started_env():
    env = gym.make("DGPTrack-v0")
    env.reset(seed=0)
    return env


@pytest.mark.parametrize("action", ACTIONS, ids=lambda v: repr(v)[:30])
def test_bad_actions(started_env, action):
    with pytest.raises(ValueError, match="action"):
        started_env.step(action)


RESET_OPTIONS = [
    ({"foo": 1}, "options"),
    ([1, 2], "options"),
    ("layout_seed=3", "options"),
    ({"layout_seed": -1}, "layout_seed"),
    ({"layout_seed": "a"}, "layout_seed"),
    ({"layout_seed": 1.5}, "layout_seed"),
    ({"layout_seed": 3, "scenario": "S2"}, "options"),
]


@pytest.mark.parametrize("options, name", RESET_OPTIONS, ids=lambda v: repr(v)[:40])
def test_bad_reset_options(options, name):
    env = gym.make("DGPTrack-v0")
    with pytest.raises(ValueError, match=name):
        env.reset(seed=0, options=options)


# (tracker id, keyword arguments, the name the error must contain)
TRACKER_ARGUMENTS = [
    ("dgpt-rbcm-trend", {"window": 1}, "window"),
    ("dgpt-rbcm-trend", {"window": 2.5}, "window"),
    ("dgpt-rbcm-trend", {"window": True}, "window"),
    ("dgpt-rbcm-trend", {"window": "3"}, "window"),
    ("dgpt-rbcm-trend", {"aggregation": "mean"}, "aggregation"),
    ("dgpt-rbcm-trend", {"inputs": "xyz"}, "inputs"),
    ("dgpt-rbcm-trend", {"gating": "false"}, "gating"),
    ("dgpt-rbcm-trend", {"gating": 0}, "gating"),
    ("dgpt-rbcm-trend", {"anytime_ucb": "no"}, "anytime_ucb"),
    ("dgpt-rbcm-trend", {"delta": 0.0}, "delta"),
    ("dgpt-rbcm-trend", {"delta": 1.0}, "delta"),
    ("dgpt-rbcm-trend", {"delta": math.nan}, "delta"),
    ("dgpt-rbcm-trend", {"mean": "quadratic"}, "mean"),
    ("dgpt-rbcm-trend", {"kernel": "matern"}, "kernel"),
    ("dgpt-rbcm-stgp-trend", {"kernel": "ncv"}, "kernel"),
    ("dgpt-rbcm-trend", {"hyperparameter_bounds": "tight"}, "hyperparameter_bounds"),
    ("dgpt-rbcm-trend", {"max_iterations": -1}, "max_iterations"),
    ("dgpt-rbcm-trend", {"gate_threshold": 0.0}, "gate_threshold"),
    ("dgpt-rbcm-trend", {"gate_threshold": -3.0}, "gate_threshold"),
    ("dgpt-rbcm-trend", {"admission_probability": 0.0}, "admission_probability"),
    ("gp-trend", {"admission_probability": 1.5}, "admission_probability"),
    ("dgpt-rbcm", {"start_gate": -1.0}, "start_gate"),
    ("dgpt-rbcm", {"start_gate": float("nan")}, "start_gate"),
    ("gp-trend", {"window": 0}, "window"),
    ("hybrid-trend", {"variant": "x"}, "variant"),
    ("hybrid-trend", {"reacquire": "y"}, "reacquire"),
    ("hybrid-trend", {"delta": 2.0}, "delta"),
    ("hybrid-trend", {"prune_tolerance": -1.0}, "prune_tolerance"),
    ("hybrid", {"prior_model": "gaussian"}, "prior_model"),
    ("hybrid-trend", {"prior_model": "mixture"}, "prior_model"),
    ("hybrid-paper", {"prior_model": "mixture"}, "prior_model"),
    ("cpf", {"n_particles": 0}, "n_particles"),
    ("cpf", {"n_particles": 1.5}, "n_particles"),
    ("cpf", {"acceleration_std": -1.0}, "acceleration_std"),
    ("cpf", {"resample_threshold": 2.0}, "resample_threshold"),
    ("cpf", {"mode_transition": [[0.5, 0.6], [0.5, 0.5]]}, "mode_transition"),
    ("pda", {"association": "x"}, "association"),
    ("pda", {"noise_diff_coeff": -1.0}, "noise_diff_coeff"),
    ("pda", {"detection_probability": 1.5}, "detection_probability"),
    ("pda", {"gate_probability": 0.0}, "gate_probability"),
    ("imm-pda", {"mode_stay_probability": 1.5}, "mode_stay_probability"),
    ("imm-pda", {"association": "nearest"}, "association"),
    ("clairvoyant", {"singer": "x"}, "singer"),
    ("centroid", {"gate_radius": -1.0}, "gate_radius"),
    ("centroid", {"alpha": 2.0}, "alpha"),
    ("centroid", {"reacquire_after": 0}, "reacquire_after"),
    ("kalman", {}, "tracker"),
    ("no_such_module:Tracker", {}, "tracker"),
    (3, {}, "tracker"),
]


@pytest.mark.parametrize("tracker, kwargs, name", TRACKER_ARGUMENTS, ids=lambda v: repr(v)[:40])
def test_bad_tracker_arguments(tracker, kwargs, name):
    with pytest.raises(ValueError, match=name):
        make_tracker(tracker, **kwargs)


@pytest.mark.parametrize(
    "changes, name",
    [
        ({"noise_std": -0.5}, "noise_std"),
        ({"sensing_range": -1.0}, "sensing_range"),
        ({"clutter_rate": -1.0}, "clutter_rate"),
        ({"clutter_sensors": "few"}, "clutter_sensors"),
        ({"n_steps": 0}, "n_steps"),
        ({"sensor_positions": np.zeros((3, 3))}, "sensor_positions"),
    ],
    ids=lambda v: repr(v)[:30],
)
def test_a_hand_built_problem_spec_is_checked(changes, name):
    # trackers divide by noise_std and friends: a spec that would crash one is refused
    with pytest.raises(ValueError, match=name):
        problem_spec(**{"sensor_positions": np.zeros((3, 2)), **changes})


EVALUATE_ARGUMENTS = [
    (["--trackers", "kalman"], "tracker"),
    (["--trackers", "my_module_that_is_not_there:Tracker"], "names no importable class"),
    (["--scenarios", "S7"], "scenario"),
    (["--noise-std", "inf"], "noise_std"),
    (["--noise-std", "-1"], "noise_std"),
    (["--noise-std", "x"], "--noise-std"),
    (["--clutter-rates", "-1"], "clutter_rate"),
    (["--runs", "0"], "runs"),
    (["--runs", "x"], "--runs"),
    (["--seed", "-1"], "first_seed"),
    (["--workers", "0"], "workers"),
    (["--batch-size", "0"], "batch_size"),
    (["--inputs", "xyz"], "--inputs"),
    (["--scheduler", "nonsense:://x"], "scheduler"),
    (["--no-such-option"], "unrecognized arguments"),
    (["--verify", "0"], "count"),
    (["--verify", "1"], "no finished run of this sweep"),
]


@pytest.mark.parametrize("argv, name", EVALUATE_ARGUMENTS, ids=lambda v: repr(v)[:40])
def test_bad_evaluate_arguments(argv, name, tmp_path, capsys):
    base = ["--scenarios", "S1", "--runs", "1", "--no-progress", "--out", str(tmp_path)]
    assert _exit_code(evaluate_cli.main, [*base, *argv]) == 2
    error = capsys.readouterr().err
    assert name in error and "error:" in error and "Traceback" not in error
    if name in evaluate_cli.OPTION_OF_ARGUMENT:  # the option the user typed is named too
        assert f"(option {evaluate_cli.OPTION_OF_ARGUMENT[name]})" in error
        assert evaluate_cli.OPTION_OF_ARGUMENT[name] in " ".join(argv)


def test_evaluate_explains_a_file_and_a_corrupt_store_given_as_out(tmp_path, capsys):
    a_file = tmp_path / "file"
    a_file.write_text("not a folder")
    corrupt = tmp_path / "corrupt"
    corrupt.mkdir()
    (corrupt / "results.sqlite").write_text("this is not an SQLite database" * 100)
    for out, name in ((a_file, "out must be a folder"), (corrupt, "results.sqlite")):
        argv = ["--trackers", "centroid", "--scenarios", "S1", "--runs", "1", "--out", str(out)]
        assert _exit_code(evaluate_cli.main, [*argv, "--no-progress"]) == 2
        assert name in capsys.readouterr().err


def test_an_unreachable_scheduler_fails_within_seconds(tmp_path, capsys):
    # nothing listens on port 1: the client gives up after SCHEDULER_TIMEOUT_S (5 s)
    pytest.importorskip("distributed", reason="the cluster extra is installed by make test")
    argv = ["--trackers", "centroid", "--scenarios", "S1", "--runs", "1", "--no-progress"]
    argv += ["--out", str(tmp_path), "--scheduler", "tcp://127.0.0.1:1"]
    assert _exit_code(evaluate_cli.main, argv) == 2
    assert "scheduler 'tcp://127.0.0.1:1' cannot be reached" in capsys.readouterr().err


def _exit_code(main, argv) -> int:
    try:
        return main(argv)
    except SystemExit as exit:  # argparse's own errors
        return exit.code


TRAIN_RL_ARGUMENTS = [
    (["--env", "kalman"], "env"),
    (["--algo", "sac"], "--algo"),
    (["--timesteps", "0"], "timesteps"),
    (["--timesteps", "x"], "--timesteps"),
    (["--n-envs", "0"], "n_envs"),
    (["--seed", "-1"], "seed"),
    (["--eval-episodes", "1"], "eval-episodes"),
    (["--env-kwargs", "scenario"], "KEY=VALUE"),
    (["--env-kwargs", "scenario=S7"], "scenario"),
    (["--env-kwargs", "clutter_rate=-1"], "clutter_rate"),
    (["--algo-kwargs", "foo=1"], "foo"),
    (["--algo-kwargs", "learning_rate=abc"], "learning_rate"),
    (["--algo-kwargs", "gamma=[1]"], "gamma"),
    (["--algo-kwargs", "normalize_advantage=1"], "normalize_advantage"),
    (["--env", "gating", "--algo", "dqn"], "Discrete"),
]


@pytest.mark.parametrize("argv, name", TRAIN_RL_ARGUMENTS, ids=lambda v: repr(v)[:40])
def test_bad_train_rl_arguments(argv, name, tmp_path, capsys):
    pytest.importorskip("stable_baselines3", reason="the rl extra is installed by make test")
    from agents.rl import cli as train_rl_cli

    base = ["--timesteps", "8", "--n-envs", "1", "--no-progress", "--out", str(tmp_path)]
    assert _exit_code(train_rl_cli.main, [*base, *argv]) == 2
    error = capsys.readouterr().err
    assert name in error and "error:" in error and "Traceback" not in error
    assert list(tmp_path.iterdir()) == []  # rejected before anything is written
