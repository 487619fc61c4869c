"""The evaluation harness: grids, the SQLite results store, resume, Dask, failures, outputs."""

import csv
import json
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from flaky_tracker import FAILING_SEED

import dgpt_gym
from dgpt_gym import make_tracker, register_tracker
from dgpt_gym.benchmark import cli as evaluate_cli
from dgpt_gym.benchmark.episodes import run_episode
from dgpt_gym.benchmark.outputs import write_outputs
from dgpt_gym.benchmark.store import DATABASE_NAME, ResultsStore, run_key
from dgpt_gym.benchmark.sweep import (
    Grid,
    Variant,
    make_blocks,
    on_every_path_mode,
    run_sweep,
    stored_metrics,
    summarize_store,
    sweep_metrics,
    sweep_units,
    verify_store,
)
from dgpt_gym.benchmark.windows import tuned_kwargs

ROOT = Path(__file__).resolve().parents[3]
DETERMINISTIC = ("step_time_ms",)  # wall-clock: the one metric that varies between runs


def deterministic_metrics_by_key(folder) -> dict[str, dict]:
    with ResultsStore(folder) as store:
        return {
            row["run_key"]: {k: v for k, v in row["metrics"].items() if k not in DETERMINISTIC}
            for row in store.rows(status="ok")
        }


def without_command_lines(path: Path) -> str:
    return "\n".join(line for line in path.read_text().splitlines() if "Command:" not in line)


def test_tiny_grid_end_to_end_equals_direct_episodes(tmp_path):
    grid = Grid(trackers=("dgpt-rbcm", "centroid"), scenarios=("S3",), clutter_rates=(5.0,), runs=2)
    report = run_sweep([grid], tmp_path, workers=1, progress=False)
    assert (report.total, report.ran, report.failed) == (4, 4, 0)
    written = write_outputs([grid], tmp_path, command="test")
    names = {path.relative_to(tmp_path).as_posix() for path in written}
    assert {
        "results.md",
        "results_cells.csv",
        "results_tables.md",
        "results_uncertainty.md",
        "figures/ucb_vs_ci.png",
        "figures/scenarios.png",
    } <= names
    assert all((tmp_path / name).stat().st_size > 0 for name in names)
    with sqlite3.connect(tmp_path / DATABASE_NAME) as connection:
        assert connection.execute("SELECT COUNT(*) FROM runs WHERE status = 'ok'").fetchone() == (
            4,
        )

    env = gym.make("DGPTrack-v0", scenario="S3", clutter_rate=5.0)
    direct = {
        tracker: [
            run_episode(env, make_tracker(tracker, **tuned_kwargs(tracker, "S3")), seed).metrics()
            for seed in (0, 1)
        ]
        for tracker in ("dgpt-rbcm", "centroid")
    }
    with (tmp_path / "results_cells.csv").open() as handle:
        cells = {row["tracker"]: row for row in csv.DictReader(handle)}
    for tracker, runs in direct.items():
        for key in ("nrmse_x", "nrmse_y", "rmse_y", "ci_coverage_x"):
            assert float(cells[tracker][key]) == pytest.approx(
                np.mean([r[key] for r in runs]), rel=1e-12
            )
        std = np.std([r["rmse_x"] for r in runs], ddof=1)
        assert float(cells[tracker]["rmse_std_x"]) == pytest.approx(std, rel=1e-12)
    # the paper-style table prints our NRMSE in percent with two decimals
    nrmse_x = 100 * np.mean([r["nrmse_x"] for r in direct["dgpt-rbcm"]])
    table = (tmp_path / "results_tables.md").read_text()
    assert f"| {nrmse_x:.2f} (" in table
    assert "Table IV" in table  # S3, TGP


