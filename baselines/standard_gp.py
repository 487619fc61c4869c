"""The centralized ("standard") GP tracker, the paper's benchmark (Sec. VII-C): with the
pooled SE trend (``gp-trend``, ``gp-paper``) and in state-space form (``gp``)."""

from __future__ import annotations

from agents.dgpt import DGPT
from agents.state_space_dgpt import StateSpaceDGPT

__all__ = ["StandardGP", "StateSpaceGP"]


class StandardGP(DGPT):
    """The centralized GP around the pooled SE trend (``gp-trend``, ``gp-paper``): one GP on
    the pooled gated summaries of all sensors in the window: the same data and the same
    gating, learning and outputs as :class:`~agents.dgpt.DGPT`, but a single expert, so it
    solves the full marginal likelihood, eq. (21), and every sensor gates with the central
    prediction. With one expert every aggregation returns that expert's prediction and the
    UCB is Lemma 1's gamma^(1/2) sigma.

    Args: as :class:`~agents.dgpt.DGPT` (``aggregation`` has no effect).
    """

    pooled = True


class StateSpaceGP(StateSpaceDGPT):
    """The centralized GP with the NCV kernel in state-space form, the default ``gp``: one
    Kalman update per process-noise component on every sensor's gated summary at once (the
    information filter, :func:`agents.state_space.pooled_update`), and q learnt on the same
    exact window likelihood as the distributed trackers. With a shared prior this is the
    BCM aggregate exactly, so ``gp`` and ``dgpt-bcm`` return the same numbers: the
    distributed tracker loses nothing to the centralized one under this model.

    Args: as :class:`~agents.state_space_dgpt.StateSpaceDGPT`, without ``aggregation``.
    """

    def __init__(self, **kwargs) -> None:
        if "aggregation" in kwargs:
            raise ValueError(
                "aggregation: the centralized GP has no experts to aggregate; "
                "use agents.state_space_dgpt.StateSpaceDGPT for an aggregation"
            )
        super().__init__(aggregation="bcm", **kwargs)
        self.name = "gp"
