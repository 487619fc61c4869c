"""Compare GP tracking models on training seeds (the evaluation seeds 0-99 only with
``--first-seed 0``, to report a setting already chosen).

Every candidate runs on S1-S4, the reference and random paths, clutter rates 1 and 5,
sigma_z = 1 (``--noise-std`` for another), training seeds 1000 onwards; ``--scenarios``,
``--trajectories`` and ``--clutter-rates`` keep only some of those cells. Printed per
candidate and cell: 2-D RMSE (m; then on the steps where a sensor senses the target and on
the coverage-gap steps), NRMSE
(%, mean of the axes), on steps where a sensor senses the target the median 2-D NEES
(nominal 1.39) and the 3-sigma coverage (mean of the axes, nominal 99.7 %), the median
step time, the share of fitted steps that left a hyperparameter on a bound (%, where
the tracker reports it), and over all steps the UCB's coverage (mean of the axes, %) and its
mean half-width over the RMSE (both per axis, averaged over episodes and axes); then a
summary per candidate over the cells. Runs go in lockstep
blocks, where a tracker with a batched step (DGPT) is much cheaper per step than one
without; compare step costs one episode at a time with ``scripts/bench.py``.

    python scripts/model_study.py                  # one candidate of each kind
    python scripts/model_study.py --seeds 10 --candidates se-trend ncv-local-bcm
    python scripts/model_study.py --clutter-sensors all --candidates se-trend se-gate-4
    python scripts/model_study.py --clutter-sensors all --clutter-rates 1 --first-seed 0 \
        --seeds 100 --candidates se-trend gp-trend hybrid-trend     # held-out report
    python scripts/model_study.py --ucb-by-step --seeds 4 --candidates ss-bcm-20
    python scripts/model_study.py --paired-against ss-bcm-20 --candidates ss-bcm-20 ss-rbcm-20

``--paired-against NAME`` adds, per candidate and path mode, the mean over shared (cell,
seed) pairs of the candidate's 2-D RMSE and NRMSE minus NAME's, with 95 % Student-t
intervals. ``--ucb-by-step`` prints instead, per candidate over all its runs, the UCB
half-width (median and mean over steps and axes), its coverage, the RMSE per axis and the
predictive sigma on the steps where a sensor senses the target and on the coverage-gap
steps (in one process).
"""

from __future__ import annotations

import argparse
import collections
import itertools
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from agents.aggregation import AGGREGATIONS  # noqa: E402
from agents.registration import SEARCHING  # noqa: E402
from agents.state_space_dgpt import EXPERT_UPDATES  # noqa: E402
from dgpt_gym.benchmark.episodes import interval_half_width  # noqa: E402
from dgpt_gym.benchmark.sweep import RunUnit, episode_results, make_blocks, run_units  # noqa: E402

MODEL_0_10 = {"turn_rates": (), "summary_variance": "point"}
"""The state-space model's arguments that 0.11.0 changed, as 0.10.0 had them."""


def _gap_end_candidate(probability: float, evidence: str, cell: float):
    """DGPT-RBCM with the silence and the reports' gap end: new-track probability, what
    weighs the hypotheses there, and the new track's cell (0: one Gaussian)."""
    return (
        "agents.state_space_dgpt:StateSpaceDGPT",
        {
            "aggregation": "rbcm",
            "silence_particles": 1000,
            "gap_end": "reports",
            "gap_restart_probability": probability,
            "gap_end_evidence": evidence,
            "gap_region_cell": cell,
        },
    )