def test_rerun_skips_finished_runs(tmp_path):
    grid = Grid(trackers=("centroid",), scenarios=("S1",), clutter_rates=(1.0,), runs=3)
    first = run_sweep([grid], tmp_path, workers=1, progress=False)
    bigger = Grid(trackers=("centroid",), scenarios=("S1",), clutter_rates=(1.0,), runs=5)
    second = run_sweep([bigger], tmp_path, workers=1, progress=False)
    assert (first.ran, second.already_finished, second.ran) == (3, 3, 2)
    summaries, failures = summarize_store([grid], tmp_path)
    assert summaries[0]["n_runs"] == 3 and failures == []  # only the grid's own seeds


def test_runs_of_another_version_are_run_again_and_replaced(tmp_path, monkeypatch):
    import dgpt_gym

    grid = Grid(trackers=("centroid",), scenarios=("S1",), clutter_rates=(1.0,), runs=2)
    run_sweep([grid], tmp_path, workers=1, progress=False)
    monkeypatch.setattr(dgpt_gym, "__version__", "99.0")
    again = run_sweep([grid], tmp_path, workers=1, progress=False)
    assert (again.already_finished, again.ran) == (0, 2)
    with sqlite3.connect(tmp_path / DATABASE_NAME) as connection:
        assert connection.execute("SELECT DISTINCT version FROM runs").fetchall() == [("99.0",)]
    assert summarize_store([grid], tmp_path)[0][0]["versions"] == "99.0"


def test_resume_after_kill_loses_and_duplicates_nothing(tmp_path):
    args = [
        sys.executable,
        str(ROOT / "scripts" / "evaluate.py"),
        *("--trackers", "dgpt-rbcm", "--scenarios", "S4", "--clutter-rates", "1"),
        *("--runs", "30", "--workers", "1", "--no-progress"),
    ]
    killed = tmp_path / "killed"
    small_blocks = ["--batch-size", "3"]  # rows arrive three at a time, the kill lands between
    process = subprocess.Popen(
        [*args, *small_blocks, "--out", str(killed)], stdout=subprocess.DEVNULL
    )
    database = killed / DATABASE_NAME
    deadline = time.monotonic() + 120
    finished = 0
    while finished < 5 and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.05)
        if database.exists():
            with sqlite3.connect(database) as connection:
                try:
                    finished = connection.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
                except sqlite3.OperationalError:  # table not created yet
                    finished = 0
    process.send_signal(signal.SIGKILL)
    process.wait()
    before = deterministic_metrics_by_key(killed)
    assert 5 <= len(before) < 30, "the kill must land part-way through the sweep"

    resumed = subprocess.run(
        [*args, *small_blocks, "--out", str(killed)], capture_output=True, text=True
    )
    assert resumed.returncode == 0, resumed.stderr
    assert f"30 runs: {len(before)} already in" in resumed.stdout
    after = deterministic_metrics_by_key(killed)
    with sqlite3.connect(database) as connection:
        assert connection.execute("SELECT COUNT(*) FROM runs").fetchone() == (30,)
        seeds = [s for (s,) in connection.execute("SELECT seed FROM runs ORDER BY seed")]
    assert seeds == list(range(30))  # none lost, none twice
    assert all(after[key] == value for key, value in before.items())

    # one block of all 30 runs: a run's numbers do not depend on what it is batched with
    clean = tmp_path / "clean"
    uninterrupted = subprocess.run([*args, "--out", str(clean)], capture_output=True, text=True)
    assert uninterrupted.returncode == 0, uninterrupted.stderr
    assert deterministic_metrics_by_key(clean) == after
    for name in ("results_tables.md", "results_uncertainty.md"):
        assert without_command_lines(killed / name) == without_command_lines(clean / name)


def test_local_pool_and_dask_cluster_give_identical_rows(tmp_path):
    from distributed import LocalCluster

    grid = Grid(trackers=("dgpt-gpoe", "cpf"), scenarios=("S2",), clutter_rates=(5.0,), runs=3)
    local = run_sweep([grid], tmp_path / "local", workers=2, progress=False)
    with LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=None,
    ) as cluster:
        remote = run_sweep(
            [grid], tmp_path / "dask", scheduler=cluster.scheduler_address, progress=False
        )
    assert local.ran == remote.ran == 6 and local.failed == remote.failed == 0
    assert deterministic_metrics_by_key(tmp_path / "local") == deterministic_metrics_by_key(
        tmp_path / "dask"
    )


