"""The command-line scripts, run as a user runs them."""

import csv
import importlib.util
import json
import os
import re
import sqlite3
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from scipy import stats

import dgpt_gym
from agents.rl.evaluation import (
    agents_against,
    iqm_interval,
    paired_iqm_difference,
    policy_cells,
)
from agents.rl.heuristics import HEURISTIC_GRIDS
from dgpt_gym import make_tracker
from dgpt_gym.benchmark.cli import with_inputs
from dgpt_gym.benchmark.episodes import run_episode

ROOT = Path(__file__).resolve().parents[1]


def load_script(name):
    """The module of ``scripts/<name>.py``, imported without running its command."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run_script(name, *args, env=None, cwd=None):
    return subprocess.run(
        [sys.executable, str(ROOT / "scripts" / name), *args],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
        cwd=cwd,
    )


def test_evaluate_prints_the_nrmse_table(tmp_path):
    result = run_script(
        "evaluate.py",
        "--out",
        str(tmp_path),
        "--trackers",
        "centroid",
        "--scenarios",
        "S1",
        "S4",
        "--clutter-rates",
        "5",
        "--runs",
        "2",
        "--no-progress",
    )
    assert result.returncode == 0, result.stderr
    # | tracker | scenario | noise | clutter | NRMSE X ± ci | paper X | NRMSE Y ± ci | paper Y |
    # RMSE ± ci | x floor | ANEES | 3 sigma | loss | runs |
    rows = re.findall(
        r"^\| centroid \| (S\d) \| 1 \| 5 \| ([\d.]+) ± [\d.]+ \| - \| ([\d.]+) ± [\d.]+ \| - \|"
        r" [\d.]+ ± [\d.]+ \| - \| [\d.]+ \| [\d.]+ / [\d.]+ \| \d+ \| 2 \|$",
        result.stdout,
        flags=re.M,
    )
    assert [row[0] for row in rows] == ["S1", "S4"], result.stdout
    assert all(0 < float(value) < 100 for row in rows for value in row[1:])
    assert "0 failed runs" in result.stdout and (tmp_path / "results.md").exists()


def test_evaluate_runs_off_the_reference_paths_and_layout(tmp_path):
    """--trajectory random --layout per_episode: the stored runs are the episodes of a random
    path with seed s in layout s; --paper refuses both, naming them."""
    args = ["--out", str(tmp_path), "--trackers", "centroid", "--scenarios", "S2"]
    args += ["--clutter-rates", "1", "--runs", "2", "--no-progress"]
    result = run_script("evaluate.py", *args, "--trajectory", "random", "--layout", "per_episode")
    assert result.returncode == 0, result.stderr
    assert re.search(r"^\| centroid \| S2 \| 1 \| 1 \| [\d.]+ ± ", result.stdout, re.M)
    with sqlite3.connect(tmp_path / "results.sqlite") as connection:
        stored = connection.execute("SELECT seed, env_kwargs, metrics FROM runs").fetchall()
    for seed, env_kwargs, metrics in sorted(stored):
        env_kwargs = json.loads(env_kwargs)
        assert (env_kwargs["trajectory"], env_kwargs["layout_seed"]) == ("random", seed)
        env = gym.make("DGPTrack-v0", **env_kwargs)
        direct = run_episode(env, make_tracker("centroid"), seed).metrics()
        assert json.loads(metrics)["rmse_2d"] == direct["rmse_2d"]
    assert [seed for seed, _, _ in sorted(stored)] == [0, 1]
    refused = run_script(
        "evaluate.py", "--paper", "--layout", "per_episode", "--out", str(tmp_path)
    )
    assert refused.returncode == 2 and "--trajectory and --layout apply" in refused.stderr


def test_evaluate_help_documents_every_option():
    result = run_script("evaluate.py", "--help")
    assert result.returncode == 0
    for option in (
        "--paper",
        "--scheduler",
        "--out",
        "--runs",
        "--inputs",
        "--workers",
        "--seed",
        "--trajectory",
        "--layout",
    ):
        assert option in result.stdout


def test_evaluate_inputs_expand_gp_trackers_and_keep_the_others():
    assert with_inputs(["gp-trend", "imm-pda", "dgpt-rbcm-stgp-trend"], ["tgp", "stgp"]) == [
        "gp-trend",
        "gp-stgp-trend",
        "imm-pda",
        "dgpt-rbcm-trend",
        "dgpt-rbcm-stgp-trend",
    ]
    assert with_inputs(["cpf", "gp-trend"], ["stgp"]) == ["cpf", "gp-stgp-trend"]
    # the state-space trackers have temporal inputs only: kept with tgp, refused for stgp alone
    assert with_inputs(["gp", "dgpt-rbcm"], ["tgp", "stgp"]) == ["gp", "dgpt-rbcm"]
    with pytest.raises(ValueError, match="temporal inputs only.*dgpt-rbcm-stgp-trend"):
        with_inputs(["dgpt-rbcm"], ["stgp"])
    assert with_inputs(["hybrid", "imm-pda"], ["stgp"]) == ["hybrid", "imm-pda"]


def test_evaluate_rejects_unknown_names_with_the_valid_ones():
    result = run_script("evaluate.py", "--trackers", "kalman")
    assert result.returncode == 2
    assert "tracker must be one of" in result.stderr and "'centroid'" in result.stderr
    result = run_script("evaluate.py", "--scenarios", "S7")
    assert result.returncode == 2 and "'S1', 'S2', 'S3', 'S4'" in result.stderr


def test_bench_prints_its_figures():
    # the quick sections only: sklearn and training-time take minutes (and write docs/)
    result = run_script(
        "bench.py",
        "--only",
        "env",
        "dgpt-step",
        "--steps",
        "300",
        "--repeats",
        "1",
        "--episodes",
        "1",
    )
    assert result.returncode == 0, result.stderr
    ratio = re.search(r"ratio DGPTrack / CartPole \(goal <= 3\): ([\d.]+)", result.stdout)
    assert ratio and float(ratio.group(1)) > 0
    for label in (r"dgpt-rbcm", r"dgpt-rbcm-trend \(window 10\)"):
        step = re.search(label + r" step, median \(ms, goal <= 1\): ([\d.]+)", result.stdout)
        assert step and float(step.group(1)) > 0


def test_bench_clutter_all_prints_a_median_per_cell():
    from dgpt_gym.benchmark.speed import bench_clutter_all

    rows = bench_clutter_all(1, ("dgpt-rbcm",), ("S1",))
    assert rows[0] == "| tracker | S1 fixed | S1 random |"
    cells = re.fullmatch(r"\| `dgpt-rbcm` \| ([\d.]+) \| ([\d.]+) \|", rows[2])
    assert cells and all(float(value) > 0 for value in cells.groups()), rows


def test_train_rl_trains_saves_and_compares(tmp_path):
    result = run_script(
        "train_rl.py",
        *("--env", "sensors", "--algo", "a2c", "--timesteps", "64", "--n-envs", "2"),
        *("--workers", "2", "--env-kwargs", "n_candidates=2", "max_episode_steps=15"),
        *("--eval-episodes", "2", "--out", str(tmp_path), "--no-progress"),
    )
    assert result.returncode == 0, result.stderr
    for name in ("model.zip", "config.json", "comparison.md", "learning_curve.png"):
        assert (tmp_path / name).stat().st_size > 0, name
    speed = re.search(r"^trained 64 steps in [\d.]+ s: (\d+) steps/s, ", result.stdout, re.M)
    assert speed and int(speed.group(1)) > 0, result.stdout
    rows = re.findall(r"^\| (trained agent|nearest 1|nearest 2|random) \| ", result.stdout, re.M)
    assert sorted(rows) == ["nearest 1", "nearest 2", "random", "trained agent"]


def test_train_rl_rejects_bad_choices(tmp_path):
    """Each bad choice exits with code 2 and a message that names it, and writes nothing
    (run from an empty folder, where the default output would go)."""
    result = run_script("train_rl.py", "--env", "kalman", cwd=tmp_path)
    assert result.returncode == 2 and "window" in result.stderr
    result = run_script(
        "train_rl.py", "--env", "gating", "--algo", "dqn", "--timesteps", "8", cwd=tmp_path
    )
    assert result.returncode == 2 and "Discrete" in result.stderr
    result = run_script(
        "train_rl.py", "--n-envs", "2", "--workers", "3", "--timesteps", "8", cwd=tmp_path
    )
    assert result.returncode == 2 and "workers must be at most n_envs = 2" in result.stderr
    assert list(tmp_path.iterdir()) == []


USER_TRACKER = """
from baselines.centroid import GatedCentroidTracker


