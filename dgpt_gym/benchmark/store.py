"""The results store of an evaluation sweep: one embedded SQLite database per output folder.

Every finished (cell, seed, tracker) run is one row, committed as soon as the run finishes,
so an interrupted sweep (Ctrl-C, a killed process) loses no finished row. The row's key is a
hash of its whole configuration (tracker id and arguments, environment arguments, seed,
and the source of a tracker from outside the project):
re-running a sweep skips the keys already stored with status ``"ok"`` by the same dgpt-gym
version and never duplicates one. Failed runs, and runs of another version (whose numbers
may differ), are run again and replaced.
"""

from __future__ import annotations

import hashlib
import json
import sqlite3
import time
from pathlib import Path

import dgpt_gym

__all__ = ["ResultsStore", "run_key", "DATABASE_NAME"]

DATABASE_NAME = "results.sqlite"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS runs (
    run_key TEXT PRIMARY KEY,
    tracker TEXT NOT NULL,
    scenario TEXT NOT NULL,
    noise_std REAL NOT NULL,
    clutter_rate REAL NOT NULL,
    seed INTEGER NOT NULL,
    tracker_kwargs TEXT NOT NULL,
    env_kwargs TEXT NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('ok', 'failed')),
    error TEXT,
    metrics TEXT,
    runtime_s REAL,
    version TEXT NOT NULL,
    finished_at TEXT NOT NULL
)
"""


def _canonical(value) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


def run_key(
    tracker: str, tracker_kwargs: dict, env_kwargs: dict, seed: int, source: str | None = None
) -> str:
    """The identity of a run: a SHA-256 of its canonical JSON configuration, and of
    ``source``, the digest of a user tracker's code (:func:`dgpt_gym.registry.source_digest`;
    None for the project's trackers, whose keys are then those of earlier versions)."""
    configuration = [tracker, tracker_kwargs, env_kwargs, int(seed)]
    if source is not None:
        configuration.append(source)
    return hashlib.sha256(_canonical(configuration).encode()).hexdigest()


class ResultsStore:
    """SQLite table ``runs`` in ``folder/results.sqlite`` (created on first use).

    Only the process that runs the sweep writes; workers return their rows to it. Each
    :meth:`add` is its own transaction (WAL journal), so a crash keeps every earlier row.
    """

    def __init__(self, folder: str | Path) -> None:
        folder = Path(folder)
        if folder.exists() and not folder.is_dir():
            raise ValueError(f"out must be a folder; {str(folder)!r} is a file")
        self.path = folder / DATABASE_NAME
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise ValueError(f"out {str(folder)!r} cannot be created: {error.strerror}") from None
        try:
            self._connection = sqlite3.connect(self.path)
            self._connection.execute("PRAGMA journal_mode=WAL")
            self._connection.execute(_SCHEMA)
            self._connection.commit()
        except sqlite3.DatabaseError as error:
            raise ValueError(
                f"{self.path} is not a usable dgpt-gym results database ({error}); move or "
                "delete it to start afresh, or give another --out"
            ) from None

    def close(self) -> None:
        self._connection.close()

    def __enter__(self) -> ResultsStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def finished_keys(self, version: str | None = None) -> set[str]:
        """Keys of the runs stored with status ``"ok"`` (by dgpt-gym ``version`` if given)."""
        query, parameters = "SELECT run_key FROM runs WHERE status = 'ok'", ()
        if version is not None:
            query, parameters = query + " AND version = ?", (version,)
        return {key for (key,) in self._connection.execute(query, parameters)}

    def add(self, unit, status: str, metrics: dict | None, error: str | None, runtime_s: float):
        """Store the outcome of ``unit`` (a :class:`dgpt_gym.benchmark.sweep.RunUnit`), replacing an
        earlier failure of the same run."""

        env = unit.env_kwargs
        with self._connection:
            self._connection.execute(
                "INSERT OR REPLACE INTO runs VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    unit.key,
                    unit.tracker,
                    env["scenario"],
                    env["noise_std"],
                    env["clutter_rate"],
                    unit.seed,
                    _canonical(unit.tracker_kwargs),
                    _canonical(env),
                    status,
                    error,
                    None if metrics is None else _canonical(metrics),
                    runtime_s,
                    dgpt_gym.__version__,
                    time.strftime("%Y-%m-%dT%H:%M:%S"),
                ),
            )

    def rows(self, keys: set[str] | None = None, status: str | None = None) -> list[dict]:
        """Stored rows (restricted to ``keys`` and ``status`` when given), sorted by tracker,
        cell and seed, with ``metrics``, ``tracker_kwargs`` and ``env_kwargs`` decoded."""
        query = "SELECT * FROM runs"
        parameters: tuple = ()
        if status is not None:
            query += " WHERE status = ?"
            parameters = (status,)
        query += " ORDER BY tracker, scenario, noise_std, clutter_rate, seed"
        cursor = self._connection.execute(query, parameters)
        names = [column[0] for column in cursor.description]
        rows = []
        for values in cursor:
            row = dict(zip(names, values))
            if keys is not None and row["run_key"] not in keys:
                continue
            for field in ("metrics", "tracker_kwargs", "env_kwargs"):
                row[field] = None if row[field] is None else json.loads(row[field])
            rows.append(row)
        return rows