def test_a_failing_run_is_recorded_and_the_sweep_completes(tmp_path):
    register_tracker("flaky", entry_point="flaky_tracker:FlakyTracker")
    grid = Grid(trackers=("flaky",), scenarios=("S1",), clutter_rates=(1.0,), runs=3)
    report = run_sweep([grid], tmp_path, workers=1, progress=False)
    assert (report.ran, report.failed) == (3, 1)
    assert "FloatingPointError: diverged on seed 1" in report.errors[0]
    summaries, failures = summarize_store([grid], tmp_path)
    assert summaries[0]["n_runs"] == 2
    assert [(row["seed"], row["status"]) for row in failures] == [(FAILING_SEED, "failed")]
    write_outputs([grid], tmp_path, command="test")
    text = (tmp_path / "results.md").read_text()
    assert "**1 failed**" in text and "diverged on seed 1" in text
    again = run_sweep([grid], tmp_path, workers=1, progress=False)  # failures are retried
    assert (again.already_finished, again.ran, again.failed) == (2, 1, 1)
    with sqlite3.connect(tmp_path / DATABASE_NAME) as connection:
        assert connection.execute("SELECT COUNT(*) FROM runs").fetchone() == (3,)
    with pytest.raises(ValueError, match=f"seed {FAILING_SEED} .* is failed"):
        stored_metrics(grid, tmp_path)
    with pytest.raises(RuntimeError, match="1 runs failed.*diverged on seed 1"):
        sweep_metrics(grid, tmp_path, workers=1, progress=False)


def test_grids_validate_their_arguments():
    with pytest.raises(ValueError, match=r"tracker must be one of \[.*'dgpt-rbcm'"):
        Grid(trackers=("kalman",))
    with pytest.raises(ValueError, match=r"'S1', 'S2', 'S3', 'S4'"):
        Grid(trackers=("gp",), scenarios=("S9",))
    with pytest.raises(ValueError, match="runs"):
        Grid(trackers=("gp",), runs=0)
    with pytest.raises(ValueError, match="noise_std"):
        Grid(trackers=("gp",), noise_levels=(-1.0,))
    with pytest.raises(ValueError, match=r"trajectory must be one of \['fixed', 'random'\]"):
        Grid(trackers=("gp",), trajectory="circle")


def test_a_random_path_grid_runs_random_paths_and_keeps_the_fixed_grids_keys(tmp_path):
    """A grid's runs on random paths are the episodes of ``trajectory="random"`` (another
    path from the reference one); the default grid's keys are those of runs whose
    environment arguments do not name the path mode, as stored before the field existed."""
    cell = dict(trackers=("centroid",), scenarios=("S2",), clutter_rates=(1.0,), runs=1)
    fixed, random = Grid(**cell).units()[0], Grid(**cell, trajectory="random").units()[0]
    assert fixed.key == run_key("centroid", fixed.tracker_kwargs, fixed.env_kwargs, 0)
    assert "trajectory" not in fixed.env_kwargs and fixed.key != random.key
    run_sweep([Grid(**cell, trajectory="random")], tmp_path, workers=1, progress=False)
    with ResultsStore(tmp_path) as store:
        (row,) = store.rows(status="ok")
    env = gym.make("DGPTrack-v0", scenario="S2", clutter_rate=1.0, trajectory="random")
    direct = run_episode(env, make_tracker("centroid"), 0).metrics()
    assert row["env_kwargs"]["trajectory"] == "random"
    assert row["metrics"]["rmse_2d"] == direct["rmse_2d"]
    reference = run_episode(
        gym.make("DGPTrack-v0", scenario="S2", clutter_rate=1.0), make_tracker("centroid"), 0
    )
    assert reference.metrics()["rmse_2d"] != direct["rmse_2d"]
    with pytest.raises(ValueError, match=r"share one trajectory.*\['fixed', 'random'\]"):
        summarize_store([Grid(**cell), Grid(**cell, trajectory="random")], tmp_path)
    both = on_every_path_mode(Grid(**cell, trajectory="random"))
    assert [unit.key for unit in both["fixed"].units()] == [fixed.key]
    assert [unit.key for unit in both["random"].units()] == [random.key]