class MyTracker(GatedCentroidTracker):
    name = "my-tracker"
"""


def test_evaluate_runs_a_user_tracker_named_by_its_class(tmp_path):
    (tmp_path / "my_trackers.py").write_text(USER_TRACKER)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])}
    args = ("--out", str(tmp_path / "out"), "--scenarios", "S1", "--clutter-rates", "1")
    result = run_script(
        "evaluate.py",
        "--trackers",
        "my_trackers:MyTracker",
        *args,
        "--runs",
        "2",
        "--no-progress",
        env=env,
    )
    assert result.returncode == 0, result.stderr
    assert re.search(r"^\| my_trackers:MyTracker \| S1 \| 1 \| 1 \| [\d.]+ ± ", result.stdout, re.M)
    missing = run_script("evaluate.py", "--trackers", "my_trackers:Nothing", *args, env=env)
    assert missing.returncode == 2 and "names no importable class" in missing.stderr


def test_evaluate_explains_a_bad_output_folder(tmp_path):
    args = ("--trackers", "centroid", "--scenarios", "S1", "--runs", "1", "--no-progress")
    a_file = tmp_path / "file"
    a_file.write_text("not a folder")
    result = run_script("evaluate.py", "--out", str(a_file), *args)
    assert result.returncode == 2 and "out must be a folder" in result.stderr
    assert "Traceback" not in result.stderr
    corrupt = tmp_path / "corrupt"
    corrupt.mkdir()
    (corrupt / "results.sqlite").write_text("this is not an SQLite database" * 100)
    result = run_script("evaluate.py", "--out", str(corrupt), *args)
    assert result.returncode == 2 and "not a usable dgpt-gym results database" in result.stderr
    assert "results.sqlite" in result.stderr and "Traceback" not in result.stderr


def test_sensors_baselines_and_agent_actions_run_on_a_few_seeds(tmp_path):
    """The scripts behind docs/rl_sensors_v2.md and the agents' action table, on 2 seeds
    (the documented runs use 100 and 20): the table has every policy and the pooled agents,
    the figure is written, and the agents' actions are tabulated by situation."""
    model = str(ROOT / "models" / "sensors-v2-ppo-seed0")
    result = run_script(
        "sensors_baselines.py",
        "--env",
        "DGPTrackSensors-v2",
        "--seeds",
        "2",
        "--training-seeds",
        "1",
        "--workers",
        "1",
        "--out",
        str(tmp_path),
        "--cache",
        str(tmp_path / "cache"),
        "--models",
        model,
    )
    assert result.returncode == 0, result.stderr
    table = (tmp_path / "rl_sensors_v2.md").read_text()
    for row in (
        "| nearest 0 |",
        "| all |",
        "| random |",
        "| uncertainty radius",
        "| silence search",
        "| **1 agents together** |",
        "| agent sensors-v2-ppo-seed0 |",
    ):
        assert row in table
    assert (tmp_path / "figures" / "rl_sensors_v2_pareto.png").stat().st_size > 10_000
    result = run_script("agent_actions.py", model, "--seeds", "1")
    assert result.returncode == 0, result.stderr
    assert "| after a silent step |" in result.stdout and "| sigma < 10 m |" in result.stdout
    result = run_script(
        "agent_actions.py",
        str(ROOT / "models" / "window-ppo-seed0"),
        "--seeds",
        "1",
        "--clairvoyant",
        "fixed C=3",
    )
    assert result.returncode == 0, result.stderr
    agent, clairvoyant = result.stdout.split("the greedy clairvoyant policy, seeds 0-0")
    for table in (agent, clairvoyant):
        assert "mean window" in table and "| 3+ experts |" in table


