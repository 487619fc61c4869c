"""The evaluation protocol: which seeds tune and which report, and the paper's tracker sets.

Every setting (windows, gates, process noise, RL hyperparameters) is chosen on
:data:`TRAINING_SEEDS` and reported on :data:`EVALUATION_SEEDS`; the two never overlap.
"""

from __future__ import annotations

from dgpt_gym.naming import PAPER_SUFFIX, tracker_id

__all__ = [
    "TRAINING_SEEDS",
    "EVALUATION_SEEDS",
    "PAPER_APPROACHES",
    "PAPER_GP_TRACKERS",
    "PAPER_AS_PRINTED_TRACKERS",
]

TRAINING_SEEDS = range(1000, 1005)
"""Seeds on which settings are searched (the searches may use more: 1000 and up)."""
EVALUATION_SEEDS = range(0, 100)
"""Seeds of the reported grids (the paper's 100 Monte Carlo runs)."""

PAPER_APPROACHES = ("gp", "dgpt-rbcm", "dgpt-gpoe")
"""The approaches of the paper's Tables II-IX: standard GP, DGPT-RBCM, DGPT-GPoE."""

PAPER_GP_TRACKERS = tuple(
    tracker_id(approach, inputs) for approach in PAPER_APPROACHES for inputs in ("tgp", "stgp")
)
"""The paper's approaches, each with temporal (TGP) and spatio-temporal (STGP) inputs, as
registered with our defaults."""

PAPER_AS_PRINTED_TRACKERS = tuple(tracker + PAPER_SUFFIX for tracker in PAPER_GP_TRACKERS)
"""The same approaches with the paper's model as printed (zero prior mean on raw
coordinates), to set beside our defaults."""
