"""The tracker ids of this package, as data: :mod:`dgpt_gym.registry` reads
:data:`TRACKERS` the first time it is asked for an id, and imports a tracker's module only
when one is built. A new tracker in ``agents/`` is registered here and nowhere else."""

from __future__ import annotations

from dgpt_gym.naming import INPUTS, PAPER_SUFFIX, tracker_id

__all__ = ["TRACKERS", "PAPER_MODEL"]

PAPER_MODEL = {"mean": "zero"}
"""The paper's GP model as printed: zero prior mean on raw coordinates, with the SE kernel,
eq. (22) learning and eqs. (27)-(28) gating of the defaults. The paper states no
hyperparameter bounds; with none (``hyperparameter_bounds="loose"``) the fit on a short
window falls into the white-noise optimum and the estimate collapses to the origin (2-D
RMSE ~500 m on training seeds), so the ``-paper`` trackers keep the tracking bounds
(:data:`agents.dgpt.HYPERPARAMETER_BOUNDS`)."""

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
    ("hybrid", "agents.hybrid:HybridFilter", {"variant": "exact"}),
    ("hybrid" + PAPER_SUFFIX, "agents.hybrid:HybridFilter", {"variant": "paper"}),
    ("hybrid-ncv", "agents.hybrid:HybridFilter", {"variant": "exact", "gp": "ncv"}),
)
"""``(id, "module:Class", default keyword arguments)`` of every tracker in ``agents/``."""
