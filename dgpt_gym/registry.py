"""Tracker registry, modelled on Gymnasium's env registry.

Trackers are registered by id with an entry-point string ``"module:attribute"`` and default
keyword arguments; :func:`make_tracker` imports the module only when a tracker is built. The
project's own ids are declared as data beside their code (:data:`BUILTIN_TRACKER_TABLES`) and
read the first time the registry is asked for an id, so ``dgpt_gym`` has no import of
``agents`` or ``baselines`` yet knows every tracker by name.

Two ways in for a user's own tracker, besides :func:`register_tracker`:

- an id of the form ``"package.module:ClassName"`` names the class itself
  (:func:`tracker_spec` registers it on first use), so ``scripts/evaluate.py --trackers
  mypackage.trackers:MyTracker`` evaluates it;
- an installed distribution may declare ids in the entry-point group
  :data:`ENTRY_POINT_GROUP` (``[project.entry-points."dgpt_gym.trackers"]`` with
  ``my-tracker = "mypackage.trackers:MyTracker"``); they are registered the first time the
  registry is asked for an id it does not know.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import inspect
import os
from dataclasses import dataclass, field
from importlib.metadata import entry_points

__all__ = [
    "TrackerSpec",
    "register_tracker",
    "make_tracker",
    "tracker_ids",
    "tracker_spec",
    "ENTRY_POINT_GROUP",
    "BUILTIN_TRACKER_TABLES",
    "load_table",
    "source_digest",
    "PROJECT_PACKAGES",
]

ENTRY_POINT_GROUP = "dgpt_gym.trackers"
"""Entry-point group through which installed packages register tracker ids."""

BUILTIN_TRACKER_TABLES = ("agents.registration:TRACKERS", "baselines.registration:TRACKERS")
"""Where the project's trackers are declared: tuples ``(id, "module:Class", kwargs)``."""

RENAMED_TABLE = "agents.registration:RENAMED"
"""Ids that earlier versions used, ``{old id: new id}``: asked for one, the registry says
what it is called now."""


PROJECT_PACKAGES = ("agents", "baselines", "dgpt_gym")
"""The packages this project ships: the dgpt-gym version identifies their code."""


def source_digest(entry_point: str) -> str | None:
    """A SHA-256 of the source file that defines the class ``entry_point``
    (``"module:Class"``) names, or None for the project's own packages
    (:data:`PROJECT_PACKAGES`), whose code the dgpt-gym version identifies. The evaluation's
    results store puts it in the run's key, so that editing one's own tracker runs it again
    instead of reading the runs of the code before the edit. Only that file is read, not
    the modules it imports; it is read again when its modification time or size changes.
    None too when the class has no source file (e.g. defined at an interactive prompt)."""
    if entry_point.partition(":")[0].partition(".")[0] in PROJECT_PACKAGES:
        return None
    path = _source_file(entry_point)
    if path is None:
        return None
    try:
        status = os.stat(path)
    except OSError:
        return None
    return _file_digest(path, status.st_mtime_ns, status.st_size)


@functools.cache
def _source_file(entry_point: str) -> str | None:
    try:
        return inspect.getsourcefile(load_table(entry_point))
    except (ImportError, AttributeError, TypeError, OSError, ValueError):
        return None


@functools.cache
def _file_digest(path: str, modified_ns: int, size: int) -> str:
    """The file's SHA-256; the modification time and size key the cache."""
    with open(path, "rb") as source:
        return hashlib.sha256(source.read()).hexdigest()


def load_table(location: str):
    """The object at ``location`` (``"package.module:NAME"``), imported on demand: how
    :mod:`dgpt_gym` reads the registration tables of the packages that build on it without
    importing them."""
    module_name, _, attribute = location.partition(":")
    return getattr(importlib.import_module(module_name), attribute)


@dataclass(frozen=True)
class TrackerSpec:
    """A registered tracker: its id, entry point and default constructor arguments."""

    id: str
    entry_point: str
    kwargs: dict = field(default_factory=dict)

    def load(self):
        if not self.entry_point.partition(":")[2]:
            raise ValueError(
                f"entry_point must look like 'package.module:Class'; got {self.entry_point!r}"
            )
        return load_table(self.entry_point)


_REGISTRY: dict[str, TrackerSpec] = {}


def register_tracker(id: str, entry_point: str, **kwargs) -> None:
    """Register a tracker ``id`` built as ``entry_point(**kwargs)``; re-registering replaces it."""
    if not isinstance(id, str) or not id:
        raise ValueError(f"id must be a non-empty string; got {id!r}")
    if not isinstance(entry_point, str) or ":" not in entry_point:
        raise ValueError(f"entry_point must look like 'package.module:Class'; got {entry_point!r}")
    _REGISTRY[id] = TrackerSpec(id, entry_point, dict(kwargs))


_tables_loaded = False


def _load_tables() -> None:
    """Register the project's ids (:data:`BUILTIN_TRACKER_TABLES`) and those that installed
    packages declare in :data:`ENTRY_POINT_GROUP` (once; ids registered by
    :func:`register_tracker` take precedence)."""
    global _tables_loaded
    if _tables_loaded:
        return
    _tables_loaded = True
    for location in BUILTIN_TRACKER_TABLES:
        for id, entry_point, kwargs in load_table(location):
            _REGISTRY.setdefault(id, TrackerSpec(id, entry_point, dict(kwargs)))
    for point in entry_points(group=ENTRY_POINT_GROUP):
        if point.name not in _REGISTRY and ":" in point.value:
            _REGISTRY[point.name] = TrackerSpec(point.name, point.value)


def tracker_ids() -> list[str]:
    """The registered tracker ids (with those of installed packages), sorted."""
    _load_tables()
    return sorted(_REGISTRY)


def tracker_spec(id: str) -> TrackerSpec:
    """The :class:`TrackerSpec` of ``id``; an id ``"package.module:ClassName"`` that is not
    registered yet is registered as that class if it can be imported. ``ValueError``
    otherwise, listing the registered ids."""
    if isinstance(id, str) and id not in _REGISTRY:
        _load_tables()
        if id not in _REGISTRY and ":" in id:
            spec = TrackerSpec(id, id)
            try:
                spec.load()
            except (ImportError, AttributeError, ValueError) as error:
                raise ValueError(
                    f"tracker {id!r} names no importable class ('package.module:ClassName'): "
                    f"{type(error).__name__}: {error}"
                ) from None
            _REGISTRY[id] = spec
    try:
        return _REGISTRY[id]
    except (KeyError, TypeError):
        renamed = load_table(RENAMED_TABLE) if isinstance(id, str) else {}
        if id in renamed:
            raise ValueError(f"tracker {id!r} was renamed or retired: use {renamed[id]}") from None
        raise ValueError(
            f"tracker must be one of {tracker_ids()} or 'package.module:ClassName'; got {id!r}"
        ) from None


def make_tracker(id: str, **kwargs):
    """Build the tracker registered as ``id``; ``kwargs`` override its registered defaults."""
    spec = tracker_spec(id)
    return spec.load()(**{**spec.kwargs, **kwargs})