def test_tuning_baselines_runs_on_a_few_seeds_and_refuses_other_tasks_agents(tmp_path):
    """The script behind docs/rl_window_v0.md on 2 evaluation seeds (the documented run uses
    100): every fixed window, the tuned rule, the random policy, the clairvoyant references,
    the agent and the agents together have a row, the best fixed setting is marked, the paired table
    compares the agents with it, and the figure is written. The best fixed window per
    episode with hindsight has, on every seed, the best fixed window's return, so its mean
    is the highest of the fixed rows'. An agent trained on another task is refused, naming
    it."""
    model = str(ROOT / "models" / "window-ppo-seed0")
    common = ["--seeds", "2", "--training-seeds", "1", "--workers", "1", "--out", str(tmp_path)]
    common += ["--cache", str(tmp_path / "cache")]
    result = run_script("tuning_baselines.py", *common, "--clairvoyant", "--models", model)
    assert result.returncode == 0, result.stderr
    table = (tmp_path / "rl_window_v0.md").read_text()
    mean_return = {
        cells[0].strip(): float(cells[2])
        for cells in (line.split("|")[1:] for line in table.splitlines())
        if len(cells) == 7 and cells[0].strip().startswith(("fixed", "clairvoyant"))
    }
    for window in (2, 3, 4, 5, 6, 8, 10, 14, 20):
        assert any(name.startswith(f"fixed C={window}") for name in mean_return)
    hindsight = mean_return.pop("clairvoyant, best fixed per episode (hindsight)")
    greedy = mean_return.pop("clairvoyant, greedy per step (sees the truth)")
    assert hindsight >= max(mean_return.values())
    assert np.isfinite(greedy)
    for row in ("| random |", "| agent window-ppo-seed0 |", "| **1 agents together** |"):
        assert row in table
    assert re.search(
        r"^\| surprise window \(quiet=\d, surprised=\d, .*tuned on training", table, re.M
    )
    training = dict(
        re.match(r"training\s+(.+?)\s+mean return\s+(\S+)", line).groups()
        for line in result.stdout.splitlines()
        if line.startswith("training  fixed")
    )
    best = max(training, key=lambda name: float(training[name]))
    assert len(training) == 9 and f"| {best} (best fixed, training seeds) |" in table
    assert table.count("(best fixed, training seeds)") == 1 and "(default)" in table
    assert "| setting | IQM return: agents - setting [95 % CI] |" in table
    assert (tmp_path / "figures" / "rl_window_v0.png").stat().st_size > 10_000
    refused = run_script(
        "tuning_baselines.py", *common, "--env-kwargs", "scenario=S1", "--models", model
    )
    assert refused.returncode == 2 and "window-ppo-seed0 was trained on" in refused.stderr


def test_the_paired_iqm_difference_pairs_the_seeds():
    """agents.rl.evaluation's paired bootstrap of IQM(agents) - IQM(reference), which the
    RL tables quote: agents that add exactly 5 to the reference's return on every seed
    give 5 with a zero-width interval, whatever the spread over seeds (a bootstrap that
    resampled the two sides independently would give an interval about +-2 wide here);
    with noise of standard deviation 1 per (agent, seed) the interval still covers 5 and
    is far narrower than the seeds' spread of 10."""
    rng = np.random.default_rng(3)
    rule = 10.0 * rng.normal(size=100)
    exact = paired_iqm_difference(np.stack([rule + 5.0] * 5), rule)
    np.testing.assert_allclose(exact, (5.0, 5.0, 5.0), rtol=0, atol=1e-9)
    noisy = paired_iqm_difference(np.stack([rule + 5.0 + rng.normal(size=100)] * 5), rule)
    assert noisy[1] < 5.0 < noisy[2] and noisy[2] - noisy[1] < 1.0


def test_the_table_cells_pair_by_seed_and_by_agent():
    """Hand-computed cells. Agent a returns the reference's return + 1 on every seed and
    agent b + 3: per seed the agents' mean is 2 above it, exactly (t over seeds: +2.0 +-
    0.0); over the two agents the differences are 1 and 3, mean 2, standard error 1,
    t(0.975, 1 dof) = 12.706 (+2.0 +- 12.7). Knobs 4 and 6 against 3: +2.0 +- 0.0. Against
    itself the reference's paired cell is "-". The pooled IQM of a and b (the middle four of
    eight values, 5.75) minus the reference's (3.75) is 2 too; its bootstrap interval is not
    exact, because a resample's trimming mixes the two agents."""
    reference = [10.0, -4.0, 7.0, 0.5]

    def rows(offset, knob):
        return [
            {"return": r + offset, "nrmse": 0.01, "per_step": knob, "seed": seed}
            for seed, r in enumerate(reference)
        ]

    by_name = {"a": rows(1.0, 4.0), "b": rows(3.0, 6.0), "ref": rows(0.0, 3.0)}
    cells = agents_against(by_name, ["a", "b"], ["ref"], "knob")[-1].split(" | ")
    assert cells[0] == "| ref" and cells[1].startswith("+2.0 [")  # IQMs 5.75 and 3.75
    assert cells[2:] == ["+2.0 +- 0.0", "+2.0 +- 12.7", "+2.0 +- 0.0 |"]
    cells = policy_cells(by_name, ["a", "b"], np.array(reference), digits=2, knob_digits=2)
    assert cells.endswith("| 1.00 | 5.00 | +2.00 +- 0.00")
    assert policy_cells(by_name, ["ref"], np.array(reference), is_reference=True).endswith("| -")


def test_the_pooled_iqm_interval_resamples_seeds_not_episodes():
    """The IQM is the mean of the middle half (1..8: 4.5, by hand). Agents whose returns go
    together seed by seed are not independent draws: five agents with the same return on
    every seed carry the information of one, so their pooled interval must be as wide as
    one agent's (resampling each agent's episodes on its own would make it about sqrt(5) =
    2.2 times narrower). Samples of different seeds are refused."""
    np.testing.assert_allclose(iqm_interval(np.arange(1.0, 9.0))[0], 4.5, rtol=0, atol=1e-12)
    returns = np.random.default_rng(5).normal(size=100)
    _, low, high = iqm_interval(returns)
    iqm, pooled_low, pooled_high = iqm_interval(*[returns] * 5)
    assert iqm == pytest.approx(stats.trim_mean(returns, 0.25), abs=1e-12)
    assert 0.8 < (pooled_high - pooled_low) / (high - low) < 1.25
    with pytest.raises(ValueError, match="same seeds"):
        iqm_interval(returns, returns[:50])


def test_model_study_pairs_runs_by_cell_and_seed():
    """With the same seeds in every cell, the mean of the paired differences equals the
    difference of the candidates' mean RMSE (summary line, rounded to 0.01 m); the UCB
    split covers every step that has a UCB; a reference that is not run is refused."""
    common = ["--seeds", "2", "--trajectories", "fixed", "--clutter-rates", "1"]
    result = run_script(
        "model_study.py",
        *common,
        "--candidates",
        "ss-bcm-20",
        "ss-plain-bcm-50",
        "--paired-against",
        "ss-bcm-20",
    )
    assert result.returncode == 0, result.stderr
    summary = {
        line.split()[0]: float(line.split()[1])
        for line in result.stdout.splitlines()
        if re.match(r"ss-\S+\s+[\d.]+\s+nan", line)
    }
    paired = re.search(r"ss-plain-bcm-50\s+fixed\s+8\s+([+-][\d.]+) \+-", result.stdout)
    assert paired, result.stdout
    expected = summary["ss-plain-bcm-50"] - summary["ss-bcm-20"]
    assert abs(float(paired.group(1)) - expected) <= 0.011
    split = run_script("model_study.py", *common, "--ucb-by-step", "--candidates", "ss-bcm-20")
    assert split.returncode == 0, split.stderr
    shares = [float(line.split()[2]) for line in split.stdout.splitlines()[1:]]
    assert len(shares) == 2 and 95.0 <= sum(shares) <= 100.0
    refused = run_script(
        "model_study.py", *common, "--candidates", "ss-bcm-20", "--paired-against", "se-trend"
    )
    assert refused.returncode == 2 and "--paired-against" in refused.stderr


