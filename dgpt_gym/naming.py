"""How tracker ids are composed: the one place that defines the suffixes.

A paper approach (``gp``, ``dgpt-rbcm``, ``dgpt-gpoe``, ...) with temporal inputs (TGP) is
registered under its own name; with spatio-temporal inputs (STGP) under the name followed by
:data:`STGP_SUFFIX`; the paper's GP model as printed (zero prior mean on raw coordinates)
adds :data:`PAPER_SUFFIX` last, e.g. ``dgpt-rbcm-stgp-paper``.
"""

from __future__ import annotations

__all__ = ["STGP_SUFFIX", "PAPER_SUFFIX", "INPUTS", "tracker_id", "split_tracker_id"]

STGP_SUFFIX = "-stgp"
"""Ids of trackers with spatio-temporal inputs (paper Sec. IV-B) end in this."""
PAPER_SUFFIX = "-paper"
"""Ids of trackers with the paper's model as printed end in this."""
INPUTS = ("tgp", "stgp")
"""Input kinds: temporal (TGP) and spatio-temporal (STGP)."""


def tracker_id(approach: str, inputs: str = "tgp", suffix: str = "") -> str:
    """The id of ``approach`` with ``inputs`` (``"tgp"`` or ``"stgp"``), then ``suffix``
    (``""`` or :data:`PAPER_SUFFIX`): ``tracker_id("dgpt-rbcm", "stgp", "-paper")`` is
    ``"dgpt-rbcm-stgp-paper"``."""
    if inputs not in INPUTS:
        raise ValueError(f"inputs must be one of {INPUTS}; got {inputs!r}")
    return approach + ("" if inputs == "tgp" else STGP_SUFFIX) + suffix


def split_tracker_id(tracker: str) -> tuple[str, str, str]:
    """``(approach, inputs, suffix)`` of an id composed by :func:`tracker_id`; the inverse of
    it for every approach that does not itself end in a suffix."""
    suffix = PAPER_SUFFIX if tracker.endswith(PAPER_SUFFIX) else ""
    base = tracker.removesuffix(suffix)
    inputs = "stgp" if base.endswith(STGP_SUFFIX) else "tgp"
    return base.removesuffix(STGP_SUFFIX), inputs, suffix
