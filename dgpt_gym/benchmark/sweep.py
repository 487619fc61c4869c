"""Evaluation sweeps: grids of (tracker, scenario, noise, clutter, seed) runs, executed on a
local process pool or a Dask cluster, stored run by run in a :class:`ResultsStore`.

A :class:`Grid` is trackers x scenarios x noise levels x clutter rates x seeds; a sweep is a
list of grids (the paper's grid is two: the GP trackers on every cell, the hybrid filters
and the CPF on the cell of Fig. 8). Each run is a picklable :class:`RunUnit` that carries
its tracker's entry point, so a worker needs no registry. A run is a pure function of its
unit: local and Dask runs of the same units give identical rows. Runs of one tracker on one
cell are stepped in lockstep in blocks (:func:`run_block`), which batches the GP trackers'
learning and prediction over episodes without changing any run's numbers, which
:func:`verify_store` checks on a sample of a store's runs.
"""

from __future__ import annotations

import inspect
import json
import os
import time
from collections.abc import Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field, replace
from pathlib import Path

import gymnasium as gym
import numpy as np
from threadpoolctl import threadpool_limits
from tqdm.auto import tqdm

import dgpt_gym
from dgpt_gym.benchmark.episodes import (
    WALL_CLOCK_METRICS,
    EpisodeResult,
    run_episodes,
    summarize_runs,
)
from dgpt_gym.benchmark.protocol import PAPER_AS_PRINTED_TRACKERS, PAPER_GP_TRACKERS
from dgpt_gym.benchmark.store import ResultsStore, run_key
from dgpt_gym.benchmark.windows import tuned_kwargs
from dgpt_gym.env import LAYOUT_MODES, TRAJECTORY_MODES
from dgpt_gym.registry import TrackerSpec, source_digest, tracker_ids, tracker_spec
from dgpt_gym.scenarios import get_scenario
from dgpt_gym.tracker import check_reset_signature
from dgpt_gym.validation import check_choice, check_integer, check_real

__all__ = [
    "Grid",
    "Variant",
    "RunUnit",
    "SweepReport",
    "run_unit",
    "run_block",
    "episode_results",
    "make_blocks",
    "run_units",
    "DEFAULT_BATCH_SIZE",
    "run_sweep",
    "summarize_store",
    "VerifyReport",
    "verify_store",
    "sweep_units",
    "stored_metrics",
    "sweep_metrics",
    "on_every_path_mode",
    "QUICK_SWEEP",
    "PAPER_SWEEP",
    "STANDARD_TRACKERS",
]

SCHEDULER_TIMEOUT_S = 5
"""Seconds to wait for a Dask scheduler before giving up with a clear error."""

DEFAULT_BATCH_SIZE = 50
"""Runs per lockstep block (measured, DGPT-RBCM-STGP on S3: 0.079, 0.062, 0.058 and 0.049 s
per episode in blocks of 10, 25, 50 and 100, against 0.25 s alone)."""


@dataclass(frozen=True)
class RunUnit:
    """One episode: a tracker (id, entry point, full constructor arguments), the
    environment's arguments and the seed of both."""

    tracker: str
    entry_point: str
    tracker_kwargs: dict = field(hash=False)
    env_kwargs: dict = field(hash=False)
    seed: int = 0

    @property
    def key(self) -> str:
        return run_key(
            self.tracker,
            self.tracker_kwargs,
            self.env_kwargs,
            self.seed,
            source_digest(self.entry_point),
        )

    @property
    def cell(self) -> tuple[str, str, float, float]:
        """(tracker, scenario, noise_std, clutter_rate)."""
        env = self.env_kwargs
        return (self.tracker, env["scenario"], env["noise_std"], env["clutter_rate"])