def test_sensors_training_table_runs_every_policy_on_training_seeds_only(tmp_path):
    """--training-table: one CSV row per policy and training seed (1000 here; no evaluation
    seed), every fixed count wakes exactly its n sensors per step, and every rule setting
    of agents/rl/heuristics.py has its row."""
    result = run_script(
        "sensors_baselines.py",
        "--training-table",
        "--training-seeds",
        "1",
        "--workers",
        "1",
        "--out",
        str(tmp_path),
        "--no-cache",
    )
    assert result.returncode == 0, result.stderr
    rows = list(csv.DictReader((tmp_path / "training_returns_v1.csv").open()))
    assert {row["seed"] for row in rows} == {"1000"}
    by_policy = {row["policy"]: row for row in rows}
    assert len(by_policy) == len(rows)
    nearest = {name: row for name, row in by_policy.items() if name.startswith("nearest ")}
    assert len(nearest) >= 2 and "random" in by_policy
    for name, row in nearest.items():
        assert float(row["per_step"]) == int(name.split()[1])
    n_rules = sum(len(grid) for grid in HEURISTIC_GRIDS.values())
    rules = [name for name in by_policy if "(" in name]
    assert len(rules) == n_rules
    assert all(np.isfinite(float(row["return"])) for row in rows)


def test_all_clutter_floor_prints_the_floor_beside_the_tracker_in_both_modes():
    """One episode, a short horizon: the ratio columns are the printed RMSEs' ratios, and the
    floor, which knows the path's shape, is below the tracker with clutter at every
    sensor on S3's reference path, where it settles at step 0."""
    result = run_script(
        "all_clutter_floor.py",
        *("--first-seed", "1000", "--seeds", "1", "--scenarios", "S3"),
        *("--trajectories", "fixed", "--horizon", "5", "--draws", "3000", "--no-progress"),
    )
    assert result.returncode == 0, result.stderr
    row = next(line for line in result.stdout.splitlines() if line.startswith("S3 fixed"))
    fields = row.split()[2:]
    assert fields[3] == "-"  # settled at step 0: no ambiguous step, no least ESS
    floor, all_clutter, detecting, ratio, floor_ratio = (float(fields[i]) for i in (0, 4, 5, 6, 7))
    assert abs(ratio - all_clutter / detecting) <= 0.01 + 0.005 * ratio
    assert abs(floor_ratio - floor / detecting) <= 0.01 + 0.005 * floor_ratio
    assert floor < all_clutter
    refused = run_script("all_clutter_floor.py", "--draws", "2")
    assert refused.returncode == 2 and "--draws" in refused.stderr


def test_fingerprint_tells_apart_numbers_one_ulp_apart_and_repeats_itself():
    """scripts/fingerprint.py's digests: an episode whose one estimate moves by one unit in
    the last place gets another digest (the script exists to show that a speed change
    leaves every bit alone), the same episode the same one; a batched sensor environment
    under the same seeds gives the same digest twice."""
    import gymnasium as gym

    from dgpt_gym.benchmark.episodes import run_episode
    from dgpt_gym.registry import make_tracker

    module = load_script("fingerprint")
    env = gym.make("DGPTrack-v0", scenario="S1", clutter_rate=1.0)
    result = run_episode(env, make_tracker("dgpt-rbcm"), 0)
    again = run_episode(env, make_tracker("dgpt-rbcm"), 0)
    assert module.episode_digest(result) == module.episode_digest(again)
    result.mean[7, 1] = np.nextafter(result.mean[7, 1], np.inf)
    assert module.episode_digest(result) != module.episode_digest(again)
    assert module.vector_env_digest("DGPTrackSensors-v2", 3) == module.vector_env_digest(
        "DGPTrackSensors-v2", 3
    )


def test_fingerprint_compare_lists_the_lines_that_moved(tmp_path):
    """``--compare``: the labels (which hold spaces) whose digest changed or that the old
    output lacks, in the new output's order; a missing file is refused by name."""
    module = load_script("fingerprint")
    before = "S1 clutter 1 dgpt-rbcm seed 0 aaaa\nDGPTrackSensors-v2 bbbb\nALL cccc\n"
    after = "S1 clutter 1 dgpt-rbcm seed 0 aaab\nDGPTrackSensors-v2 bbbb\nnew line dddd\nALL cccd"
    assert module.moved_lines(before, after) == [
        "S1 clutter 1 dgpt-rbcm seed 0",
        "new line",
        "ALL",
    ]
    assert module.moved_lines(before, before) == []
    refused = run_script("fingerprint.py", "--compare", str(tmp_path / "missing.txt"))
    assert refused.returncode == 2 and "--compare: no such file" in refused.stderr


def test_compare_cells_prints_a_row_per_tracker_and_rejects_a_missing_file(tmp_path):
    header = "tracker,scenario,noise_std,clutter_rate,rmse_2d,step_time_ms\n"
    (tmp_path / "old.csv").write_text(header + "gp,S1,1.0,1.0,8.0,0.5\npda,S1,1.0,1.0,9.0,0.2\n")
    (tmp_path / "new.csv").write_text(header + "gp,S1,1.0,1.0,8.0,0.9\npda,S1,1.0,1.0,9.9,0.2\n")
    module = load_script("compare_cells")
    result = run_script("compare_cells.py", str(tmp_path / "old.csv"), str(tmp_path / "new.csv"))
    assert result.returncode == 0, result.stderr
    assert "| `gp` | 1 | 1 of 1 | 0 | - | 0 / 0 |" in result.stdout
    assert "| `pda` | 1 | 0 of 1 | 0.1 | S1, 1.0, 1.0, rmse_2d | 0 / 0 |" in result.stdout
    with pytest.raises(SystemExit) as exit_info:
        module.main([str(tmp_path / "missing.csv"), str(tmp_path / "new.csv")])
    assert exit_info.value.code == 2


