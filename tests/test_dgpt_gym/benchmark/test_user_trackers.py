"""A user's own tracker in the evaluation: its edits are run again, not read from the store,
and what it gets wrong about the tracker contract fails at once, naming what is wrong."""

import hashlib
import importlib
import sys

import gymnasium as gym
import numpy as np
import pytest

from dgpt_gym import registry
from dgpt_gym.benchmark import cli as evaluate_cli
from dgpt_gym.benchmark.episodes import run_episode
from dgpt_gym.benchmark.metrics import coverage
from dgpt_gym.benchmark.store import ResultsStore
from dgpt_gym.benchmark.sweep import Grid, Variant, run_sweep
from dgpt_gym.registry import source_digest
from dgpt_gym.tracker import Estimate, TrackerBase, check_reset_signature

USER_MODULE = """
import numpy as np
from dgpt_gym.benchmark.metrics import coverage
from dgpt_gym.tracker import Estimate, TrackerBase, check_reset_signature

VARIANCE = {variance}


class Centroid(TrackerBase):
    name = "user-centroid"

    def reset(self, spec, seed=None):
        self.spec_, self.last_ = spec, np.full(2, spec.area / 2.0)

    def update(self, obs):
        mask = np.asarray(obs["mask"]).astype(bool)
        if mask.any():
            self.last_ = np.asarray(obs["measurements"])[mask].mean(axis=0)
        return Estimate(self.last_.copy(), np.full(2, VARIANCE))


class NeedsArgument(Centroid):
    def __init__(self, k):
        self.k = k


class NoSeed(Centroid):
    def reset(self, spec):
        super().reset(spec)
"""


@pytest.fixture
def user_module(tmp_path, monkeypatch):
    """Write ``user_trackers_<test folder>.py`` with a given variance into a folder on
    sys.path; returns a function that (re)writes it and forgets the imported module (as a
    new process would). The ids the test registers are forgotten after it."""
    name = "user_trackers_" + "".join(c if c.isalnum() else "_" for c in tmp_path.name)
    path = tmp_path / f"{name}.py"
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))

    def write(variance: str) -> str:
        path.write_text(USER_MODULE.format(variance=variance))
        sys.modules.pop(name, None)
        importlib.invalidate_caches()
        return name

    yield write
    sys.modules.pop(name, None)


def test_editing_a_user_trackers_module_runs_it_again(user_module, tmp_path):
    """The store's key holds the user module's source: the same code is read back, an edit
    is run again (in the same process: the digest follows the file's size and time). The edit scales the reported variance by 4 / 9, so every episode's ANEES
    scales by 9 / 4 exactly (same estimates, same seeds)."""
    grid_of = lambda module: Grid(  # noqa: E731
        trackers=(f"{module}:Centroid",), scenarios=("S1",), clutter_rates=(1.0,), runs=2
    )
    out = tmp_path / "out"
    grid = grid_of(user_module("9.0"))
    first = run_sweep([grid], out, workers=1, progress=False)
    again = run_sweep([grid], out, workers=1, progress=False)
    assert (first.ran, again.already_finished, again.ran) == (2, 2, 0)
    before = anees_by_seed(out, grid)
    grid = grid_of(user_module("4.00"))  # another size too: no stale bytecode
    edited = run_sweep([grid], out, workers=1, progress=False)
    assert (edited.already_finished, edited.ran) == (0, 2)
    after = anees_by_seed(out, grid)
    assert after.keys() == before.keys() == {0, 1}
    for seed in before:
        assert after[seed] == pytest.approx(before[seed] * 9.0 / 4.0, rel=1e-12)


def anees_by_seed(out, grid) -> dict[int, float]:
    keys = {unit.key: unit.seed for unit in grid.units()}
    with ResultsStore(out) as store:
        rows = store.rows(keys=set(keys), status="ok")
    return {keys[row["run_key"]]: row["metrics"]["anees"] for row in rows}


def test_the_source_digest_is_the_user_modules_and_none_for_the_projects(user_module):
    module = user_module("1.0")
    path = sys.path[0] + f"/{module}.py"
    with open(path, "rb") as source:
        expected = hashlib.sha256(source.read()).hexdigest()
    assert source_digest(f"{module}:Centroid") == expected
    for project in (
        "agents.state_space_dgpt:StateSpaceDGPT",
        "baselines.centroid:GatedCentroidTracker",
        "dgpt_gym.tracker:TrackerBase",
    ):
        assert source_digest(project) is None


def test_a_tracker_that_cannot_be_built_or_reset_fails_the_grid_at_once(
    user_module, tmp_path, monkeypatch
):
    module = user_module("1.0")
    cell = dict(scenarios=("S1",), clutter_rates=(1.0,), runs=1)
    with pytest.raises(ValueError, match=r"cannot be built with the arguments \{\}.*'k'"):
        Grid(trackers=(f"{module}:NeedsArgument",), **cell)
    with pytest.raises(ValueError, match=r"NoSeed\.reset must take reset\(spec, seed=None\)"):
        Grid(trackers=(f"{module}:NoSeed",), **cell)
    with pytest.raises(ValueError, match="no_such_argument"):
        Variant("centroid/bad", "centroid", (("no_such_argument", 1),))
    broken = tmp_path / "needs_a_missing_package.py"
    broken.write_text("raise ImportError(\"needs foo: pip install 'foo'\")\n")
    importlib.invalidate_caches()
    missing = r"needs foo: pip install 'foo'"
    with pytest.raises(ValueError, match=r"names no importable class .*" + missing):
        Grid(trackers=("needs_a_missing_package:Tracker",), **cell)
    # a registered id whose module needs an extra that is not installed (as stonesoup-pda)
    spec = registry.TrackerSpec("needs-foo", "needs_a_missing_package:Tracker")
    monkeypatch.setitem(registry._REGISTRY, "needs-foo", spec)
    with pytest.raises(ValueError, match=r"'needs-foo' cannot be loaded: " + missing):
        Grid(trackers=("needs-foo",), **cell)


