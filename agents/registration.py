"""The tracker ids of this package, as data: :mod:`dgpt_gym.registry` reads
:data:`TRACKERS` the first time it is asked for an id, and imports a tracker's module only
when one is built. A new tracker in ``agents/`` is registered here and nowhere else."""

from __future__ import annotations

from dgpt_gym.naming import INPUTS, PAPER_SUFFIX, tracker_id

__all__ = ["TRACKERS", "PAPER_MODEL", "SILENCE_PARTICLES"]

PAPER_MODEL = {"mean": "zero"}
"""The paper's GP model as printed: zero prior mean on raw coordinates, with the SE kernel,
eq. (22) learning and eqs. (27)-(28) gating of the defaults. The paper states no
hyperparameter bounds; with none (``hyperparameter_bounds="loose"``) the fit on a short
window falls into the white-noise optimum and the estimate collapses to the origin (2-D
RMSE ~500 m on training seeds), so the ``-paper`` trackers keep the tracking bounds
(:data:`agents.dgpt.HYPERPARAMETER_BOUNDS`)."""

SILENCE_PARTICLES = 1000
"""Particles of ``dgpt-bcm-ncv-silence`` in a coverage gap: of 200, 500 and 1000 on training
seeds 1000-1011 (``python scripts/model_study.py --seeds 12 --paired-against ss-bcm-20
--candidates ss-bcm-20 ss-silence-200 ss-silence-500 ss-silence-1000``), 1000 had the lowest
RMSE (13.30 / 19.50 m on the reference / random paths, against 13.40 / 19.61 m for 500,
13.87 / 19.87 m for 200 and 14.40 / 23.09 m without the silence)."""

TRACKERS: tuple[tuple[str, str, dict], ...] = (
    *(
        (
            tracker_id(f"dgpt-{aggregation}", inputs),
            "agents.dgpt:DGPT",
            {"aggregation": aggregation, "inputs": inputs},
        )
        for aggregation in ("rbcm", "gpoe", "bcm", "poe")
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
    *(
        (
            f"dgpt-{aggregation}-ncv",
            "agents.state_space_dgpt:StateSpaceDGPT",
            {"aggregation": aggregation},
        )
        for aggregation in ("bcm", "rbcm")
    ),
    (
        "dgpt-bcm-ncv-silence",
        "agents.state_space_dgpt:StateSpaceDGPT",
        {"aggregation": "bcm", "silence_particles": SILENCE_PARTICLES},
    ),
    ("hybrid", "agents.hybrid:HybridFilter", {"variant": "exact"}),
    ("hybrid" + PAPER_SUFFIX, "agents.hybrid:HybridFilter", {"variant": "paper"}),
    ("hybrid-ncv", "agents.hybrid:HybridFilter", {"variant": "exact", "gp": "ncv"}),
)
"""``(id, "module:Class", default keyword arguments)`` of every tracker in ``agents/``."""