def test_calibration_misses_tallies_by_hand():
    """scripts/calibration_misses.py's table on four hand-made steps: the share of axes
    outside 3 sigma and the median and mean of z_x^2 + z_y^2 per group."""
    module = load_script("calibration_misses")
    # (z_x, z_y, steps since a gap, target points, turning)
    steps = np.array(
        [
            [4.0, 0.0, 0, 1, 0],  # one axis outside: NEES 16
            [3.0, 1.0, 0, 2, 1],  # on the bound, inside: NEES 10
            [0.0, 3.5, 12, 1, 1],  # one axis outside: NEES 12.25
            [2.5, 0.5, 3, 3, 0],  # inside: NEES 6.5
        ]
    )
    table = {label: rest for label, *rest in module.miss_table(steps)}
    assert table["all detected steps"] == [4, 2 / 8, 11.125, 44.75 / 4]
    assert table["0 steps since a gap"] == [2, 1 / 4, 13.0, 13.0]
    assert table["2-4 steps since a gap"] == [1, 0.0, 6.5, 6.5]
    assert table["10+ steps since a gap"] == [1, 0.5, 12.25, 12.25]
    assert table["1 target point"] == [2, 2 / 4, 14.125, 14.125]
    assert table["2+ target points"] == [2, 0.0, 8.25, 8.25]
    assert table["turning"] == [2, 1 / 4, 11.125, 11.125]
    assert table["1 step since a gap"][0] == 0 and np.isnan(table["1 step since a gap"][1])


def test_clairvoyant_imitation_records_advantages_and_acts_on_them(tmp_path):
    """scripts/clairvoyant_imitation.py on a few seeds: each step's record holds every fixed
    window's one-step reward minus the best fixed window's (so that window's own column is
    zero and the best is at least zero), and the learned policy takes the setting with the
    highest predicted advantage, the fallback where none is above zero (a tree fitted to a
    planted rule)."""
    import json

    import gymnasium as gym
    from sklearn.tree import DecisionTreeRegressor

    from agents.rl.cli import TUNING_TASK_KWARGS, parse_kwargs
    from agents.rl.tuning_envs import DEFAULT_WINDOWS

    cache = tmp_path / "cache"
    args = ["--fit-seeds", "1", "--select-seeds", "1", "--seeds", "2", "--workers", "1"]
    args += ["--training-seeds", "1"]
    result = run_script(
        "clairvoyant_imitation.py", *args, "--cache", str(cache), "--out", str(tmp_path)
    )
    assert result.returncode == 0, result.stderr
    report = (tmp_path / "rl_imitation_window_v0.md").read_text()
    assert re.search(r"^- evaluation seeds 0-1, min leaf \d+: .* paired [+-]", report, re.M)
    best = re.search(
        r"best fixed setting on training seeds 1000-1000: fixed C=(\d+)", result.stdout
    )
    best_column = DEFAULT_WINDOWS.index(int(best.group(1)))
    (records_file,) = cache.glob("records-*.json")
    records = json.loads(records_file.read_text())
    advantages = np.array(records["advantages"])
    assert advantages.shape == (len(records["observations"]), 9)
    # an independent replay: reset with the fit seed, take the best fixed window for 20
    # steps, then each window: the reward differences are step 21's recorded advantages
    env = gym.make("DGPTrackWindow-v0", **parse_kwargs(TUNING_TASK_KWARGS))
    replayed = []
    for action in range(9):
        env.reset(seed=1000)
        for _ in range(20):
            env.step(best_column)
        replayed.append(env.step(action)[1])
    assert np.ptp(replayed) > 0  # a step where the window matters
    np.testing.assert_allclose(advantages[20], np.array(replayed) - replayed[best_column])

    module = load_script("clairvoyant_imitation")
    x = np.linspace(0, 1, 40)[:, None]
    y = np.zeros((40, 3))
    y[x[:, 0] > 0.5, 2] = 1.0  # the third setting pays above 0.5
    y[x[:, 0] <= 0.5, 0] = -1.0  # the first costs below it
    tree = DecisionTreeRegressor(min_samples_leaf=5).fit(x, y)
    policy = module.AdvantagePolicy(tree, ["a", "b", "c"], fallback=1)
    assert [policy.predict([value]) for value in (0.1, 0.45, 0.6, 0.9)] == ["b", "b", "c", "c"]
    refused = run_script("clairvoyant_imitation.py", *args, "--seeds", "0")
    assert refused.returncode == 2 and "must be >= 1" in refused.stderr


def test_train_rl_reports_its_speed_by_hand():
    from agents.rl.cli import training_speed

    # 65536 / 40 = 1638.4 steps/s; 1e6 / 1638.4 / 60 = 10.17 min
    expected = "trained 65536 steps in 40.0 s: 1638 steps/s, 10.2 min per 1e6 steps"
    assert training_speed(65536, 40.0) == expected


def test_train_rl_keeps_each_tasks_and_seeds_agent_in_its_own_folder():
    from agents.rl.cli import default_output_folder
    from agents.rl.training import RL_ENV_IDS

    folders = {
        default_output_folder(env_id, "ppo", seed) for env_id in RL_ENV_IDS for seed in range(3)
    }
    assert len(folders) == 3 * len(RL_ENV_IDS)  # the sensor task's v0, v1, v2 included
    assert Path("results/rl/DGPTrackSensors-v2-ppo-seed1") in folders


def test_agent_actions_classifies_tuning_steps_in_metres():
    """scripts/agent_actions.py's situations of a tuning task: a silent step first, then an
    innovation above 10 m (observed in sensing ranges, so the range converts it), then the
    number of experts."""
    from agents.rl.features import FEATURE_NAMES

    module = load_script("agent_actions")
    index = {name: i for i, name in enumerate(FEATURE_NAMES)}

    def situation(experts, innovation_m, silent, sensing_range):
        vector = np.zeros(len(FEATURE_NAMES), dtype=np.float32)
        vector[index["n_experts"]] = experts / 10
        vector[index["innovation"]] = innovation_m / sensing_range
        vector[index["silent_steps"]] = silent / 10
        return module.tuning_situation(vector, sensing_range)

    names = module.TUNING_SITUATIONS
    for sensing_range in (50.0, 80.0):
        assert situation(3, 9.0, 0, sensing_range) == names[1]
        assert situation(2, 9.0, 0, sensing_range) == names[0]
        assert situation(3, 11.0, 0, sensing_range) == names[2]
        assert situation(3, 11.0, 1, sensing_range) == names[3]