def check_buildable(id: str, overrides: dict | None = None) -> None:
    """Build one tracker ``id`` (with ``overrides`` of its registered arguments) and check
    its ``reset`` signature, so that what would fail every run of a sweep fails once, here,
    with a ``ValueError`` naming the tracker and why: an unknown id, a module or class that
    cannot be loaded (e.g. a missing optional dependency), arguments the class does not take
    or needs, a ``reset`` without ``seed=``. An error inside the constructor itself
    propagates as it is."""
    spec = tracker_spec(id)
    try:
        make = spec.load()
    except (ImportError, AttributeError) as error:
        raise ValueError(f"tracker {id!r} cannot be loaded: {error}") from error
    kwargs = {**spec.kwargs, **(overrides or {})}
    try:
        signature = inspect.signature(make)
    except (TypeError, ValueError):  # no signature to read: the call below tells
        signature = None
    if signature is not None:
        try:
            signature.bind(**kwargs)
        except TypeError as error:
            hint = "; a class named by its path is built without arguments" if ":" in id else ""
            raise ValueError(
                f"tracker {id!r} cannot be built with the arguments {kwargs}: {error}{hint}"
            ) from error
    tracker = make(**kwargs)
    try:
        check_reset_signature(tracker)
    except TypeError as error:
        raise ValueError(f"tracker {id!r}: {error}") from error


@dataclass(frozen=True)
class Variant:
    """A registered tracker with some constructor arguments changed, run under its own
    ``name``: one arm of an ablation. ``overrides`` (pairs of argument name and value) are
    applied after the registered arguments and the tuned window of ``base``; for example
    ``Variant("dgpt-rbcm/no-turn-modes", "dgpt-rbcm", (("turn_rates", ()),))``. The name
    must not be a registered id, and the arguments are checked by building one tracker."""

    name: str
    base: str
    overrides: tuple[tuple[str, object], ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"name must be a non-empty string; got {self.name!r}")
        if self.name in tracker_ids():
            raise ValueError(
                f"name must not be a registered tracker id (its runs would be reported as "
                f"that tracker's); got {self.name!r}"
            )
        check_buildable(self.base, dict(self.overrides))


@dataclass(frozen=True)
class Grid:
    """Every tracker on every (scenario, noise_std, clutter_rate) cell, seeds
    ``first_seed .. first_seed + runs - 1`` (the same seeds give every tracker the same
    measurements). A tracker is a registered id or a :class:`Variant` of one. With
    ``tuned_windows`` the GP trackers use the window tuned for the scenario
    (:mod:`dgpt_gym.benchmark.tuning`). ``trajectory``: the environment's path
    mode (:data:`dgpt_gym.env.TRAJECTORY_MODES`); ``"fixed"``, the paper's reference
    paths, leaves it out of the runs' environment arguments, so their keys in the store are
    those of the grids without the field. ``layout``: where each run's sensor layout comes
    from (:data:`dgpt_gym.env.LAYOUT_MODES`); ``"per_episode"`` runs seed s in layout s,
    adding ``layout_seed`` to every run's environment arguments (seed 0's too, whose layout
    is the environment's default), and ``"fixed"`` leaves it out."""

    trackers: tuple[str | Variant, ...]
    scenarios: tuple[str, ...] = ("S1", "S2", "S3", "S4")
    noise_levels: tuple[float, ...] = (1.0,)
    clutter_rates: tuple[float, ...] = (1.0, 5.0)
    runs: int = 10
    first_seed: int = 0
    tuned_windows: bool = True
    trajectory: str = "fixed"
    layout: str = "fixed"

    def __post_init__(self) -> None:
        for name in ("trackers", "scenarios", "noise_levels", "clutter_rates"):
            if not isinstance(getattr(self, name), Sequence) or not getattr(self, name):
                raise ValueError(
                    f"{name} must be a non-empty sequence; got {getattr(self, name)!r}"
                )
        for tracker in self.trackers:
            if not isinstance(tracker, Variant):
                check_buildable(tracker)
        for scenario in self.scenarios:
            get_scenario(scenario)
        for noise in self.noise_levels:
            check_real("noise_std", noise, low=0.0)
        for clutter in self.clutter_rates:
            check_real("clutter_rate", clutter, low=0.0)
        check_integer("runs", self.runs, low=1)
        check_integer("first_seed", self.first_seed, low=0)
        check_choice("trajectory", self.trajectory, TRAJECTORY_MODES)
        check_choice("layout", self.layout, LAYOUT_MODES)

    def units(self) -> list[RunUnit]:
        units = []
        for scenario in self.scenarios:
            for noise in self.noise_levels:
                for clutter in self.clutter_rates:
                    env_kwargs = {
                        "scenario": scenario,
                        "noise_std": float(noise),
                        "clutter_rate": float(clutter),
                    }
                    if self.trajectory != "fixed":
                        env_kwargs["trajectory"] = self.trajectory
                    for tracker in self.trackers:
                        name, base, overrides = (
                            (tracker.name, tracker.base, tracker.overrides)
                            if isinstance(tracker, Variant)
                            else (tracker, tracker, ())
                        )
                        spec = tracker_spec(base)
                        kwargs = dict(spec.kwargs)
                        if self.tuned_windows:
                            kwargs.update(tuned_kwargs(base, scenario))
                        kwargs.update(overrides)
                        for seed in range(self.first_seed, self.first_seed + self.runs):
                            run_env_kwargs = env_kwargs
                            if self.layout == "per_episode":
                                run_env_kwargs = {**env_kwargs, "layout_seed": seed}
                            units.append(
                                RunUnit(name, spec.entry_point, kwargs, run_env_kwargs, seed)
                            )
        return units


