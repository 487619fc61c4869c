"""The tracker ids of this package, as data (see :mod:`agents.registration`)."""

from __future__ import annotations

from agents.registration import PAPER_MODEL, SEARCHING
from dgpt_gym.naming import INPUTS, PAPER_SUFFIX, TREND_SUFFIX, tracker_id

__all__ = ["TRACKERS"]

TRACKERS: tuple[tuple[str, str, dict], ...] = (
    ("centroid", "baselines.centroid:GatedCentroidTracker", {}),
    ("gp", "baselines.standard_gp:StateSpaceGP", SEARCHING),
    *(
        (
            tracker_id("gp", inputs, TREND_SUFFIX),
            "baselines.standard_gp:StandardGP",
            {"inputs": inputs},
        )
        for inputs in INPUTS
    ),
    *(
        (
            tracker_id("gp", inputs, PAPER_SUFFIX),
            "baselines.standard_gp:StandardGP",
            # aggregation has no effect with one expert; it is part of the stored run keys
            {"aggregation": "rbcm", "inputs": inputs, **PAPER_MODEL},
        )
        for inputs in INPUTS
    ),
    ("cpf", "baselines.cpf:MultipleModelCPF", {}),
    ("pda", "baselines.pda:PDAFilter", {}),
    ("imm-pda", "baselines.pda:IMMPDAFilter", {}),
    ("clairvoyant", "baselines.clairvoyant:ClairvoyantFilter", {}),
    ("stonesoup-pda", "baselines.stonesoup:StoneSoupTracker", {}),
)
"""``(id, "module:Class", default keyword arguments)`` of every tracker in ``baselines/``."""