def test_fault_check_faults_are_in_todays_code_and_stale_ones_are_named():
    """scripts/fault_check.py: each listed fault's text occurs exactly once in the code it
    names and the fault changes it (else the check would test an unchanged copy); a text
    that is not there, or is there twice, is a ValueError that names the fault."""
    module = load_script("fault_check")
    names = [fault.name for fault in module.FAULTS]
    assert len(set(names)) == len(names)
    for fault in module.FAULTS:
        text = (ROOT / fault.path).read_text()
        assert module.faulty_text(text, fault) != text
    fault = module.FAULTS[0]
    with pytest.raises(ValueError, match=f"fault '{fault.name}'.* 0 times"):
        module.faulty_text("", fault)
    with pytest.raises(ValueError, match=f"fault '{fault.name}'.* 2 times"):
        module.faulty_text(fault.old + fault.old, fault)
    # the table counts every failing test and names the first SHOWN_TESTS (3)
    failed = [f"tests/test_agents/test_a.py::test_{i}" for i in range(4)]
    row = module.table([(fault, "caught", failed, 12.0)]).splitlines()[-1]
    assert row.endswith(
        "| caught | 4 | `test_a.py::test_0`<br>`test_a.py::test_1`<br>"
        "`test_a.py::test_2`<br>... | 12 |"
    )


def test_fault_check_tells_a_caught_fault_from_a_survived_one():
    """scripts/fault_check.py on the aggregation tests: a wrong gamma (Theorem 1's
    2 log(M / delta) halved) makes a test fail, a fault that changes nothing does not, and
    the working tree is left as it was."""
    module = load_script("fault_check")
    tests = ("tests/test_agents/test_aggregation.py",)
    source = ROOT / "agents" / "aggregation.py"
    before = source.read_text()
    old = "return 2.0 * np.log(np.maximum(np.asarray(n_experts, dtype=float), 1.0) / delta)"
    wrong = module.Fault(
        "gamma-halved", "", "agents/aggregation.py", old, old.replace("2.0", "1.0")
    )
    outcome, failed, _ = module.check_fault(wrong, tests)
    assert outcome == "caught"
    assert failed and all(
        test.startswith("tests/test_agents/test_aggregation.py::") for test in failed
    )
    inert = module.Fault("inert", "", "agents/aggregation.py", old, old + "  # unchanged")
    assert module.check_fault(inert, tests)[:2] == ("**survived**", [])
    assert source.read_text() == before


def hand_made_episodes(rmse, coverage_x=0.99, nees=1.5):
    """Stored metrics of one episode per value of ``rmse``, as the study scripts read them:
    3-sigma coverage ``coverage_x`` on X and 1 on Y, median NEES ``nees``."""
    return [
        {
            "rmse_2d": value,
            "coverage_3sigma_x_detected": coverage_x,
            "coverage_3sigma_y_detected": 1.0,
            "nees_median_detected": nees,
        }
        for value in rmse
    ]


def test_random_paths_tables_by_hand():
    """scripts/random_paths.py's tables from hand-made episodes: the RMS over episodes, the
    random / reference ratio (RMS 7.07 over 3.54 = 2), the paired difference to dgpt-rbcm
    and the calibration columns."""
    module = load_script("random_paths")
    episodes = hand_made_episodes
    cells = [(s, module.NOISE_STD, c) for s in module.SCENARIOS for c in module.CLUTTER_RATES]
    fixed = {(t, *cell): episodes([3.0, 4.0]) for t in ("dgpt-rbcm", "other") for cell in cells}
    random = {("dgpt-rbcm", *cell): episodes([6.0, 8.0]) for cell in cells}
    random |= {("other", *cell): episodes([7.0, 10.0], 0.5, 2.0) for cell in cells}
    text = module.report(fixed, random, ["dgpt-rbcm", "other"])
    rows = [line for line in text.splitlines() if line.startswith("| `")]
    assert rows[0].split(" | ")[1] == "7.07 (3.54)"  # RMS of 6, 8 and of 3, 4
    assert rows[2].split(" | ")[1].startswith("**2.00** [")
    # other - dgpt-rbcm: 1 and 2 m, mean 1.5; half-width t(0.975, 1) x sd 0.707 / sqrt(2)
    assert rows[5].split(" | ")[1] == f"+1.50 ± {stats.t.ppf(0.975, 1) * 0.5:.2f}"
    assert rows[7].split(" | ")[1] == "50.0 / 100.0, 2.00"
    value, low, high = module.ratio_interval([3.0, 4.0, 5.0], [6.0, 8.0, 10.0])
    assert value == pytest.approx(2.0) and low < 1.9 and high > 2.1
    # paired, every resample of proportional episodes has the ratio 2: the interval is a point
    assert module.ratio_interval([3.0, 4.0, 5.0], [6.0, 8.0, 10.0], paired=True) == (
        pytest.approx(2.0),
        pytest.approx(2.0),
        pytest.approx(2.0),
    )
    # unseen layouts against layout 0: the same tables under the comparison's names, no goal
    layouts = module.report(
        fixed, random, ["dgpt-rbcm", "other"], module.layout_comparison("random paths")
    )
    assert "### RMSE, unseen layouts, random paths (layout 0, random paths in parentheses)" in (
        layouts
    )
    ratio_rows = [line for line in layouts.splitlines() if line.startswith("| `")][2:4]
    assert ratio_rows[0].split(" | ")[1] == "2.00 [2.00, 2.00]"  # 6, 8 against 3, 4: paired
    assert "**" not in layouts and "goal 4" not in layouts
    # the UCB: coverage per axis in %, mean half-width (width 8 / 2) over mean RMSE (2 and
    # 4); an episode without a value (NaN) is left out of that mean, as in the grid's summaries
    bound = {"ucb_coverage_x_detected": 0.99, "ucb_coverage_y_detected": 1.0}
    bound |= {"ucb_width_x_detected": 8.0, "ucb_width_y_detected": 8.0}
    bound |= {"rmse_x_detected": 2.0, "rmse_y_detected": 4.0}
    assert module.ucb_cell([bound, bound | {"ucb_width_x_detected": np.nan}]) == (
        "99.00 / 100.00, 2.00 / 1.00"
    )
    assert module.ucb_cell([dict.fromkeys(bound, np.nan)]) == "-"
    medians = module.report(fixed, random, ["dgpt-rbcm", "other"], only=("median",))
    assert medians.startswith("### Median episode RMSE, random paths (reference paths in")
    assert [line.split(" | ")[1] for line in medians.splitlines() if line.startswith("| `")] == [
        "7.00 (3.50)",  # the medians of 6, 8 and of 3, 4
        "8.50 (3.50)",
    ]