STANDARD_TRACKERS = ("pda", "imm-pda", "clairvoyant")
"""The field's standard trackers (KF-PDA, IMM-PDA) and the clairvoyant accuracy floor."""

QUICK_SWEEP = (
    Grid(
        trackers=(
            "gp",
            "dgpt-rbcm",
            "dgpt-gpoe",
            "dgpt-rbcm-trend",
            "hybrid",
            "hybrid-trend",
            "cpf",
            "imm-pda",
            "clairvoyant",
        ),
        runs=10,
    ),
)
"""``scripts/evaluate.py`` with no options (and ``make evaluate``): 1-2 minutes on 2
cores. The paper's approaches with the default model (the NCV GP in state-space form,
conditioned on the silence of the sensors in coverage gaps), the pooled SE trend of dgpt-gym
0.8 (``-trend``), the hybrid filter around each DGPT-RBCM, the
CPF, IMM-PDA and the clairvoyant floor."""

PAPER_SWEEP = (
    Grid(
        trackers=PAPER_GP_TRACKERS + STANDARD_TRACKERS,
        noise_levels=(1.0, 2.0, 4.0),
        runs=100,
    ),
    Grid(trackers=PAPER_AS_PRINTED_TRACKERS, noise_levels=(1.0,), runs=100),
    Grid(
        trackers=("hybrid", "hybrid-trend", "hybrid-paper", "cpf"),
        noise_levels=(1.0,),
        clutter_rates=(1.0, 5.0),
        runs=100,
    ),
)
"""``--paper``: Tables II-IX (the paper's three approaches with the default model, and with
the pooled SE trend and temporal or spatio-temporal inputs; sigma_z in {1, 2, 4}, clutter 1
and 5) with the standard trackers and the clairvoyant floor on every
cell; the paper's model as printed (``-paper`` ids) at sigma_z = 1; and the hybrid filter
around DGPT-RBCM with each model, and the CPF, at sigma_z = 1 and both clutter rates (Fig. 8
is the clutter-5 cell); 100 Monte Carlo runs each."""


def _single_threaded_blas() -> None:
    """Worker initializer: one BLAS thread per process. The GP matrices are tiny, and
    several processes each running a multi-threaded BLAS on the same cores spin against
    each other (measured: 2 workers ran 5x slower than 1 without this)."""

    threadpool_limits(limits=1)


def sweep_units(grids: Iterable[Grid]) -> list[RunUnit]:
    """The units of all ``grids``, without repeats (grids may overlap)."""
    units, seen = [], set()
    for grid in grids:
        for unit in grid.units():
            if unit.key not in seen:
                seen.add(unit.key)
                units.append(unit)
    return units