CANDIDATES = {
    "se-trend": ("agents.dgpt:DGPT", {"window": 3}),
    "gp-trend": ("baselines.standard_gp:StandardGP", {"window": 3}),
    "hybrid-trend": ("agents.hybrid:HybridFilter", {"gp": "se", "window": 3}),
    **{
        f"hybrid-trend-{'region' if region else 'no-region'}": (
            "agents.hybrid:HybridFilter",
            {"gp": "se", "window": 3, "reporting_region": region},
        )
        for region in (False, True)
    },
    "hybrid-ncv": ("agents.hybrid:HybridFilter", {"gp": "ncv"}),
    "hybrid-ncv-moments": ("agents.hybrid:HybridFilter", {"gp": "ncv", "prior_model": "moments"}),
    "hybrid-ncv-silence-1000": (
        "agents.hybrid:HybridFilter",
        {"gp": "ncv", "silence_particles": 1000},
    ),
    **{
        f"hybrid-ncv-silence-1000-reports-{probability:g}": (
            "agents.hybrid:HybridFilter",
            {
                "gp": "ncv",
                "silence_particles": 1000,
                "gap_end": "reports",
                "gap_restart_probability": probability,
                "gap_end_evidence": "summaries",
                "gap_region_cell": 0.0,
            },
        )
        for probability in (0.02, 0.1)
    },
    "hybrid-ncv-silence-1000-search-3-0.1-gap-0.003": (
        "agents.hybrid:HybridFilter",
        {
            "gp": "ncv",
            "silence_particles": 1000,
            "search_particles": 2000,
            "gap_birth_probability": 0.003,
        },
    ),
    "hybrid-ncv-silence-1000-moments": (
        "agents.hybrid:HybridFilter",
        {"gp": "ncv", "silence_particles": 1000, "gap_end": "moments"},
    ),
    "hybrid-ncv-reacquire-none": ("agents.hybrid:HybridFilter", {"gp": "ncv", "reacquire": "none"}),
    "hybrid-ncv-per-sensor": (
        "agents.hybrid:HybridFilter",
        {"gp": "ncv", "scan_model": "per-sensor"},
    ),
    "hybrid-per-sensor": (
        "agents.hybrid:HybridFilter",
        {"gp": "se", "window": 3, "scan_model": "per-sensor"},
    ),
    "hybrid-ncv-per-sensor-reacquire-none": (
        "agents.hybrid:HybridFilter",
        {"gp": "ncv", "scan_model": "per-sensor", "reacquire": "none"},
    ),
    "hybrid-per-sensor-reacquire-none": (
        "agents.hybrid:HybridFilter",
        {"gp": "se", "window": 3, "scan_model": "per-sensor", "reacquire": "none"},
    ),
    # references, not GP models: the accuracy floor and the strongest standard tracker
    "clairvoyant": ("baselines.clairvoyant:ClairvoyantFilter", {}),
    "imm-pda": ("baselines.pda:IMMPDAFilter", {}),
    # the paper's CPF baseline (its kernel floored at the model's least posterior variance),
    # and with a fixed floor under the kernel's position sd (0: none, as before 0.25.0)
    "cpf": ("baselines.cpf:MultipleModelCPF", {}),
    **{
        f"cpf-kernel-floor-{floor:g}": (
            "baselines.cpf:MultipleModelCPF",
            {"kernel_position_std_floor": floor},
        )
        for floor in (0.0, 0.5, 1.0, 2.0, 4.0)
    },
    "se-zero": ("agents.dgpt:DGPT", {"window": 3, "mean": "zero"}),
    "se-zero-loose": (
        "agents.dgpt:DGPT",
        {"window": 3, "mean": "zero", "hyperparameter_bounds": "loose"},
    ),
    **{
        f"se-gate-{threshold:g}": ("agents.dgpt:DGPT", {"window": 3, "gate_threshold": threshold})
        for threshold in (3.0, 4.0, 5.0, 6.0)
    },
    "ncv-local-bcm": (
        "agents.dgpt:DGPT",
        {"window": 4, "kernel": "ncv", "mean": "prediction", "aggregation": "bcm"},
    ),
    "ncv-local-rbcm": (
        "agents.dgpt:DGPT",
        {"window": 4, "kernel": "ncv", "mean": "prediction", "aggregation": "rbcm"},
    ),
    "ncv-centralized": (
        "baselines.standard_gp:StandardGP",
        {"window": 4, "kernel": "ncv", "mean": "prediction"},
    ),
    **{
        f"ss-{aggregation}-{window}": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {"aggregation": aggregation, "window": window},
        )
        for aggregation in ("bcm", "rbcm", "gpoe", "poe")
        for window in (4, 8, 20, 50)
    },
    **{
        f"ss-manoeuvre-{intensity:g}-{probability:g}": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {"manoeuvre_intensity": intensity, "manoeuvre_probability": probability},
        )
        for intensity, probability in (
            (100.0, 0.05),
            (400.0, 0.05),
            (1600.0, 0.05),
            (400.0, 0.02),
            (400.0, 0.2),
            (400.0, 0.5),
            (400.0, 0.8),
            (1600.0, 0.2),
        )
    },
    **{
        f"ss-silence-{n}": ("agents.state_space_dgpt:StateSpaceDGPT", {"silence_particles": n})
        for n in (200, 500, 1000)
    },
    **{
        f"ss-rbcm-fixed-q{q:g}": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {"aggregation": "rbcm", "process_noise": q, "learn_process_noise": False},
        )
        for q in (1e-4, 1.0, 10.0)
    },
    **{
        f"ss-{aggregation}-local": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {
                "aggregation": aggregation,
                "association": "local",
                "manoeuvre_probability": 0.5,
                "window": 20,
                **MODEL_0_10,
            },
        )
        for aggregation in ("bcm", "rbcm")
    },
    **{
        f"ss-joint-m{intensity:g}-{probability:g}": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {
                "aggregation": "rbcm",
                "manoeuvre_intensity": intensity,
                "manoeuvre_probability": probability,
                "window": 20,
                **MODEL_0_10,
            },
        )
        for intensity, probability in (
            (0.0, 0.0),
            (100.0, 0.05),
            (400.0, 0.05),
            (1600.0, 0.05),
            (400.0, 0.2),
            (1600.0, 0.2),
            (400.0, 0.5),
        )
    },
    **{
        f"ss-turn{len(rates)}-s{stay:g}-q{q:g}": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {
                "aggregation": "rbcm",
                "turn_rates": rates,
                "mode_stay_probability": stay,
                "turn_process_noise": q,
                "manoeuvre_probability": 0.2,
                "summary_variance": "point",
            },
        )
        for rates in ((0.35, -0.35), (0.35, -0.35, 0.52, -0.52))
        for stay in (0.8, 0.9, 0.95, 0.98)
        for q in (0.5, 5.0)
    },
    **{
        f"ss-turn{len(rates)}-s{stay:g}-q{q:g}-m{intensity:g}-{probability:g}": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {
                "aggregation": "rbcm",
                "turn_rates": rates,
                "mode_stay_probability": stay,
                "turn_process_noise": q,
                "manoeuvre_intensity": intensity,
                "manoeuvre_probability": probability,
                "summary_variance": "point",
            },
        )
        for rates, stay, q, intensity, probability in (
            *(
                ((0.35, -0.35), 0.9, 5.0, intensity, probability)
                for intensity, probability in (
                    (400.0, 0.05),
                    (100.0, 0.2),
                    (0.0, 0.0),
                    (1600.0, 0.05),
                    (400.0, 0.02),
                    (1600.0, 0.02),
                )
            ),
            ((0.35, -0.35), 0.95, 5.0, 400.0, 0.05),
            ((0.35, -0.35), 0.9, 0.5, 400.0, 0.05),
            ((0.35, -0.35, 0.52, -0.52), 0.9, 5.0, 400.0, 0.05),
        )
    },
    **{
        f"ss-rbcm-p{probability:g}": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {"aggregation": "rbcm", "manoeuvre_probability": probability},
        )
        for probability in (0.02, 0.05, 0.1, 0.2)
    },
    **{
        f"ss-rbcm-silence-{n}" + ("-ba" if prior == "boundary-avoiding" else ""): (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {"aggregation": "rbcm", "silence_particles": n, "process_noise_prior": prior},
        )
        for n in (1000,)
        for prior in ("none", "boundary-avoiding")
    },
    **{
        f"ss-rbcm-silence-1000-p{probability:g}": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {
                "aggregation": "rbcm",
                "silence_particles": 1000,
                "manoeuvre_probability": probability,
            },
        )
        for probability in (0.05, 0.1)
    },
    **{
        f"ss-rbcm-silence-1000-reports-{probability:g}": _gap_end_candidate(
            probability, "summaries", 0.0
        )
        for probability in (0.0, 0.02, 0.1, 0.3, 0.6)
    },
    **{
        f"ss-rbcm-silence-1000-reports-{probability:g}-scans": _gap_end_candidate(
            probability, "scans", 0.0
        )
        for probability in (0.02, 0.1, 0.3)
    },
    **{
        f"ss-rbcm-silence-1000-reports-{probability:g}-scans-cells-{cell:g}": (
            _gap_end_candidate(probability, "scans", cell)
        )
        for probability in (0.03, 0.1, 0.3)
        for cell in (5.0, 10.0, 20.0)
    },
    **{
        f"ss-rbcm-silence-1000-search-{settle:g}-{birth:g}": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {
                "aggregation": "rbcm",
                "silence_particles": 1000,
                "search_particles": 2000,
                "search_settle_std": settle,
                "search_birth_probability": birth,
            },
        )
        for settle in (1.5, 3.0, 6.0)
        for birth in (0.05, 0.1, 0.3)
    },
    **{
        f"ss-rbcm-silence-1000-search-3-0.1-gap-{birth:g}": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {
                "aggregation": "rbcm",
                "silence_particles": 1000,
                "search_particles": 2000,
                "gap_birth_probability": birth,
            },
        )
        for birth in (0.0003, 0.001, 0.003, 0.01, 0.03, 0.1, 0.3)
    },
    **{
        f"ss-rbcm-silence-1000-turn-q{q:g}": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {"aggregation": "rbcm", "silence_particles": 1000, "turn_process_noise": q},
        )
        for q in (5.0, 10.0, 20.0, 40.0)
    },
    **{
        f"hybrid-{'region' if region else 'no-region'}": (
            "agents.hybrid:HybridFilter",
            {**SEARCHING, "reporting_region": region},
        )
        for region in (False, True)
    },
    "ss-rbcm-silence-1000-moments": (
        "agents.state_space_dgpt:StateSpaceDGPT",
        {"aggregation": "rbcm", "silence_particles": 1000, "gap_end": "moments"},
    ),
    "ss-rbcm-silence-1000-turn4": (
        "agents.state_space_dgpt:StateSpaceDGPT",
        {
            "aggregation": "rbcm",
            "silence_particles": 1000,
            "turn_rates": (0.35, -0.35, 0.52, -0.52),
        },
    ),
    **{
        f"ss-rbcm-s{stay:g}-q{q:g}": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {"aggregation": "rbcm", "mode_stay_probability": stay, "turn_process_noise": q},
        )
        for stay in (0.9, 0.95, 0.98)
        for q in (0.5, 5.0)
    },
    "ss-rbcm-0.10": (
        "agents.state_space_dgpt:StateSpaceDGPT",
        {"aggregation": "rbcm", "manoeuvre_probability": 0.2, **MODEL_0_10},
    ),
    "ss-rbcm-boundary-avoiding": (
        "agents.state_space_dgpt:StateSpaceDGPT",
        {"aggregation": "rbcm", "process_noise_prior": "boundary-avoiding"},
    ),
    **{
        f"dgpt-{aggregation}-{update}": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {"aggregation": aggregation, **SEARCHING, "expert_update": update},
        )
        for aggregation in AGGREGATIONS
        for update in EXPERT_UPDATES
    },
    **{
        f"hybrid-{update}": (
            "agents.hybrid:HybridFilter",
            {"variant": "exact", **SEARCHING, "expert_update": update},
        )
        for update in EXPERT_UPDATES
    },
    # the registered dgpt-rbcm, and with a new track's start gated on the prediction while
    # the track holds (squared Mahalanobis distance; 9.21 and 18.4: chi-square(2) at 0.99
    # and 0.9999), with clutter at every sensor
    "dgpt-rbcm-registered": (
        "agents.state_space_dgpt:StateSpaceDGPT",
        {"aggregation": "rbcm", **SEARCHING},
    ),
    **{
        f"dgpt-rbcm-start-gate-{gate:g}": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {"aggregation": "rbcm", **SEARCHING, "start_gate": gate},
        )
        for gate in (9.21, 18.4, 50.0)
    },
    "ss-point-variance": (
        "agents.state_space_dgpt:StateSpaceDGPT",
        {"aggregation": "rbcm", "summary_variance": "point"},
    ),
    **{
        f"ss-plain-bcm-{window}": (
            "agents.state_space_dgpt:StateSpaceDGPT",
            {"aggregation": "bcm", "window": window, "manoeuvre_intensity": 0.0},
        )
        for window in (20, 50, 150)
    },
}
"""Candidate models: the SE kernel around the pooled least-squares trend (``se-trend``, the
default until 0.8.0, registered as ``dgpt-rbcm-trend``; also as the centralized GP and
inside the hybrid filter), the paper's zero mean with and without bounds, the NCV kernel with
every expert's state integrated out (distributed with BCM / RBCM, and centralized), and the
NCV GP in state-space form with the broadcast posterior as every expert's prior (the default
since 0.9.0, :mod:`agents.state_space_dgpt`: ``ss-<aggregation>-<C>`` with its manoeuvre
component, ``ss-rbcm-4`` being ``dgpt-rbcm`` of 0.10.0-0.11.0 (``ss-rbcm-20`` up to 0.9.0); ``ss-manoeuvre-<q_m>-<p>`` with other
manoeuvre settings, ``ss-plain-bcm-<C>`` without, ``ss-silence-<N>`` conditioned in coverage
gaps on the silence of the sensors with N particles, ``ss-rbcm-fixed-q<q>`` with q fixed
instead of learnt over the last C steps with data). Since 0.10.0 these associate the
measurements jointly (:func:`agents.gating.target_probabilities`) with manoeuvre probability
0.2; ``ss-<aggregation>-local`` is 0.9.0's model (eq. (27) per sensor, probability 0.5, window
20) and ``ss-joint-m<q_m>-<p>`` the manoeuvre settings searched with the joint association
(window 20, the default when they were searched), both without 0.11.0's turn modes and with
a summary's variance sigma_n^2 + its spread (:data:`MODEL_0_10`). Since 0.11.0 the
defaults have coordinated-turn modes and a summary's variance is its weighted mean's:
``ss-turn<K>-s<stay>-q<q>`` adds K turn modes (+-0.35 rad/s, and +-0.52 with K = 4) that stay
with probability ``stay`` and have process noise q (``turn_rates`` of
:class:`~agents.state_space_dgpt.StateSpaceDGPT`) to 0.10.0's model, ``-m<q_m>-<p>`` with
another manoeuvre component (the search of :data:`~agents.state_space_dgpt.TURN_MODES`, all
with the summary variance ``"point"``), and ``ss-point-variance`` is the default with that
variance; ``ss-rbcm-p<p>`` is the default with manoeuvre probability p, and
``ss-rbcm-0.10`` is 0.10.0's ``dgpt-rbcm``. ``ss-rbcm-s<stay>-q<q>`` has other turn-mode
settings, ``ss-rbcm-boundary-avoiding`` climbs q with the boundary-avoiding prior
(:data:`~agents.state_space_dgpt.PROCESS_NOISE_PRIORS`), and ``ss-rbcm-silence-1000`` (with
``-ba``: and that prior) conditions on the silence of the sensors in coverage gaps with 1000
particles: it is ``dgpt-rbcm`` since 0.12.0; ``-moments`` is 0.12.0-0.14.0's ``dgpt-rbcm``,
whose prior after a gap is the particles' moments predicted, and ``-reports-<p>`` conditions
that prior on which sensors report, with a new track of prior probability p
(:data:`~agents.state_space_dgpt.GAP_ENDS`; ``hybrid-ncv-silence-1000-*`` the same inside
the hybrid), its hypotheses weighed by their summaries as up to 0.20.0; ``-reports-<p>-scans``
weighs them by the scans' evidence (:data:`~agents.state_space_dgpt.GAP_END_EVIDENCE`;
``-reports-0.1-scans`` is ``dgpt-rbcm`` of 0.21.0), both with the new track as one
Gaussian, and ``-reports-<p>-scans-cells-<c>`` spreads the new track over cells of c m
(:data:`~agents.state_space_dgpt.GAP_REGION_CELL`; ``-reports-0.1-scans-cells-10`` is
``dgpt-rbcm`` since 0.22.0). ``ss-rbcm-silence-1000-turn-q<q>`` is ``dgpt-rbcm`` with turn
process noise q (:data:`~agents.state_space_dgpt.TURN_MODES`; q 5 is the default), and
``hybrid-region`` / ``hybrid-no-region`` the registered ``hybrid`` (``hybrid-trend-region`` /
``hybrid-trend-no-region``: ``hybrid-trend``) with and without the likelihood of which
sensors report (:data:`agents.hybrid.REPORTING_REGION`). Results
in docs/analysis.md's sections before 0.10.0 came from the code of their version."""

