"""Window lengths tuned per scenario, as the paper tuned them (Sec. VII-B: "the lengths of
sliding windows in different trajectories are carefully tuned").

:func:`tune_windows` runs a grid search on *training* seeds (1000 onwards, disjoint from
the evaluation seeds 0 onwards) at sigma_z = 1 and both clutter rates, and picks for every
tracker and scenario the window with the lowest NRMSE averaged over axes, clutter rates and
seeds. The result is stored in ``tuned_windows.json`` beside this module and used by
:mod:`dgpt_gym.sweep`. Regenerate it with
``python scripts/evaluate.py --tune-windows``.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Iterable
from pathlib import Path

import numpy as np

__all__ = [
    "TUNED_WINDOWS_PATH",
    "TRAINING_SEEDS",
    "tuned_windows",
    "tuned_kwargs",
    "tune_windows",
    "save_tuned_windows",
]

TUNED_WINDOWS_PATH = Path(__file__).with_name("tuned_windows.json")
TRAINING_SEEDS = range(1000, 1005)
WINDOW_GRID = (2, 3, 4, 5, 6, 8)


@functools.lru_cache(maxsize=1)
def tuned_windows() -> dict[str, dict[str, int]]:
    """``{tracker id: {scenario: window}}`` from ``tuned_windows.json`` (empty if absent)."""
    if not TUNED_WINDOWS_PATH.exists():
        return {}
    return json.loads(TUNED_WINDOWS_PATH.read_text())["windows"]


WINDOW_SOURCES = {"hybrid": "dgpt-rbcm", "hybrid-paper": "dgpt-rbcm"}
"""Trackers that wrap a DGPT use the window tuned for it."""


def tuned_kwargs(tracker_id: str, scenario: str) -> dict:
    """``{"window": C}`` for a tracker with a tuned window on ``scenario``, else ``{}``."""
    source = WINDOW_SOURCES.get(tracker_id, tracker_id)
    window = tuned_windows().get(source, {}).get(scenario)
    return {} if window is None else {"window": int(window)}


def tune_windows(
    tracker_ids: Iterable[str],
    scenarios: Iterable[str] = ("S1", "S2", "S3", "S4"),
    windows: Iterable[int] = WINDOW_GRID,
    seeds: Iterable[int] = TRAINING_SEEDS,
    clutter_rates: Iterable[float] = (1.0, 5.0),
    noise_std: float = 1.0,
    workers: int = 1,
    progress: bool = True,
) -> tuple[dict[str, dict[str, int]], list[dict]]:
    """Grid search of the window length; returns the best windows and every grid row
    (tracker, scenario, window, mean NRMSE)."""
    from dgpt_gym.registry import tracker_spec
    from dgpt_gym.sweep import RunUnit, run_units

    tracker_ids, scenarios = list(tracker_ids), list(scenarios)
    windows, seeds, clutter_rates = list(windows), list(seeds), list(clutter_rates)
    keys = [(t, s, w) for t in tracker_ids for s in scenarios for w in windows]
    units = [
        RunUnit(
            t,
            tracker_spec(t).entry_point,
            {**tracker_spec(t).kwargs, "window": w},
            {"scenario": s, "noise_std": float(noise_std), "clutter_rate": float(c)},
            seed,
        )
        for t, s, w in keys
        for c in clutter_rates
        for seed in seeds
    ]
    outcomes = run_units(units, workers, progress)
    failed = [o["error"] for o in outcomes if o["status"] != "ok"]
    if failed:
        raise RuntimeError(f"{len(failed)} runs of the window search failed, e.g. {failed[0]}")
    results = [o["metrics"] for o in outcomes]
    per_key = len(clutter_rates) * len(seeds)
    rows, best = [], {}
    for index, (tracker, scenario, window) in enumerate(keys):
        chunk = results[index * per_key : (index + 1) * per_key]
        score = float(np.mean([0.5 * (r["nrmse_x"] + r["nrmse_y"]) for r in chunk]))
        rows.append({"tracker": tracker, "scenario": scenario, "window": window, "nrmse": score})
        current = best.setdefault(tracker, {}).get(scenario)
        if current is None or score < current[1]:
            best[tracker][scenario] = (window, score)
    return {t: {s: w for s, (w, _) in by.items()} for t, by in best.items()}, rows


def save_tuned_windows(
    best: dict[str, dict[str, int]], rows: list[dict], path: Path = TUNED_WINDOWS_PATH
) -> None:
    """Write the tuned windows and the grid they came from."""
    path.write_text(json.dumps({"windows": best, "grid": rows}, indent=1) + "\n")
    tuned_windows.cache_clear()