def run_unit(unit: RunUnit) -> dict:
    """Run one episode; never raises. Returns ``status`` ("ok" or "failed"), ``metrics``
    (:meth:`EpisodeResult.metrics`), ``error`` and the wall ``runtime_s``."""
    return run_block((unit,))[0]


def episode_results(units: Sequence[RunUnit]) -> list[EpisodeResult]:
    """The per-step results of ``units`` (one tracker's runs, any cells), built from their
    entry point and arguments and run in lockstep
    (:func:`dgpt_gym.benchmark.episodes.run_episodes`); the environments are closed."""
    make = TrackerSpec(units[0].tracker, units[0].entry_point).load()
    trackers = [make(**unit.tracker_kwargs) for unit in units]
    envs = [gym.make("DGPTrack-v0", **unit.env_kwargs) for unit in units]
    try:
        return run_episodes(envs, trackers, [unit.seed for unit in units])
    finally:
        for env in envs:
            env.close()


def run_block(units: Sequence[RunUnit]) -> list[dict]:
    """Run the episodes of ``units``, which share tracker and environment settings but
    their seeds and layouts (:func:`make_blocks`), in lockstep
    (:func:`dgpt_gym.benchmark.episodes.run_episodes`); never raises. One outcome per unit
    as in :func:`run_unit`; ``runtime_s`` is the block's wall time divided by its size. If
    the block raises, each unit is run alone, so one failing run is recorded as failed and
    the others as they would be anyway (a run's numbers do not depend on its block)."""

    started = time.perf_counter()
    try:
        if any(_block_key(unit) != _block_key(units[0]) for unit in units):
            raise ValueError(
                "a block's units must share tracker and environment settings (all but the "
                "seed and layout_seed)"
            )
        metrics = [result.metrics() for result in episode_results(units)]
    except Exception as exception:  # a failed run is recorded, the sweep goes on
        if len(units) > 1:
            return [outcome for unit in units for outcome in run_block((unit,))]
        error = f"{type(exception).__name__}: {exception}"
        return [_outcome("failed", None, error, time.perf_counter() - started)]
    runtime = (time.perf_counter() - started) / len(units)
    return [_outcome("ok", row, None, runtime) for row in metrics]


def _outcome(status: str, metrics: dict | None, error: str | None, runtime: float) -> dict:
    return {"status": status, "metrics": metrics, "error": error, "runtime_s": runtime}


def _block_key(unit: RunUnit) -> str:
    """What the runs of a block share: everything but the seed and the sensor layout (each
    episode is reset with its own environment and tracker, so layouts may differ)."""
    env_kwargs = {key: value for key, value in unit.env_kwargs.items() if key != "layout_seed"}
    return json.dumps(
        [unit.tracker, unit.entry_point, unit.tracker_kwargs, env_kwargs], sort_keys=True
    )


def make_blocks(units: Sequence[RunUnit], batch_size: int) -> list[tuple[RunUnit, ...]]:
    """Split ``units`` into blocks of at most ``batch_size`` runs of one tracker on one cell
    (same settings, different seeds and perhaps layouts), keeping their order; blocks run in
    lockstep."""
    check_integer("batch_size", batch_size, low=1)
    by_setting: dict[str, list[RunUnit]] = {}
    for unit in units:
        by_setting.setdefault(_block_key(unit), []).append(unit)
    return [
        tuple(same[start : start + batch_size])
        for same in by_setting.values()
        for start in range(0, len(same), batch_size)
    ]


@dataclass(frozen=True)
class SweepReport:
    """What a call of :func:`run_sweep` did: units of the sweep, found already finished in
    the store, run now, and failed now (``errors``: the first few, with their run)."""

    total: int
    already_finished: int
    ran: int
    failed: int
    errors: tuple[str, ...] = ()


