"""The tracker ids of this package, as data: :mod:`dgpt_gym.registry` reads
:data:`TRACKERS` the first time it is asked for an id, and imports a tracker's module only
when one is built. A new tracker in ``agents/`` is registered here and nowhere else."""

from __future__ import annotations

from dgpt_gym.naming import INPUTS, PAPER_SUFFIX, TREND_SUFFIX, tracker_id

__all__ = [
    "TRACKERS",
    "PAPER_MODEL",
    "SILENCE_PARTICLES",
    "SEARCH_PARTICLES",
    "GAP_BIRTH_PROBABILITY",
    "RENAMED",
]

PAPER_MODEL = {"mean": "zero"}
"""The paper's GP model as printed: zero prior mean on raw coordinates, with the SE kernel,
eq. (22) learning and eqs. (27)-(28) gating of the defaults. The paper states no
hyperparameter bounds; with none (``hyperparameter_bounds="loose"``) the fit on a short
window falls into the white-noise optimum and the estimate collapses to the origin (2-D
RMSE ~500 m on training seeds), so the ``-paper`` trackers keep the tracking bounds
(:data:`agents.dgpt.HYPERPARAMETER_BOUNDS`)."""

SILENCE_PARTICLES = 1000
"""Particles with which the registered state-space GP trackers (``dgpt-<aggregation>``,
``gp``) condition on the silence of the sensors in a coverage gap
(``StateSpaceDGPT(silence_particles=N)``; up to 0.11.0 only ``dgpt-bcm-silence`` did). The
number: of 200, 500 and 1000 on training seeds 1000-1011 in 0.8.0 (``python
scripts/model_study.py --seeds 12 --paired-against ss-bcm-20 --candidates ss-bcm-20
ss-silence-200 ss-silence-500 ss-silence-1000``), 1000 had the lowest RMSE (13.30 / 19.50 m
on the reference / random paths, against 13.40 / 19.61 m for 500, 13.87 / 19.87 m for 200
and 14.40 / 23.09 m without the silence). On by default since 0.12.0: with 0.11.0's model, on
training seeds 1000-1011 (S1-S4, both path modes, clutter 1 and 5; ``python
scripts/model_study.py --first-seed 1000 --seeds 12 --candidates ss-rbcm-4
ss-rbcm-silence-1000 imm-pda --paired-against ss-rbcm-4``) DGPT-RBCM with the silence was
-1.15 +- 0.60 / -2.14 +- 0.66 m from the one without (RMSE 7.09 / 15.29 m against
8.23 / 17.43 m; IMM-PDA 7.52 / 16.95 m), with the same 3-sigma coverage on detected steps
(99.35 against 99.37 %) and UCB coverage (99.84 against 99.89 %)."""

SEARCH_PARTICLES = 2000
"""Particles of the search before the first track with clutter at every sensor
(``StateSpaceDGPT(search_particles=N)``, :class:`agents.search.SearchFilter`; since 0.16.0
in every registered ``dgpt-*`` and ``gp``; it acts only with ``clutter_sensors="all"``). On
training seeds 1000-1011 (S1-S4, both path modes, clutter rate 1; ``python
scripts/model_study.py --first-seed 1000 --seeds 12 --clutter-rates 1 --clutter-sensors all
--candidates ss-rbcm-silence-1000-reports-0.1 ss-rbcm-silence-1000-search-3-0.1
--paired-against ss-rbcm-silence-1000-reports-0.1``) DGPT-RBCM's RMSE went from 43.7 / 44.3
m to 35.4 / 35.6 m on the reference / random paths (paired -8.2 +- 8.9 / -8.7 +- 7.3 m);
seeds 1012-1023: -12.4 +- 8.2 / -12.3 +- 12.2 m."""

