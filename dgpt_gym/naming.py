"""How tracker ids are composed: the one place that defines the suffixes.

A paper approach (``gp``, ``dgpt-rbcm``, ``dgpt-gpoe``, ...) with temporal inputs (TGP) is
registered under its own name; with spatio-temporal inputs (STGP) under the name followed by
:data:`STGP_SUFFIX`. The GP model comes last: none for the default (the NCV GP in
state-space form, temporal inputs only), :data:`TREND_SUFFIX` for the SE kernel around a
pooled constant-velocity trend (e.g. ``dgpt-rbcm-stgp-trend``), :data:`PAPER_SUFFIX` for the
paper's model as printed (zero prior mean on raw coordinates, e.g. ``dgpt-rbcm-stgp-paper``).
"""

from __future__ import annotations

__all__ = [
    "STGP_SUFFIX",
    "TREND_SUFFIX",
    "PAPER_SUFFIX",
    "MODEL_SUFFIXES",
    "INPUTS",
    "tracker_id",
    "split_tracker_id",
]

STGP_SUFFIX = "-stgp"
"""Ids of trackers with spatio-temporal inputs (paper Sec. IV-B) end in this."""
TREND_SUFFIX = "-trend"
"""Ids of trackers with the SE kernel around a least-squares constant-velocity trend pooled
over every sensor's summaries (:class:`agents.dgpt.DGPT`) end in this."""
PAPER_SUFFIX = "-paper"
"""Ids of trackers with the paper's model as printed end in this."""
MODEL_SUFFIXES = ("", TREND_SUFFIX, PAPER_SUFFIX)
"""The GP models' suffixes: the default, the pooled SE trend, the paper's as printed."""
INPUTS = ("tgp", "stgp")
"""Input kinds: temporal (TGP) and spatio-temporal (STGP)."""


def tracker_id(approach: str, inputs: str = "tgp", suffix: str = "") -> str:
    """The id of ``approach`` with ``inputs`` (``"tgp"`` or ``"stgp"``), then ``suffix``
    (one of :data:`MODEL_SUFFIXES`): ``tracker_id("dgpt-rbcm", "stgp", "-paper")`` is
    ``"dgpt-rbcm-stgp-paper"``."""
    if inputs not in INPUTS:
        raise ValueError(f"inputs must be one of {INPUTS}; got {inputs!r}")
    if suffix not in MODEL_SUFFIXES:
        raise ValueError(f"suffix must be one of {MODEL_SUFFIXES}; got {suffix!r}")
    return approach + ("" if inputs == "tgp" else STGP_SUFFIX) + suffix


def split_tracker_id(tracker: str) -> tuple[str, str, str]:
    """``(approach, inputs, suffix)`` of an id composed by :func:`tracker_id`; the inverse of
    it for every approach that does not itself end in a suffix."""
    suffix = next((s for s in MODEL_SUFFIXES if s and tracker.endswith(s)), "")
    base = tracker.removesuffix(suffix)
    inputs = "stgp" if base.endswith(STGP_SUFFIX) else "tgp"
    return base.removesuffix(STGP_SUFFIX), inputs, suffix
