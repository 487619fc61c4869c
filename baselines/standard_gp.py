"""The centralized ("standard") GP tracker, the paper's benchmark (Sec. VII-C)."""

from __future__ import annotations

from agents.dgpt import DGPT

__all__ = ["StandardGP"]


class StandardGP(DGPT):
    """One GP on the pooled gated summaries of all sensors in the window: the same data and
    the same gating, learning and outputs as :class:`~agents.dgpt.DGPT`, but a single
    expert, so it solves the full marginal likelihood, eq. (21), and every sensor gates with
    the central prediction. With one expert every aggregation returns that expert's
    prediction and the UCB is Lemma 1's gamma^(1/2) sigma.

    Args: as :class:`~agents.dgpt.DGPT` (``aggregation`` has no effect).
    """

    pooled = True