DEFAULT_CANDIDATES = (
    "se-trend",
    "se-zero",
    "se-zero-loose",
    "se-gate-5",
    "ncv-local-bcm",
    "ncv-local-rbcm",
    "ncv-centralized",
    "ss-bcm-20",
    "ss-plain-bcm-50",
)
"""The candidates run without ``--candidates``: one of each kind (the rest are settings
searched once and documented in docs/analysis.md)."""

SCENARIOS = ("S1", "S2", "S3", "S4")
TRAJECTORIES = ("fixed", "random")
CLUTTER_RATES = (1.0, 5.0)


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--candidates",
        nargs="+",
        choices=sorted(CANDIDATES),
        default=list(DEFAULT_CANDIDATES),
        metavar="NAME",
        help=f"one or more of the {len(CANDIDATES)} candidates of CANDIDATES (an unknown name "
        "lists them all); default: " + " ".join(DEFAULT_CANDIDATES),
    )
    parser.add_argument("--seeds", type=int, default=6, help="seeds FIRST .. FIRST+N-1")
    parser.add_argument(
        "--first-seed",
        type=int,
        default=1000,
        help="first seed (default: 1000, the training seeds; 0 reports on the evaluation seeds)",
    )
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument(
        "--clutter-sensors",
        choices=("detecting", "all"),
        default="detecting",
        help="which sensors report clutter (the environment's clutter_sensors)",
    )
    parser.add_argument("--scenarios", nargs="+", choices=SCENARIOS, default=list(SCENARIOS))
    parser.add_argument(
        "--trajectories", nargs="+", choices=TRAJECTORIES, default=list(TRAJECTORIES)
    )
    parser.add_argument("--clutter-rates", nargs="+", type=float, default=list(CLUTTER_RATES))
    parser.add_argument(
        "--noise-std", type=float, default=1.0, help="sigma_z of every cell, m (default: 1)"
    )
    parser.add_argument(
        "--paired-against",
        metavar="NAME",
        choices=sorted(CANDIDATES),
        help="also print each candidate's paired difference to this one (which must be run)",
    )
    parser.add_argument(
        "--ucb-by-step",
        action="store_true",
        help="print the UCB on sensed and coverage-gap steps instead of the table",
    )
    return parser.parse_args(argv)