GAP_BIRTH_PROBABILITY = 0.003
"""The prior probability per gap step that the target is somewhere new, with clutter at
every sensor (``StateSpaceDGPT(gap_birth_probability=...)``: particles born from pairs of
points of consecutive steps join the gap's particles; since 0.17.0 in every registered
``dgpt-*`` and ``gp``). Chosen on training seeds 1000-1023 (S1-S4, both path modes, clutter
rate 1; ``python scripts/model_study.py --first-seed 1000 --seeds 24 --clutter-rates 1
--clutter-sensors all --candidates ss-rbcm-silence-1000-search-3-0.1
ss-rbcm-silence-1000-search-3-0.1-gap-<p> --paired-against
ss-rbcm-silence-1000-search-3-0.1``) by the mean RMSE over both path modes: 28.9 m for
0.003, against 32.3, 29.4, 29.6, 30.8 and 34.5 m for 0.0003, 0.001, 0.01, 0.03 and 0.1, and
35.9 m without births. Paired against no births, 0.003 was -8.4 +- 5.1 / -5.6 +- 4.4 m on
the reference / random paths."""

# The hybrid returns its DGPT's estimate before the first track and in coverage gaps, so the
# search and the births act there too: on training seeds 1000-1011 / 1012-1023 with clutter
# at every sensor (``python scripts/model_study.py --first-seed 1000 --seeds 12
# --clutter-rates 1 --clutter-sensors all --candidates hybrid-ncv-silence-1000-reports-0.1
# hybrid-ncv-silence-1000-search-3-0.1-gap-0.003 --paired-against
# hybrid-ncv-silence-1000-reports-0.1``) its RMSE went from 38.2 / 39.5 to 21.7 / 29.3 m and
# from 39.7 / 48.0 to 21.4 / 26.8 m on the reference / random paths.
SEARCHING = {
    "silence_particles": SILENCE_PARTICLES,
    "search_particles": SEARCH_PARTICLES,
    "gap_birth_probability": GAP_BIRTH_PROBABILITY,
}
"""The keyword arguments with which every registered state-space GP tracker (and the
``hybrid`` around one) is built."""

AGGREGATIONS = ("rbcm", "gpoe", "bcm", "poe")

TRACKERS: tuple[tuple[str, str, dict], ...] = (
    *(
        (
            f"dgpt-{aggregation}",
            "agents.state_space_dgpt:StateSpaceDGPT",
            {"aggregation": aggregation, **SEARCHING},
        )
        for aggregation in AGGREGATIONS
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
    (
        "hybrid",
        "agents.hybrid:HybridFilter",
        {"variant": "exact", **SEARCHING},
    ),
    ("hybrid" + TREND_SUFFIX, "agents.hybrid:HybridFilter", {"variant": "exact", "gp": "se"}),
    ("hybrid" + PAPER_SUFFIX, "agents.hybrid:HybridFilter", {"variant": "paper", "gp": "se"}),
)
"""``(id, "module:Class", default keyword arguments)`` of every tracker in ``agents/``: the
distributed NCV GP in state-space form, conditioned on the silence of the sensors in
coverage gaps (``dgpt-<aggregation>``, the default), the SE kernel around a
pooled trend (``-trend``) and the paper's model as printed (``-paper``), with temporal and
spatio-temporal (``-stgp``) inputs, and the hybrid Bayesian filter around each."""

RENAMED = {
    "dgpt-bcm-ncv": "dgpt-bcm",
    "dgpt-rbcm-ncv": "dgpt-rbcm",
    "dgpt-bcm-ncv-silence": "dgpt-bcm (0.12.0: every dgpt-* uses the silence)",
    "dgpt-bcm-silence": "dgpt-bcm (0.12.0: every dgpt-* uses the silence)",
    "hybrid-ncv": "hybrid (now around dgpt-rbcm; around dgpt-bcm: aggregation='bcm')",
    **{
        tracker_id(approach, "stgp"): tracker_id(approach, "stgp", TREND_SUFFIX)
        for approach in ("gp", *(f"dgpt-{a}" for a in AGGREGATIONS))
    },
}
"""Ids that a later version renamed or retired, and what to use. 0.12.0 retired
``dgpt-bcm-silence``: the silence of the sensors is part of every ``dgpt-*`` and ``gp``
(:data:`SILENCE_PARTICLES`; ``silence_particles=0`` turns it off). 0.9.0 renamed the ids of
dgpt-gym 0.8: the state-space NCV GP
became the default ``dgpt-*`` and ``gp``, the pooled SE trend took ``-trend``. The SE ids
with temporal inputs (``dgpt-rbcm``, ``gp``, ...) now name the state-space trackers, and
their 0.8 trackers are ``dgpt-rbcm-trend``, ``gp-trend``, ...; ``hybrid`` is
``hybrid-trend``."""
