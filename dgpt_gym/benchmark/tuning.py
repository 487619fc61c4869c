"""Window lengths tuned per scenario, as the paper tuned them (Sec. VII-B: "the lengths of
sliding windows in different trajectories are carefully tuned").

:func:`tune_windows` runs a grid search on *training* seeds (1000 onwards, disjoint from
the evaluation seeds 0 onwards) at sigma_z = 1 and both clutter rates, and picks for every
tracker and scenario the window with the lowest NRMSE averaged over axes, clutter rates and
seeds. The result is stored in ``tuned_windows.json`` beside this module and used by
:mod:`dgpt_gym.benchmark.sweep`. Regenerate it with
``python scripts/evaluate.py --tune-windows``.
"""

from __future__ import annotations

import json
from collections.abc import Iterable

import numpy as np

from dgpt_gym.benchmark.protocol import TRAINING_SEEDS
from dgpt_gym.benchmark.sweep import RunUnit, run_units
from dgpt_gym.registry import tracker_spec

__all__ = [
    "WINDOW_GRID",
    "tune_windows",
    "grid_search",
    "BASELINE_CANDIDATES",
    "baseline_tuning_markdown",
]

WINDOW_GRID = (2, 3, 4, 5, 6, 8)
"""Window lengths the search tries."""


def tune_windows(
    tracker_ids: Iterable[str],
    scenarios: Iterable[str] = ("S1", "S2", "S3", "S4"),
    windows: Iterable[int] = WINDOW_GRID,
    seeds: Iterable[int] = TRAINING_SEEDS,
    clutter_rates: Iterable[float] = (1.0, 5.0),
    noise_std: float = 1.0,
    workers: int = 1,
    progress: bool = True,
    trajectories: Iterable[str] = ("fixed", "random"),
) -> tuple[dict[str, dict[str, int]], list[dict]]:
    """Grid search of the window length on the scenarios' reference paths and on random
    paths (a window must not be fitted to four paths); returns the best windows and every
    grid row (tracker, scenario, window, mean NRMSE)."""

    tracker_ids, scenarios = list(tracker_ids), list(scenarios)
    windows, seeds, clutter_rates = list(windows), list(seeds), list(clutter_rates)
    trajectories = list(trajectories)
    keys = [(t, s, w) for t in tracker_ids for s in scenarios for w in windows]
    units = [
        RunUnit(
            t,
            tracker_spec(t).entry_point,
            {**tracker_spec(t).kwargs, "window": w},
            {
                "scenario": s,
                "noise_std": float(noise_std),
                "clutter_rate": float(c),
                "trajectory": trajectory,
            },
            seed,
        )
        for t, s, w in keys
        for trajectory in trajectories
        for c in clutter_rates
        for seed in seeds
    ]
    outcomes = run_units(units, workers, progress)
    failed = [o["error"] for o in outcomes if o["status"] != "ok"]
    if failed:
        raise RuntimeError(f"{len(failed)} runs of the window search failed, e.g. {failed[0]}")
    results = [o["metrics"] for o in outcomes]
    per_key = len(trajectories) * len(clutter_rates) * len(seeds)
    rows, best = [], {}
    for index, (tracker, scenario, window) in enumerate(keys):
        chunk = results[index * per_key : (index + 1) * per_key]
        score = float(np.mean([0.5 * (r["nrmse_x"] + r["nrmse_y"]) for r in chunk]))
        rows.append({"tracker": tracker, "scenario": scenario, "window": window, "nrmse": score})
        current = best.setdefault(tracker, {}).get(scenario)
        if current is None or score < current[1]:
            best[tracker][scenario] = (window, score)
    return {t: {s: w for s, (w, _) in by.items()} for t, by in best.items()}, rows


def _imm_candidates() -> list[dict]:
    candidates = []
    for stay in (0.9, 0.95, 0.98):
        for low, high in ((0.1, 20.0), (0.5, 50.0), (1.0, 100.0)):
            candidates.append(
                {
                    "turn_rates": [0.0, 0.0],
                    "noise_diff_coeffs": [low, high],
                    "mode_stay_probability": stay,
                }
            )
            for rates in ((0.25,), (0.35,), (0.45,), (0.52,), (0.35, 0.52)):
                turn_rates = [0.0, 0.0] + [sign * w for w in rates for sign in (1.0, -1.0)]
                candidates.append(
                    {
                        "turn_rates": turn_rates,
                        "noise_diff_coeffs": [low, high] + [low] * (len(turn_rates) - 2),
                        "mode_stay_probability": stay,
                    }
                )
    return candidates


BASELINE_CANDIDATES = {
    "pda": [
        {"association": association, "noise_diff_coeff": q}
        for association in ("multi", "single")
        for q in (0.5, 2.0, 5.0, 20.0, 50.0, 100.0)
    ],
    "imm-pda": _imm_candidates(),
}
"""The settings :func:`grid_search` compares for the model-based baselines
(``scripts/evaluate.py --tune-baselines``); the winners are the classes' defaults."""