@pytest.mark.parametrize("tracker", ["dgpt-rbcm", "dgpt-rbcm-trend", "hybrid"])
def test_per_episode_layouts_run_seed_s_in_layout_s_in_one_block_as_each_alone(tmp_path, tracker):
    """With ``layout="per_episode"`` the run of seed s is the episode of ``layout_seed=s``;
    the three runs share one lockstep block (one tracker, one cell) although their layouts
    differ, and each equals its episode run alone. The default grid's keys do not name the
    layout."""
    cell = dict(trackers=(tracker,), scenarios=("S1",), clutter_rates=(5.0,), runs=3)
    units = Grid(**cell, layout="per_episode").units()
    assert [unit.env_kwargs["layout_seed"] for unit in units] == [0, 1, 2]
    assert "layout_seed" not in Grid(**cell).units()[0].env_kwargs
    assert len(make_blocks(units, batch_size=50)) == 1
    run_sweep([Grid(**cell, layout="per_episode")], tmp_path, workers=1, progress=False)
    stored = deterministic_metrics_by_key(tmp_path)
    for unit in units:
        env = gym.make("DGPTrack-v0", scenario="S1", clutter_rate=5.0, layout_seed=unit.seed)
        alone = run_episode(env, make_tracker(tracker, **tuned_kwargs(tracker, "S1")), unit.seed)
        expected = {k: v for k, v in alone.metrics().items() if k not in DETERMINISTIC}
        assert json.dumps(stored[unit.key], sort_keys=True) == json.dumps(expected, sort_keys=True)
    # seed 0's layout is the default one, seed 1's another: only seed 0's run is the fixed
    # grid's
    fixed = {unit.seed: unit for unit in Grid(**cell).units()}
    run_sweep([Grid(**{**cell, "runs": 2})], tmp_path, workers=1, progress=False)
    every = deterministic_metrics_by_key(tmp_path)
    assert every[units[0].key] == every[fixed[0].key]
    assert every[units[1].key]["rmse_2d"] != every[fixed[1].key]["rmse_2d"]
    with pytest.raises(ValueError, match=r"layout must be one of \['fixed', 'per_episode'\]"):
        Grid(**cell, layout="random")
    with pytest.raises(ValueError, match=r"share one layout.*\['fixed', 'per_episode'\]"):
        summarize_store([Grid(**cell), Grid(**cell, layout="per_episode")], tmp_path)


def test_a_variant_runs_its_base_with_the_overrides_under_its_own_name(tmp_path):
    """A :class:`Variant`'s runs are the base tracker's episodes with the changed argument,
    stored under the variant's name, and :func:`stored_metrics` returns them by cell in seed
    order, beside the base's own runs, which are different."""
    narrow = Variant("centroid/gate-10", "centroid", (("gate_radius", 10.0),))
    grid = Grid(trackers=("centroid", narrow), scenarios=("S1",), clutter_rates=(5.0,), runs=2)
    assert [unit.tracker for unit in grid.units()] == ["centroid"] * 2 + ["centroid/gate-10"] * 2
    with pytest.raises(ValueError, match="not stored"):
        stored_metrics(grid, tmp_path)
    done, metrics = sweep_metrics(grid, tmp_path, workers=1, progress=False)
    assert (done.ran, done.already_finished) == (4, 0) and metrics == stored_metrics(grid, tmp_path)
    env = gym.make("DGPTrack-v0", scenario="S1", clutter_rate=5.0)
    for seed in (0, 1):
        direct = run_episode(env, make_tracker("centroid", gate_radius=10.0), seed).metrics()
        default = run_episode(env, make_tracker("centroid"), seed).metrics()
        assert metrics[("centroid/gate-10", "S1", 1.0, 5.0)][seed]["rmse_2d"] == direct["rmse_2d"]
        assert metrics[("centroid", "S1", 1.0, 5.0)][seed]["rmse_2d"] == default["rmse_2d"]
        assert direct["rmse_2d"] != default["rmse_2d"]