def print_paired(runs: dict[tuple, dict], reference: str, trajectories) -> None:
    """Per candidate and path mode, the mean of (candidate - ``reference``) 2-D RMSE (m) and
    mean-over-axes NRMSE (percentage points) over the (cell, seed) pairs both ran, +- the
    95 % Student-t half-width; ``runs`` maps (name, scenario, trajectory, clutter, seed) to
    the run's metrics."""
    print()
    print(f"paired against {reference}: candidate - {reference}, mean +- 95 % interval")
    print("candidate        paths    pairs  rmse_2d m           nrmse pp")
    names = dict.fromkeys(key[0] for key in runs if key[0] != reference)
    for name in names:
        for trajectory in trajectories:
            pairs = [
                (metrics, runs[(reference, *key[1:])])
                for key, metrics in runs.items()
                if key[0] == name and key[2] == trajectory and (reference, *key[1:]) in runs
            ]
            if len(pairs) < 2:
                continue
            rmse = np.array([mine["rmse_2d"] - theirs["rmse_2d"] for mine, theirs in pairs])
            nrmse = np.array(
                [
                    50 * (mine["nrmse_x"] + mine["nrmse_y"] - theirs["nrmse_x"] - theirs["nrmse_y"])
                    for mine, theirs in pairs
                ]
            )
            print(
                f"{name:16s} {trajectory:8s} {len(pairs):5d}"
                f"  {rmse.mean():+7.2f} +- {interval_half_width(rmse):5.2f}"
                f"  {nrmse.mean():+7.3f} +- {interval_half_width(nrmse):5.3f}"
            )


