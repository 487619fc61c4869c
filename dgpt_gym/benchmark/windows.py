"""The tuned window lengths: ``tuned_windows.json`` beside this module, read and written.

The file is produced by :func:`dgpt_gym.benchmark.tuning.tune_windows` (``python
scripts/evaluate.py --tune-windows``) and applied by :mod:`dgpt_gym.benchmark.sweep`.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

__all__ = [
    "TUNED_WINDOWS_PATH",
    "WINDOW_SOURCES",
    "tuned_windows",
    "tuned_kwargs",
    "save_tuned_windows",
]

TUNED_WINDOWS_PATH = Path(__file__).with_name("tuned_windows.json")


@functools.lru_cache(maxsize=1)
def tuned_windows() -> dict[str, dict[str, int]]:
    """``{tracker id: {scenario: window}}`` from ``tuned_windows.json`` (empty if absent)."""
    if not TUNED_WINDOWS_PATH.exists():
        return {}
    return json.loads(TUNED_WINDOWS_PATH.read_text())["windows"]


WINDOW_SOURCES = {"hybrid-trend": "dgpt-rbcm-trend", "hybrid-paper": "dgpt-rbcm-trend"}
"""Trackers that wrap a DGPT use the window tuned for it."""


def tuned_kwargs(tracker_id: str, scenario: str) -> dict:
    """``{"window": C}`` for a tracker with a tuned window on ``scenario``, else ``{}``."""
    source = WINDOW_SOURCES.get(tracker_id, tracker_id)
    window = tuned_windows().get(source, {}).get(scenario)
    return {} if window is None else {"window": int(window)}


def save_tuned_windows(
    best: dict[str, dict[str, int]], rows: list[dict], path: Path = TUNED_WINDOWS_PATH
) -> None:
    """Write the tuned windows and the grid they came from."""
    path.write_text(json.dumps({"windows": best, "grid": rows}, indent=1) + "\n")
    tuned_windows.cache_clear()
