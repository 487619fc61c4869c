"""Argument checks shared by the env and the trackers: each raises ``ValueError`` naming the
argument, the value given and what is allowed."""

from __future__ import annotations

import math
import numbers
from collections.abc import Collection

import numpy as np

__all__ = ["check_real", "check_integer", "check_choice", "check_bool"]


def check_real(
    name: str,
    value: object,
    *,
    low: float | None = None,
    high: float | None = None,
    low_inclusive: bool = True,
    high_inclusive: bool = True,
) -> float:
    """``value`` as a finite float inside the given bounds, or ``ValueError``."""
    interval = (
        f"{'[' if low_inclusive else '('}{'-inf' if low is None else low}, "
        f"{'inf' if high is None else high}{']' if high_inclusive else ')'}"
    )
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite real number in {interval}; got {value!r}")
    value = float(value)
    too_low = low is not None and (value < low if low_inclusive else value <= low)
    too_high = high is not None and (value > high if high_inclusive else value >= high)
    if too_low or too_high:
        raise ValueError(f"{name} must be in {interval}; got {value!r}")
    return value


def check_integer(name: str, value: object, *, low: int | None = None) -> int:
    """``value`` as an int of at least ``low``, or ``ValueError``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer >= {low}; got {value!r}")
    if low is not None and value < low:
        raise ValueError(f"{name} must be an integer >= {low}; got {value!r}")
    return int(value)


def check_choice(name: str, value: object, allowed: Collection) -> object:
    """``value`` if it is one of ``allowed``, or ``ValueError`` listing them."""
    try:
        ok = value in allowed
    except TypeError:
        ok = False
    if not ok:
        raise ValueError(f"{name} must be one of {sorted(allowed, key=str)}; got {value!r}")
    return value


def check_bool(name: str, value: object) -> bool:
    """``value`` if it is a bool (numpy's included), or ``ValueError``: a string such as
    ``"false"`` would otherwise silently count as True."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise ValueError(f"{name} must be True or False; got {value!r}")