def grid_search(
    tracker_id: str,
    candidates: Iterable[dict],
    scenarios: Iterable[str] = ("S1", "S2", "S3", "S4"),
    seeds: Iterable[int] = TRAINING_SEEDS,
    clutter_rates: Iterable[float] = (1.0, 5.0),
    trajectories: Iterable[str] = ("fixed", "random"),
    noise_std: float = 1.0,
    workers: int = 1,
    progress: bool = True,
) -> list[dict]:
    """Score every candidate set of constructor arguments of ``tracker_id`` on training
    seeds, fixed and random paths: one row per candidate and scenario with the mean NRMSE
    (over axes, clutter rates, path modes and seeds) and the mean 2-D RMSE, and a row with
    scenario ``"all"`` averaging the scenarios. The model-based baselines take the
    candidate with the lowest ``"all"`` NRMSE as their one documented setting."""

    spec = tracker_spec(tracker_id)
    candidates, scenarios = [dict(c) for c in candidates], list(scenarios)
    cells = [
        (s, float(c), trajectory, seed)
        for s in scenarios
        for c in clutter_rates
        for trajectory in trajectories
        for seed in seeds
    ]
    units = [
        RunUnit(
            tracker_id,
            spec.entry_point,
            {**spec.kwargs, **candidate},
            {
                "scenario": s,
                "noise_std": float(noise_std),
                "clutter_rate": c,
                "trajectory": trajectory,
            },
            seed,
        )
        for candidate in candidates
        for s, c, trajectory, seed in cells
    ]
    outcomes = run_units(units, workers, progress)
    failed = [o["error"] for o in outcomes if o["status"] != "ok"]
    if failed:
        raise RuntimeError(f"{len(failed)} runs of the grid search failed, e.g. {failed[0]}")
    rows = []
    for index, candidate in enumerate(candidates):
        chunk = outcomes[index * len(cells) : (index + 1) * len(cells)]
        by_scenario: dict[str, list[dict]] = {}
        for (scenario, *_), outcome in zip(cells, chunk):
            by_scenario.setdefault(scenario, []).append(outcome["metrics"])
        scores = {
            scenario: (
                float(np.mean([0.5 * (m["nrmse_x"] + m["nrmse_y"]) for m in runs])),
                float(np.mean([np.hypot(m["rmse_x"], m["rmse_y"]) for m in runs])),
            )
            for scenario, runs in by_scenario.items()
        }
        for scenario, (nrmse, rmse) in scores.items():
            rows.append(
                {"candidate": candidate, "scenario": scenario, "nrmse": nrmse, "rmse": rmse}
            )
        rows.append(
            {
                "candidate": candidate,
                "scenario": "all",
                "nrmse": float(np.mean([v[0] for v in scores.values()])),
                "rmse": float(np.mean([v[1] for v in scores.values()])),
            }
        )
    return rows


def baseline_tuning_markdown(results: dict[str, list[dict]], command: str) -> str:
    """The grid searches of the model-based baselines as Markdown: per tracker, every
    candidate's NRMSE (%) per scenario and overall, best first."""
    lines = [
        "# Tuning of the model-based baselines",
        "",
        f"Generated by `{command}`: every candidate on training seeds"
        f" {TRAINING_SEEDS.start}-{TRAINING_SEEDS.stop - 1}, S1-S4, fixed and random paths,"
        " clutter rates 1 and 5, sigma_z = 1 (disjoint from the evaluation seeds 0-99). Cells:"
        " mean NRMSE % over axes, clutter rates, path modes and seeds; the last column the mean"
        " 2-D RMSE, m. The first row of each table is the tracker's default.",
        "",
    ]
    for tracker, rows in results.items():
        candidates = []
        for row in rows:
            if row["candidate"] not in candidates:
                candidates.append(row["candidate"])
        scenarios = list(dict.fromkeys(row["scenario"] for row in rows))
        score = {(json.dumps(r["candidate"]), r["scenario"]): r for r in rows}
        candidates.sort(key=lambda c: score[(json.dumps(c), "all")]["nrmse"])
        lines += [
            f"## {tracker}",
            "",
            "| setting | " + " | ".join(scenarios) + " | RMSE all, m |",
            "|---|" + "---|" * (len(scenarios) + 1),
        ]
        for candidate in candidates:
            key = json.dumps(candidate)
            cells = [f"{100 * score[(key, s)]['nrmse']:.3f}" for s in scenarios]
            setting = ", ".join(f"`{k}` = {v}" for k, v in candidate.items())
            lines.append(
                f"| {setting} | " + " | ".join(cells) + f" | {score[(key, 'all')]['rmse']:.2f} |"
            )
        lines.append("")
    return "\n".join(lines)