def run_units(
    units: list[RunUnit],
    workers: int = 1,
    progress: bool = True,
    batch_size: int = DEFAULT_BATCH_SIZE,
) -> list[dict]:
    """:func:`run_unit` of every unit, in order, on ``workers`` local processes in blocks of
    ``batch_size``, without a store (for short searches such as
    :func:`dgpt_gym.benchmark.tuning.tune_windows`)."""

    index = {id(unit): i for i, unit in enumerate(units)}
    outcomes: list[dict] = [{}] * len(units)
    with tqdm(total=len(units), desc="runs", disable=not progress) as bar:
        for block, block_outcomes in _local_results(make_blocks(units, batch_size), workers):
            for unit, outcome in zip(block, block_outcomes):
                outcomes[index[id(unit)]] = outcome
            bar.update(len(block))
    return outcomes


def _local_results(blocks: list[tuple[RunUnit, ...]], workers: int):
    """Yield ``(block, outcomes)`` as blocks finish on a process pool (in-process for 1)."""
    if workers <= 1:
        for block in blocks:
            yield block, run_block(block)
        return

    pool = ProcessPoolExecutor(max_workers=workers, initializer=_single_threaded_blas)
    try:
        futures = {pool.submit(run_block, block): block for block in blocks}
        for future in as_completed(futures):
            yield futures[future], future.result()
    finally:  # on Ctrl-C or an error, drop what has not started
        pool.shutdown(wait=True, cancel_futures=True)


def _dask_results(blocks: list[tuple[RunUnit, ...]], scheduler: str):
    """Yield ``(block, outcomes)`` as blocks finish on the Dask cluster at ``scheduler``."""
    try:
        from distributed import Client, as_completed
    except ImportError as error:  # pragma: no cover - depends on the install
        raise ImportError(
            "--scheduler needs dask.distributed: pip install 'dgpt-gym[cluster]'"
        ) from error
    try:
        client = Client(scheduler, timeout=SCHEDULER_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError, TypeError) as error:
        raise ValueError(
            f"scheduler {scheduler!r} cannot be reached within {SCHEDULER_TIMEOUT_S} s "
            f"(expected the address of a running Dask scheduler, e.g. tcp://host:8786): {error}"
        ) from None
    with client:
        client.run(_single_threaded_blas)
        futures = client.map(run_block, blocks, pure=False)
        owner = {future.key: block for future, block in zip(futures, blocks)}
        try:
            for future in as_completed(futures):
                block = owner[future.key]
                try:
                    outcomes = future.result()
                except Exception as error:  # a lost worker: record, go on
                    lost = f"{type(error).__name__}: {error}"
                    outcomes = [_outcome("failed", None, lost, float("nan")) for _ in block]
                yield block, outcomes
        finally:
            client.cancel(futures)


def run_sweep(
    grids: Iterable[Grid],
    out: str | Path,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool = True,
    batch_size: int = DEFAULT_BATCH_SIZE,
) -> SweepReport:
    """Run every unit of ``grids`` not yet finished in the store at ``out`` by this version
    of dgpt-gym, storing each outcome as soon as it arrives.

    Args:
        grids: the sweep.
        out: output folder; the database is ``out/results.sqlite``.
        workers: local worker processes (default: all cores; 1 runs in this process).
            Ignored with ``scheduler``.
        scheduler: address of a running Dask scheduler (``tcp://host:8786``) to run on
            instead of the local pool.
        progress: show a tqdm bar over runs with an ETA.
        batch_size: runs of one tracker on one cell stepped in lockstep per task
            (:func:`make_blocks`); a run's numbers do not depend on it, only the speed
            and how much an interruption loses (the blocks in flight).
    """

    units = sweep_units(grids)
    if workers is None:
        workers = os.cpu_count() or 1
    check_integer("workers", workers, low=1)
    failed, errors = 0, []

    with ResultsStore(out) as store:
        finished = store.finished_keys(dgpt_gym.__version__)  # another version's rows are re-run
        todo = [unit for unit in units if unit.key not in finished]
        blocks = make_blocks(todo, batch_size)
        results = _dask_results(blocks, scheduler) if scheduler else _local_results(blocks, workers)
        with tqdm(
            total=len(units), initial=len(units) - len(todo), desc="runs", disable=not progress
        ) as bar:
            for block, outcomes in results:
                for unit, outcome in zip(block, outcomes):
                    store.add(unit, **outcome)
                    if outcome["status"] == "failed":
                        failed += 1
                        if len(errors) < 5:
                            errors.append(f"{unit.cell} seed {unit.seed}: {outcome['error']}")
                        bar.set_postfix(failed=failed)
                bar.update(len(block))
    return SweepReport(len(units), len(units) - len(todo), len(todo), failed, tuple(errors))


