"""The tracker ids of this package, as data: :mod:`dgpt_gym.registry` reads
:data:`TRACKERS` the first time it is asked for an id, and imports a tracker's module only
when one is built. A new tracker in ``agents/`` is registered here and nowhere else."""

from __future__ import annotations

from dgpt_gym.naming import INPUTS, PAPER_SUFFIX, TREND_SUFFIX, tracker_id

__all__ = ["TRACKERS", "PAPER_MODEL", "SILENCE_PARTICLES", "RENAMED"]

PAPER_MODEL = {"mean": "zero"}
"""The paper's GP model as printed: zero prior mean on raw coordinates, with the SE kernel,
eq. (22) learning and eqs. (27)-(28) gating of the defaults. The paper states no
hyperparameter bounds; with none (``hyperparameter_bounds="loose"``) the fit on a short
window falls into the white-noise optimum and the estimate collapses to the origin (2-D
RMSE ~500 m on training seeds), so the ``-paper`` trackers keep the tracking bounds
(:data:`agents.dgpt.HYPERPARAMETER_BOUNDS`)."""

SILENCE_PARTICLES = 1000
"""Particles of ``dgpt-bcm-silence`` (``dgpt-bcm-ncv-silence`` before 0.9.0) in a coverage
gap: of 200, 500 and 1000 on training seeds 1000-1011 (``python scripts/model_study.py --seeds 12 --paired-against ss-bcm-20
--candidates ss-bcm-20 ss-silence-200 ss-silence-500 ss-silence-1000``), 1000 had the lowest
RMSE (13.30 / 19.50 m on the reference / random paths, against 13.40 / 19.61 m for 500,
13.87 / 19.87 m for 200 and 14.40 / 23.09 m without the silence)."""

AGGREGATIONS = ("rbcm", "gpoe", "bcm", "poe")

TRACKERS: tuple[tuple[str, str, dict], ...] = (
    *(
        (
            f"dgpt-{aggregation}",
            "agents.state_space_dgpt:StateSpaceDGPT",
            {"aggregation": aggregation},
        )
        for aggregation in AGGREGATIONS
    ),
    (
        "dgpt-bcm-silence",
        "agents.state_space_dgpt:StateSpaceDGPT",
        {"aggregation": "bcm", "silence_particles": SILENCE_PARTICLES},
    ),
    *(
        (
            tracker_id(f"dgpt-{aggregation}", inputs, TREND_SUFFIX),
            "agents.dgpt:DGPT",
            {"aggregation": aggregation, "inputs": inputs},
        )
        for aggregation in AGGREGATIONS
        for inputs in INPUTS
    ),
    *(
        (
            tracker_id(f"dgpt-{aggregation}", inputs, PAPER_SUFFIX),
            "agents.dgpt:DGPT",
            {"aggregation": aggregation, "inputs": inputs, **PAPER_MODEL},
        )
        for aggregation in ("rbcm", "gpoe")
        for inputs in INPUTS
    ),
    ("hybrid", "agents.hybrid:HybridFilter", {"variant": "exact"}),
    ("hybrid" + TREND_SUFFIX, "agents.hybrid:HybridFilter", {"variant": "exact", "gp": "se"}),
    ("hybrid" + PAPER_SUFFIX, "agents.hybrid:HybridFilter", {"variant": "paper", "gp": "se"}),
)
"""``(id, "module:Class", default keyword arguments)`` of every tracker in ``agents/``: the
distributed NCV GP in state-space form (``dgpt-<aggregation>``, the default), the same with
the silence of the sensors in coverage gaps (``dgpt-bcm-silence``), the SE kernel around a
pooled trend (``-trend``) and the paper's model as printed (``-paper``), with temporal and
spatio-temporal (``-stgp``) inputs, and the hybrid Bayesian filter around each."""

RENAMED = {
    "dgpt-bcm-ncv": "dgpt-bcm",
    "dgpt-rbcm-ncv": "dgpt-rbcm",
    "dgpt-bcm-ncv-silence": "dgpt-bcm-silence",
    "hybrid-ncv": "hybrid (now around dgpt-rbcm; around dgpt-bcm: aggregation='bcm')",
    **{
        tracker_id(approach, "stgp"): tracker_id(approach, "stgp", TREND_SUFFIX)
        for approach in ("gp", *(f"dgpt-{a}" for a in AGGREGATIONS))
    },
}
"""Ids of dgpt-gym 0.8 that 0.9.0 renamed, and their new names: the state-space NCV GP
became the default ``dgpt-*`` and ``gp``, the pooled SE trend took ``-trend``. The SE ids
with temporal inputs (``dgpt-rbcm``, ``gp``, ...) now name the state-space trackers, and
their 0.8 trackers are ``dgpt-rbcm-trend``, ``gp-trend``, ...; ``hybrid`` is
``hybrid-trend``."""