def test_variants_validate_their_name_and_arguments():
    with pytest.raises(ValueError, match="registered tracker id.*'pda'"):
        Variant("pda", "centroid", (("gate_radius", 10.0),))
    with pytest.raises(ValueError, match="cannot be built .*gate_width"):
        Variant("centroid/x", "centroid", (("gate_width", 10.0),))
    with pytest.raises(ValueError, match="gate_radius"):
        Variant("centroid/x", "centroid", (("gate_radius", -1.0),))
    with pytest.raises(ValueError, match="tracker must be one of"):
        Variant("x/y", "no-such-tracker")


def test_overlapping_grids_run_each_unit_once():
    a = Grid(trackers=("gp", "cpf"), scenarios=("S1",), clutter_rates=(5.0,), runs=2)
    b = Grid(trackers=("cpf",), scenarios=("S1", "S2"), clutter_rates=(5.0,), runs=2)
    units = sweep_units([a, b])
    assert len(units) == 4 + 2
    assert len({unit.key for unit in units}) == len(units)


def test_verify_reruns_stored_runs_and_names_the_metric_that_differs(tmp_path, monkeypatch, capsys):
    grid = Grid(trackers=("centroid",), scenarios=("S1", "S2"), clutter_rates=(5.0,), runs=3)
    run_sweep([grid], tmp_path, workers=1, progress=False)
    clean = verify_store([grid], tmp_path, count=4, progress=False)
    assert (clean.checked, clean.other_versions, clean.mismatches) == (4, 0, ())
    database = sqlite3.connect(tmp_path / DATABASE_NAME)
    with database:
        # one stored run that its code does not produce, by the last bit of one metric
        (text,) = database.execute(
            "SELECT metrics FROM runs WHERE scenario = 'S2' AND seed = 1"
        ).fetchone()
        metrics = json.loads(text)
        metrics["nrmse_x"] = float(np.nextafter(metrics["nrmse_x"], 1.0))
        database.execute(
            "UPDATE runs SET metrics = ? WHERE scenario = 'S2' AND seed = 1",
            (json.dumps(metrics),),
        )
        # and one stored by another version, which is not this code's to reproduce
        database.execute("UPDATE runs SET version = '0.0.0' WHERE scenario = 'S1' AND seed = 0")
    database.close()
    tampered = verify_store([grid], tmp_path, count=100, progress=False)
    assert (tampered.checked, tampered.other_versions) == (5, 1)
    (line,) = tampered.mismatches
    assert line.startswith("centroid S2 sigma_z 1 clutter 5 seed 1: nrmse_x ")
    assert "->" in line and ";" not in line  # that metric alone
    # any_version draws from the other version's run too, and finds it this code's numbers
    every = verify_store([grid], tmp_path, count=100, progress=False, any_version=True)
    assert (every.checked, every.other_versions, every.mismatches) == (6, 1, tampered.mismatches)
    assert (every.checked_other_versions, tampered.checked_other_versions) == (1, 0)
    argv = ["--trackers", "centroid", "--scenarios", "S1", "S2", "--clutter-rates", "5"]
    argv += ["--runs", "3", "--out", str(tmp_path), "--verify", "6", "--no-progress"]
    assert evaluate_cli.main(argv) == 1
    printed = capsys.readouterr().out
    assert "differs: centroid S2 sigma_z 1 clutter 5 seed 1: nrmse_x" in printed
    assert (
        "re-ran 5 runs" in printed and "1 differ" in printed and "1 runs stored by other" in printed
    )
    monkeypatch.setattr(dgpt_gym, "__version__", "0.0.0-other")
    with pytest.raises(ValueError, match="no finished run of this sweep"):
        verify_store([grid], tmp_path, count=1, progress=False)
    with pytest.raises(ValueError, match="count"):
        verify_store([grid], tmp_path, count=0, progress=False)
