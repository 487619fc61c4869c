"""Tracker registry, modelled on Gymnasium's env registry.

Trackers are registered by id with an entry-point string ``"module:attribute"`` and default
keyword arguments; :func:`make_tracker` imports the module only when a tracker is built, so
``dgpt_gym`` has no static import of ``agents`` or ``baselines`` yet knows every tracker by
name.

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

import importlib
from dataclasses import dataclass, field

__all__ = [
    "TrackerSpec",
    "register_tracker",
    "make_tracker",
    "tracker_ids",
    "tracker_spec",
    "ENTRY_POINT_GROUP",
]

ENTRY_POINT_GROUP = "dgpt_gym.trackers"
"""Entry-point group through which installed packages register tracker ids."""


@dataclass(frozen=True)
class TrackerSpec:
    """A registered tracker: its id, entry point and default constructor arguments."""

    id: str
    entry_point: str
    kwargs: dict = field(default_factory=dict)

    def load(self):
        module_name, _, attribute = self.entry_point.partition(":")
        if not attribute:
            raise ValueError(
                f"entry_point must look like 'package.module:Class'; got {self.entry_point!r}"
            )
        return getattr(importlib.import_module(module_name), attribute)


_REGISTRY: dict[str, TrackerSpec] = {}


def register_tracker(id: str, entry_point: str, **kwargs) -> None:
    """Register a tracker ``id`` built as ``entry_point(**kwargs)``; re-registering replaces it."""
    if not isinstance(id, str) or not id:
        raise ValueError(f"id must be a non-empty string; got {id!r}")
    if not isinstance(entry_point, str) or ":" not in entry_point:
        raise ValueError(f"entry_point must look like 'package.module:Class'; got {entry_point!r}")
    _REGISTRY[id] = TrackerSpec(id, entry_point, dict(kwargs))


_entry_points_loaded = False


def _load_entry_points() -> None:
    """Register the ids that installed packages declare in :data:`ENTRY_POINT_GROUP` (once;
    ids registered in code take precedence)."""
    global _entry_points_loaded
    if _entry_points_loaded:
        return
    _entry_points_loaded = True
    from importlib.metadata import entry_points

    for point in entry_points(group=ENTRY_POINT_GROUP):
        if point.name not in _REGISTRY and ":" in point.value:
            _REGISTRY[point.name] = TrackerSpec(point.name, point.value)


def tracker_ids() -> list[str]:
    """The registered tracker ids (with those of installed packages), sorted."""
    _load_entry_points()
    return sorted(_REGISTRY)


def tracker_spec(id: str) -> TrackerSpec:
    """The :class:`TrackerSpec` of ``id``; an id ``"package.module:ClassName"`` that is not
    registered yet is registered as that class if it can be imported. ``ValueError``
    otherwise, listing the registered ids."""
    if isinstance(id, str) and id not in _REGISTRY:
        _load_entry_points()
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
        raise ValueError(
            f"tracker must be one of {tracker_ids()} or 'package.module:ClassName'; got {id!r}"
        ) from None


def make_tracker(id: str, **kwargs):
    """Build the tracker registered as ``id``; ``kwargs`` override its registered defaults."""
    spec = tracker_spec(id)
    return spec.load()(**{**spec.kwargs, **kwargs})