def print_ucb_by_step(units: list[RunUnit]) -> None:
    """The UCB half-width, its coverage, the RMSE and sigma per axis on sensed and gap steps,
    per candidate over all of its runs (steps before a track starts have no UCB and are left
    out)."""
    print("candidate        steps     share%  ucb_median  ucb_mean  ucb_cover%  rmse  sigma")
    by_name = collections.defaultdict(list)
    for block in make_blocks(units, 64):
        by_name[block[0].tracker].extend(episode_results(block))
    for name, results in by_name.items():
        for kind in ("sensed", "gap"):
            ucb, error, sigma = [], [], []
            for result in results:
                steps = (result.n_detecting > 0) == (kind == "sensed")
                steps &= np.all(np.isfinite(result.ucb), axis=1)
                ucb.append(result.ucb[steps].ravel())
                error.append(np.abs(result.mean - result.truth)[steps].ravel())
                sigma.append(np.sqrt(result.var[steps]).ravel())
            ucb, error, sigma = map(np.concatenate, (ucb, error, sigma))
            share = 100 * ucb.size / sum(result.ucb.size for result in results)
            print(
                f"{name:16s} {kind:7s} {share:8.1f} {np.median(ucb):11.1f} {ucb.mean():9.1f}"
                f" {100 * np.mean(error <= ucb):11.2f} {np.sqrt(np.mean(error**2)):5.1f}"
                f" {sigma.mean():6.1f}"
            )


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.seeds < 1:
        print("error: --seeds must be at least 1", file=sys.stderr)
        return 2
    if args.paired_against and args.paired_against not in args.candidates:
        print("error: --paired-against must name one of --candidates", file=sys.stderr)
        return 2
    units, keys = [], []
    for name in args.candidates:
        entry_point, kwargs = CANDIDATES[name]
        for cell in itertools.product(args.scenarios, args.trajectories, args.clutter_rates):
            scenario, trajectory, clutter = cell
            env = {
                "scenario": scenario,
                "noise_std": args.noise_std,
                "clutter_rate": clutter,
                "trajectory": trajectory,
                "clutter_sensors": args.clutter_sensors,
            }
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                units.append(RunUnit(name, entry_point, kwargs, env, seed))
                keys.append((name, *cell, seed))
    if args.ucb_by_step:
        print_ucb_by_step(units)
        return 0
    outcomes = run_units(units, workers=args.workers)
    by_cell, runs = collections.defaultdict(list), {}
    for key, outcome in zip(keys, outcomes):
        if outcome["status"] != "ok":
            print(f"failed {key}: {outcome['error']}", file=sys.stderr)
            continue
        by_cell[key[:-1]].append(outcome["metrics"])
        runs[key] = outcome["metrics"]

    def mean(rows, key):
        return float(np.nanmean([row[key] for row in rows]))

    print(
        "candidate        cell                rmse_2d  det  gap  nrmse%  nees_med_det  cov3_det%"
        "  ms  bound%  ucb%  ucb/rmse"
    )
    totals, anees = collections.defaultdict(list), collections.defaultdict(list)
    for (name, scenario, trajectory, clutter), rows in by_cell.items():
        nrmse = 50 * (mean(rows, "nrmse_x") + mean(rows, "nrmse_y"))
        coverage = 50 * (
            mean(rows, "coverage_3sigma_x_detected") + mean(rows, "coverage_3sigma_y_detected")
        )
        nees = float(np.nanmedian([row["nees_median_detected"] for row in rows]))
        rmse = mean(rows, "rmse_2d")
        at_bound = 100 * mean(rows, "share_at_bound") if "share_at_bound" in rows[0] else np.nan
        ucb_coverage = 50 * (mean(rows, "ucb_coverage_x") + mean(rows, "ucb_coverage_y"))
        # ucb_width is the full width, 2 x the half-width
        ucb_ratio = (mean(rows, "ucb_width_x") + mean(rows, "ucb_width_y")) / (
            2.0 * (mean(rows, "rmse_x") + mean(rows, "rmse_y"))
        )
        cell = f"{scenario} {trajectory:6s} c{clutter:g}"
        detected, gap = mean(rows, "rmse_2d_detected"), mean(rows, "rmse_2d_gap")
        print(
            f"{name:16s} {cell:18s} {rmse:8.2f} {detected:4.1f} {gap:4.1f} {nrmse:7.2f}"
            f" {nees:12.3f} {coverage:9.2f}"
            f" {float(np.median([row['step_time_ms'] for row in rows])):5.2f} {at_bound:6.1f}"
            f" {ucb_coverage:5.2f} {ucb_ratio:9.2f}"
        )
        totals[name].append(
            (trajectory, rmse, nrmse, nees, coverage, at_bound, ucb_coverage, ucb_ratio)
        )
        anees[name].extend(row["anees_detected"] for row in rows)
    print()
    print(
        "candidate        rmse fixed  rmse random  nrmse%  nees_med_det  cov3_det%  bound%"
        "  ucb%  ucb/rmse  anees_det median / max"
    )
    for name, cells in totals.items():
        fixed, random = (
            np.mean([c[1] for c in cells if c[0] == mode]) if mode in args.trajectories else np.nan
            for mode in TRAJECTORIES
        )
        rest = np.mean([c[2:] for c in cells], axis=0)
        print(
            f"{name:16s} {fixed:10.2f} {random:12.2f} {rest[0]:7.2f} {rest[1]:12.3f}"
            f" {rest[2]:10.2f} {rest[3]:7.1f} {rest[4]:5.2f} {rest[5]:9.2f}"
            f"  {np.nanmedian(anees[name]):.2f} / {np.nanmax(anees[name]):.3g}"
        )
    if args.paired_against:
        print_paired(runs, args.paired_against, args.trajectories)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