@dataclass(frozen=True)
class VerifyReport:
    """What :func:`verify_store` found: ``checked`` runs re-run, ``other_versions`` finished
    runs of the sweep stored by another dgpt-gym version (not checked, unless
    ``any_version``: then ``checked_other_versions`` of them were), and one line per run
    whose metrics differ."""

    checked: int
    other_versions: int
    mismatches: tuple[str, ...]
    checked_other_versions: int = 0


def _differing_metrics(stored: dict, rerun: dict) -> list[str]:
    """The metrics that differ between a stored run and its re-run, as "key stored ->
    re-run" (NaN equals NaN; the wall-clock metrics aside)."""
    differing = []
    for key in sorted((set(stored) | set(rerun)) - set(WALL_CLOCK_METRICS)):
        old, new = stored.get(key), rerun.get(key)
        same = old == new or (
            isinstance(old, float) and isinstance(new, float) and np.isnan(old) and np.isnan(new)
        )
        if not same:
            differing.append(f"{key} {old!r} -> {new!r}")
    return differing


def verify_store(
    grids: Iterable[Grid],
    out: str | Path,
    count: int,
    workers: int = 1,
    progress: bool = True,
    seed: int = 0,
    batch_size: int = DEFAULT_BATCH_SIZE,
    any_version: bool = False,
) -> VerifyReport:
    """Re-run ``count`` of the sweep's runs that this dgpt-gym version finished in the store
    at ``out``, chosen at random (a ``numpy.random.Generator`` seeded with ``seed``), and
    compare every metric with the stored one to the last bit, the wall-clock ones aside.
    With ``any_version`` the runs are drawn from every version's: a study that reads runs
    an earlier version stored, whose trackers did not change, shows that they are this
    code's numbers.

    A difference means the store holds numbers the installed code does not produce: rows
    from a run interrupted across a code change, another machine's floating point, or a
    run that depends on something besides its unit (its block, the worker). The re-runs
    form their own lockstep blocks, so this also checks that a run's numbers do not
    depend on its block.
    """
    check_integer("count", count, low=1)
    units = {unit.key: unit for unit in sweep_units(grids)}
    with ResultsStore(out) as store:
        rows = store.rows(set(units), status="ok")
    drawable = [row for row in rows if any_version or row["version"] == dgpt_gym.__version__]
    if not drawable:
        by = "" if any_version else f" by dgpt-gym {dgpt_gym.__version__}"
        raise ValueError(
            f"the store at {out} holds no finished run of this sweep{by}; run it first"
        )
    picked = np.random.default_rng(seed).choice(
        len(drawable), size=min(count, len(drawable)), replace=False
    )
    chosen = [drawable[index] for index in sorted(picked)]
    outcomes = run_units([units[row["run_key"]] for row in chosen], workers, progress, batch_size)
    mismatches = []
    for row, outcome in zip(chosen, outcomes):
        if outcome["status"] != "ok":
            differing = [f"the re-run failed: {outcome['error']}"]
        else:
            differing = _differing_metrics(row["metrics"], outcome["metrics"])
        if differing:
            mismatches.append(
                f"{row['tracker']} {row['scenario']} sigma_z {row['noise_std']:g} clutter"
                f" {row['clutter_rate']:g} seed {row['seed']}: "
                + "; ".join(differing[:3])
                + (f"; and {len(differing) - 3} more" if len(differing) > 3 else "")
            )

    def others(chosen_rows):
        return sum(row["version"] != dgpt_gym.__version__ for row in chosen_rows)

    return VerifyReport(len(chosen), others(rows), tuple(mismatches), others(chosen))