def run_on_both_path_modes_then_resume(script, args, runs):
    """Run a study script with ``args``: it must run ``runs`` episodes on each path mode,
    then, run again, find every one in its store."""
    first = run_script(script, *args)
    assert first.returncode == 0, first.stderr
    assert f"fixed paths: {runs} runs" in first.stdout
    assert f"random paths: {runs} runs" in first.stdout
    again = run_script(script, *args)
    assert f"random paths: 0 runs, {runs} already stored" in again.stdout


def test_random_paths_runs_both_path_modes_and_resumes(tmp_path):
    args = ["--trackers", "dgpt-rbcm", "centroid", "--runs", "2", "--workers", "1"]
    args += ["--out", str(tmp_path), "--report", str(tmp_path / "report.md"), "--no-progress"]
    run_on_both_path_modes_then_resume("random_paths.py", args, 32)  # 2 x 8 cells x 2 seeds
    report = (tmp_path / "report.md").read_text()
    assert report.count("| `centroid` |") == 4 and "seeds 0-1" in report
    # both path modes again in layouts 0 and 1 (seed s in layout s), against the stored layout 0
    layouts = run_script("random_paths.py", *args, "--layout", "per_episode", "--verify", "5")
    assert layouts.returncode == 0, layouts.stderr
    assert "random paths in unseen layouts: 32 runs" in layouts.stdout
    assert "fixed paths in unseen layouts: 32 runs" in layouts.stdout
    report = (tmp_path / "report.md").read_text()
    # six tables per path mode, and goal 4's ratio with both modes in unseen layouts
    assert report.count("| `centroid` |") == 13 and "unseen sensor layouts" in report
    assert f"by dgpt-gym {dgpt_gym.__version__}." in report
    assert "re-ran 5 of the runs read, 0 of them stored by other versions" in layouts.stdout
    assert "every metric but the wall-clock ones equals the stored one" in layouts.stdout


def test_unseen_layouts_need_the_stored_layout_0_runs(tmp_path):
    args = ["--trackers", "centroid", "--runs", "1", "--workers", "1", "--layout", "per_episode"]
    result = run_script("random_paths.py", *args, "--out", str(tmp_path), "--no-progress")
    assert result.returncode != 0
    assert "not stored" in result.stderr and "for the runs in layout 0" in result.stderr
    with sqlite3.connect(tmp_path / "results.sqlite") as connection:  # nothing ran before
        assert connection.execute("SELECT COUNT(*) FROM runs").fetchone() == (0,)


def test_clutter_sweep_tables_by_hand():
    """scripts/clutter_sweep.py's tables from hand-made episodes: the RMS over episodes, the
    paired difference to dgpt-rbcm averaged over the four scenarios with its stratified
    interval, and the calibration cell (mean and lowest scenario-axis, median NEES)."""
    module = load_script("clutter_sweep")
    episodes = hand_made_episodes
    rates = [1.0, 20.0]
    by_mode = {}
    for mode in ("fixed", "random"):
        cells = {}
        for index, scenario in enumerate(module.SCENARIOS):
            for rate in rates:
                cell = (scenario, module.NOISE_STD, rate)
                cells[("dgpt-rbcm", *cell)] = episodes([3.0, 4.0])
                # differences to the reference: scenario k (0-3) gets k + 1 and k + 3
                cells[("other", *cell)] = episodes(
                    [4.0 + index, 7.0 + index], 0.98 - 0.01 * index, nees=2.0 + index**2
                )
                cells[("other", *cell)][1]["coverage_3sigma_x_detected"] -= 0.02
                # no variance at clutter 1 (NaN coverage on both axes), some at clutter 20
                blind = episodes([5.0], nees=np.nan)
                blind[0]["coverage_3sigma_y_detected"] = np.nan if rate == 1.0 else 1.0
                if rate == 1.0:
                    blind[0]["coverage_3sigma_x_detected"] = np.nan
                cells[("blind", *cell)] = blind
        by_mode[mode] = cells
    text = module.report(by_mode, ["dgpt-rbcm", "other", "blind"], rates)
    rows = [line for line in text.splitlines() if line.startswith("| ")]
    assert "| S1 | `dgpt-rbcm` | 3.54 | 3.54 |" in rows  # RMS of 3 and 4
    assert f"| S2 | `other` | {np.sqrt((25 + 64) / 2):.2f} | {np.sqrt((25 + 64) / 2):.2f} |" in rows
    # per scenario the mean difference is k + 2 (mean 3.5 over k = 0-3), the variance of
    # each mean 2 / 2; the stratified half-width 1.96 sqrt(4 x 1) / 4
    half = stats.norm.ppf(0.975) * np.sqrt(4.0) / 4
    paired = next(row for row in rows if row.startswith("| `other` | fixed | **"))
    assert paired.split(" | ")[2] == f"**+3.50 ± {half:.2f}**"
    # coverage X: episodes at 98 and 96 % in S1 (mean 97), then 96, 95, 94 %; Y 100 % in
    # the four scenarios; NEES 2, 3, 6, 11 (two episodes each): median 4.5, mean 5.5
    calibration = [row for row in rows if row.startswith("| `other` | random | 9")]
    assert calibration[0].split(" | ")[2] == f"{(97 + 96 + 95 + 94 + 400) / 8:.2f} (94.00), 4.50"
    # a cell without variance is "-", the others keep their columns
    assert "| `blind` | fixed | - | 99.50 (99.00), nan |" in rows