def test_the_evaluation_command_explains_a_tracker_it_cannot_build(user_module, tmp_path, capsys):
    argv = ["--trackers", f"{user_module('1.0')}:NeedsArgument", "--scenarios", "S1"]
    argv += ["--runs", "1", "--no-progress", "--out", str(tmp_path / "out")]
    assert evaluate_cli.main(argv) == 2
    error = capsys.readouterr().err
    assert "error: tracker" in error and "cannot be built" in error
    assert "Traceback" not in error


class Answers(TrackerBase):
    """Returns ``answer(position)`` for the centre of the area on every step."""

    name = "answers"

    def __init__(self, answer):
        self.answer = answer

    def reset(self, spec, seed=None):
        self.spec_ = spec

    def update(self, obs):
        return self.answer(np.full(2, self.spec_.area / 2.0))


class Centre(Answers):
    """The centre of the area with a unit variance."""

    def __init__(self):
        super().__init__(lambda position: Estimate(position, np.ones(2)))


BAD_ANSWERS = [
    (lambda p: p, TypeError, r"Answers\.update must return a dgpt_gym\.tracker\.Estimate"),
    (lambda p: Estimate(np.append(p, 0.0), np.ones(2)), ValueError, r"Estimate\.mean as a finite"),
    (lambda p: Estimate(p + np.nan, np.ones(2)), ValueError, r"Estimate\.mean as a finite"),
    (lambda p: Estimate(p, np.eye(2)), ValueError, r"Estimate\.var as a \(2,\) per-axis"),
    (lambda p: Estimate(p, None), ValueError, r"Estimate\.var as a \(2,\)"),
    (lambda p: Estimate(p, 1.0), ValueError, r"Estimate\.var as a \(2,\)"),
    (lambda p: Estimate(p, np.array([1.0, -1e-9])), ValueError, r"Estimate\.var .*not negative"),
    (lambda p: Estimate(p, np.ones(2), np.array([-1.0, 1.0])), ValueError, r"Estimate\.ucb"),
]


@pytest.mark.parametrize("answer, error, message", BAD_ANSWERS)
def test_an_estimate_the_evaluation_cannot_score_names_the_update_and_the_field(
    answer, error, message
):
    env = gym.make("DGPTrack-v0", scenario="S1", max_episode_steps=3)
    with pytest.raises(error, match=message):
        run_episode(env, Answers(answer), seed=0)


def test_a_tracker_that_reports_no_variance_is_scored_without_its_calibration():
    """NaN variances are how a tracker says it has none: its accuracy is scored, its
    calibration is NaN (not 0 % coverage). An infinite variance is a variance (every error
    inside it)."""
    env = gym.make("DGPTrack-v0", scenario="S1", max_episode_steps=5)
    none = run_episode(env, Answers(lambda p: Estimate(p, np.full(2, np.nan))), 0).metrics()
    assert np.isfinite(none["rmse_2d"]) and np.isnan(none["anees"])
    calibration = [key for key in none if "coverage" in key or "nees" in key]
    assert len(calibration) >= 20 and all(np.isnan(none[key]) for key in calibration)
    wide = run_episode(env, Answers(lambda p: Estimate(p, np.full(2, np.inf))), 0).metrics()
    assert wide["rmse_2d"] == none["rmse_2d"] and wide["coverage_3sigma_x"] == 1.0


def test_coverage_leaves_out_the_steps_without_a_half_width():
    """By hand: errors 1, 3, 1 against half-widths 2, 2, NaN cover 1 of the 2 steps that
    have one; an axis without any is NaN."""
    estimates = np.array([[1.0, 0.0], [3.0, 0.0], [1.0, 0.0]])
    half_width = np.array([[2.0, np.nan], [2.0, np.nan], [np.nan, np.nan]])
    covered = coverage(estimates, np.zeros((3, 2)), half_width)
    assert covered[0] == 0.5 and np.isnan(covered[1])
    assert coverage(estimates, np.zeros((3, 2)), 2.0).tolist() == [2 / 3, 1.0]


def test_a_tracker_defined_in_the_running_script_runs(tmp_path, monkeypatch):
    """A class in ``__main__`` (a script, a notebook), registered by name, runs and is
    keyed by the file that defines it."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    monkeypatch.setattr(sys.modules["__main__"], "ScriptTracker", Centre, raising=False)
    registry.register_tracker("script-tracker", "__main__:ScriptTracker")
    assert source_digest("__main__:ScriptTracker") is not None
    grid = Grid(trackers=("script-tracker",), scenarios=("S1",), clutter_rates=(1.0,), runs=1)
    report = run_sweep([grid], tmp_path, workers=1, progress=False)
    assert (report.ran, report.failed) == (1, 0)


def test_the_reset_check_takes_an_oracles_truth_and_skips_compiled_code():
    class Oracle(Answers):
        def reset(self, spec, seed=None, *, truth):
            self.spec_ = spec

    class Compiled(Answers):
        reset = min  # a builtin: no signature to read

    class NoSeed(Answers):
        def reset(self, spec):
            self.spec_ = spec

    for tracker in (Oracle(None), Compiled(None)):
        check_reset_signature(tracker)
    with pytest.raises(TypeError, match=r"NoSeed\.reset must take"):
        check_reset_signature(NoSeed(None))