def stored_metrics(grid: Grid, out: str | Path) -> dict[tuple, list[dict]]:
    """The metrics of ``grid``'s runs in the store at ``out``, by cell (:attr:`RunUnit.cell`),
    in seed order; a ValueError names the first run that is missing or failed (run the grid
    with :func:`run_sweep` first)."""
    units = grid.units()
    with ResultsStore(out) as store:
        rows = {row["run_key"]: row for row in store.rows({unit.key for unit in units})}
    metrics: dict[tuple, list[dict]] = {}
    for unit in units:
        row = rows.get(unit.key)
        if row is None or row["status"] != "ok":
            state = "not stored" if row is None else "failed"
            raise ValueError(
                f"run {unit.cell} seed {unit.seed} ({grid.trajectory} paths, {grid.layout} "
                f"layout) is {state} in {out}"
            )
        metrics.setdefault(unit.cell, []).append(row["metrics"])
    return metrics


def on_every_path_mode(grid: Grid) -> dict[str, Grid]:
    """``grid`` on the reference paths and on random ones (each of
    :data:`~dgpt_gym.env.TRAJECTORY_MODES`, whatever ``grid``'s own), by mode: the same
    cells and seeds, so that each mode's runs pair by seed across trackers."""
    return {mode: replace(grid, trajectory=mode) for mode in TRAJECTORY_MODES}


def sweep_metrics(
    grid: Grid, out: str | Path, workers: int | None = None, progress: bool = True
) -> tuple[SweepReport, dict[tuple, list[dict]]]:
    """Run ``grid`` (:func:`run_sweep`, resuming what the store at ``out`` holds) and return
    what the run did and :func:`stored_metrics`; a RuntimeError, with the first failure, if
    any run failed."""
    done = run_sweep([grid], out, workers, progress=progress)
    if done.failed:
        raise RuntimeError(f"{done.failed} runs failed, e.g. {done.errors[0]}")
    return done, stored_metrics(grid, out)


def summarize_store(grids: Iterable[Grid], out: str | Path) -> tuple[list[dict], list[dict]]:
    """Per-cell summaries (:func:`summarize_runs`, seeds in order, and the dgpt-gym
    ``versions`` that produced the runs) of the sweep's finished runs in the store at
    ``out``, in the grids' order, and the stored rows of its failed runs. The grids must
    share one path mode and one layout mode (a cell names neither)."""
    grids = list(grids)
    for name, what in (("trajectory", "path mode"), ("layout", "layout mode")):
        modes = sorted({getattr(grid, name) for grid in grids})
        if len(modes) > 1:
            raise ValueError(
                f"grids must share one {name} to be summarised together; got {modes}: "
                f"summarise each {what} on its own"
            )
    units = sweep_units(grids)
    keys = {unit.key for unit in units}
    with ResultsStore(out) as store:
        stored = {row["run_key"]: row for row in store.rows(keys)}
    by_cell: dict[tuple, list[dict]] = {}
    kwargs_of_cell: dict[tuple, dict] = {}
    failures = []
    for unit in units:
        row = stored.get(unit.key)
        kwargs_of_cell.setdefault(unit.cell, unit.tracker_kwargs)
        if row is None:
            continue
        if row["status"] != "ok":
            failures.append(row)
            continue
        by_cell.setdefault(unit.cell, []).append({"seed": unit.seed, **row["metrics"]})
    versions_of_cell: dict[tuple, set[str]] = {}
    for unit in units:
        row = stored.get(unit.key)
        if row is not None and row["status"] == "ok":
            versions_of_cell.setdefault(unit.cell, set()).add(row["version"])
    summaries = []
    for cell, runs in by_cell.items():
        tracker, scenario, noise, clutter = cell
        # None: the tracker's own default window (the state-space trackers': 20) or none
        window = kwargs_of_cell[cell].get("window")
        summaries.append(
            {
                "tracker": tracker,
                "scenario": scenario,
                "noise_std": noise,
                "clutter_rate": clutter,
                "window": window,
                **summarize_runs(sorted(runs, key=lambda run: run["seed"])),
                "versions": " ".join(sorted(versions_of_cell[cell])),
            }
        )
    return summaries, failures