def test_clutter_sweep_runs_resumes_and_draws(tmp_path):
    args = ["--trackers", "dgpt-rbcm", "centroid", "--runs", "1", "--clutter-rates", "1", "8"]
    args += ["--workers", "1", "--out", str(tmp_path), "--no-progress"]
    args += ["--report", str(tmp_path / "report.md"), "--figure", str(tmp_path / "rmse.png")]
    # 2 trackers x 4 scenarios x 2 clutter rates x 1 seed in each mode
    run_on_both_path_modes_then_resume("clutter_sweep.py", args, 16)
    report = (tmp_path / "report.md").read_text()
    # 8 RMSE rows (4 scenarios x 2 modes), 2 paired and 2 calibration rows
    assert report.count("| `centroid` |") == 12 and "| c1 | c8 |" in report
    assert (tmp_path / "rmse.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_ablations_tables_by_hand():
    """scripts/ablations.py's tables from hand-made episodes: the paired difference per cell
    with its t interval, the cells' stratified mean and interval, and the summary row."""
    module = load_script("ablations")
    # strata of unequal size: means 1 and 11; variances of the mean 2 / 2 and 3 / 3
    mean, half = module.stratified_difference([np.array([0.0, 2.0]), np.array([10, 10, 13.0])])
    assert mean == pytest.approx(6.0)
    assert half == pytest.approx(stats.norm.ppf(0.975) * np.sqrt(2.0) / 2)

    def episodes(rmse, shares=(0.2, np.nan, 0.5), nrmse=((0.01, 0.01),) * 3):
        return [
            {
                "rmse_2d": value,
                "coverage_3sigma_x_detected": 0.99,
                "coverage_3sigma_y_detected": 1.0,
                "nees_median_detected": value / 2,
                "share_at_bound": share,
                "nrmse_x": x,
                "nrmse_y": y,
            }
            for value, share, (x, y) in zip(rmse, shares, nrmse)
        ]

    cells = [(s, module.NOISE_STD, c) for s in module.SCENARIOS for c in module.CLUTTER_RATES]
    by_mode = {
        mode: {
            **{(module.REFERENCE, *cell): episodes([3.0, 4.0, 5.0]) for cell in cells},
            **{("gp", *cell): episodes([4.0, 6.0, 14.0], [np.nan] * 3) for cell in cells},
            **{
                ("dgpt-rbcm/window-8", *cell): episodes(
                    [3.0, 4.0, 5.0], nrmse=((0.01, 0.03), (0.02, 0.04), (0.06, 0.08))
                )
                for cell in cells
            },
            **{
                ("dgpt-rbcm/window-2", *cell): episodes([3.0, 4.0, 5.0], nrmse=((0.02, 0.02),) * 3)
                for cell in cells
            },
        }
        for mode in module.TRAJECTORY_MODES
    }
    # on the reference paths, S1 at clutter 5 learnt with q on a bound on 80 % of steps
    by_mode["fixed"][("dgpt-rbcm/window-8", "S1", module.NOISE_STD, 5.0)] = episodes(
        [3.0, 4.0, 5.0], (0.8,) * 3, ((0.01, 0.03), (0.02, 0.04), (0.06, 0.08))
    )
    text = module.report(by_mode, ["gp", "dgpt-rbcm/window-8", "dgpt-rbcm/window-2"])
    rows = [line.split(" | ") for line in text.splitlines() if line.startswith("| `gp`")]
    assert len(rows) == 3  # one per path mode and the summary
    # gp - dgpt-rbcm: 1, 2 and 9 m in every cell, mean 4, variance 19; not bold within a cell
    assert rows[0][1] == f"+4.00 ± {stats.t.ppf(0.975, 2) * np.sqrt(19 / 3):.2f}"
    # over 8 equal cells: 1.96 sqrt(8 x 19 / 3) / 8 = 1.74
    assert rows[0][-1] == "**+4.00 ± 1.74** |"
    # RMS of 4, 6, 14; coverage (99 + 100) / 2; the median (not the mean, 4) of 2, 3, 7;
    # no learning step in any episode
    assert rows[2][2:] == ["9.09 / 9.09", "99.50 / 99.50", "3.00 / 3.00", "- / - |"]
    reference = next(line for line in text.splitlines() if line.startswith("| `dgpt-rbcm` |"))
    # the share's mean over the episodes that learnt: (20 + 50) / 2, not over all three
    assert reference.endswith("| 35 / 35 |")
    # NRMSE against the window, per path mode: the episodes' mean (not the median, 3) of the
    # axes' mean, in % (window 8: 2, 3 and 7 %), the windows in order, the default's 4 too
    lines = text.splitlines()
    rows = [
        f"| {w} | " + " | ".join([value] * 8) + " |"
        for w, value in ((2, "2.00"), (4, "1.00"), (8, "4.00"))
    ]
    assert [lines.count(row) for row in rows] == [2, 2, 2]
    assert lines.index(rows[0]) < lines.index(rows[1]) < lines.index(rows[2])
    assert module.window_table(by_mode, ["gp"]) == []  # no window arm, no table
    # on a bound per scenario: the learning episodes' mean, both clutter rates pooled
    # (20 and 50 % in each; S1's reference paths also 80, 80, 80 at clutter 5: 310 / 5),
    # and no row for an arm that never learns
    bounds = module.bound_table(by_mode, ["gp", "dgpt-rbcm/window-8"])
    assert bounds[-2:] == [
        "| `dgpt-rbcm` | " + " | ".join(["35 / 35"] * 4) + " |",
        "| `dgpt-rbcm/window-8` | 62 / 35 | " + " | ".join(["35 / 35"] * 3) + " |",
    ]
    assert not any(line.startswith("| `gp`") for line in bounds)


def test_ablations_runs_an_arm_on_both_path_modes(tmp_path):
    args = ["--arms", "dgpt-rbcm/no-learning", "--runs", "1", "--workers", "1"]
    args += ["--out", str(tmp_path), "--report", str(tmp_path / "report.md"), "--no-progress"]
    result = run_script("ablations.py", *args)
    assert result.returncode == 0, result.stderr
    # 2 trackers x 8 cells x 1 seed in each mode
    assert "fixed paths: 16 runs" in result.stdout and "random paths: 16 runs" in result.stdout
    assert (tmp_path / "report.md").read_text().count("| `dgpt-rbcm/no-learning` |") == 3


def test_all_clutter_error_parts_by_hand():
    """An episode of 20 steps: errors 30 m on steps 0-1 and 12 m on step 3, so the track
    first holds (3 steps in a row below 10 m) at step 4, not at step 2; a coverage gap on
    step 8 with 20 m errors on steps 9 and 19 (19 is 11 steps after the gap: elsewhere; 18
    is the last step near it), 1 m otherwise."""
    module = load_script("all_clutter_floor")
    error = np.ones(20)
    error[[0, 1]] = 30.0
    error[3] = 12.0
    error[[9, 19]] = 20.0
    detecting = np.full(20, 2)
    detecting[8] = 0
    truth = np.zeros((20, 2))
    result = type("Result", (), {})()
    result.truth, result.n_detecting = truth, detecting
    result.mean = np.column_stack([error, np.zeros(20)])
    before, near_gap, elsewhere = module.error_parts(result)
    assert before == 2 * 900.0 + 1.0 + 144.0  # steps 0-3
    assert near_gap == 400.0 + 10 * 1.0  # step 9, and steps 8 and 10-18
    assert elsewhere == 400.0 + 4 * 1.0  # step 19, and steps 4-7
