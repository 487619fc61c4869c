"""Tracker registry, modelled on Gymnasium's env registry.

Trackers are registered by id with an entry-point string ``"module:attribute"`` and default
keyword arguments; :func:`make_tracker` imports the module only when a tracker is built, so
``dgpt_gym`` has no static import of ``agents`` or ``baselines`` yet knows every tracker by
name.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field

__all__ = ["TrackerSpec", "register_tracker", "make_tracker", "tracker_ids", "tracker_spec"]


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


def tracker_ids() -> list[str]:
    """The registered tracker ids, sorted."""
    return sorted(_REGISTRY)


def tracker_spec(id: str) -> TrackerSpec:
    """The :class:`TrackerSpec` of ``id``, or ``ValueError`` listing the registered ids."""
    try:
        return _REGISTRY[id]
    except (KeyError, TypeError):
        raise ValueError(f"tracker must be one of {tracker_ids()}; got {id!r}") from None


def make_tracker(id: str, **kwargs):
    """Build the tracker registered as ``id``; ``kwargs`` override its registered defaults."""
    spec = tracker_spec(id)
    return spec.load()(**{**spec.kwargs, **kwargs})
