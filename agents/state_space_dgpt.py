"""DGPT with the nearly-constant-velocity GP in state-space form: experts that share only the
broadcast estimate, a hyperparameter the window identifies, and a variance that is the
model's.

The target's coordinates are NCV GPs (the integrated Wiener-velocity kernel), each driven
by white acceleration of intensity q, except that at any step, with prior probability p, a
manoeuvre adds q_m (:class:`agents.state_space.Manoeuvre`). By default the target may also
turn: coordinated-turn modes (:data:`TURN_MODES`) that persist from step to step through a
Markov chain, which makes each step an IMM step over the modes (the ``turn_rates`` argument
of :class:`StateSpaceDGPT`); below, "component" is a process-noise component of the NCV
mode or a turn mode, each with its own prediction. Each step t:

1. **Prediction**: the network's broadcast posterior of each axis's state
   [position, velocity] at the last step, carried to t under each of the two intensities
   (:func:`agents.state_space.ncv_predict`): the GP prior of s_t given the past, per
   component. With turn modes the broadcast posterior is one per mode with the modes'
   probabilities; they are first mixed through the Markov chain
   (:func:`baselines.kalman.imm_mix`), and a turn mode's prediction rotates the velocity
   (:func:`agents.state_space.turn_predict`).
2. **Association**, per component: every reporting sensor weighs its measurements by the
   probability that each is the target's and reports their weighted mean, eq. (28)
   (:mod:`agents.gating`). By default (``association="joint"``) the probability is that
   of the paper's measurement model given every reporting sensor's measurements and the
   broadcast prediction (:func:`agents.gating.target_probabilities`): the target's points
   of different sensors confirm each other, clutter does not. ``"local"`` is eq. (27): the
   sensor's own measurements' predictive likelihoods under the broadcast prediction (which,
   with the prior shared, differs from an expert's own last posterior carried forward only
   by the expert's own last summary, which it already holds). A summary's variance is
   sigma_n^2 sum_j w_j^2 (the variance of the weighted mean of target points) plus the
   weighted spread of the sensor's measurements about it: a summary whose weights cannot
   tell the target from clutter counts for less (:data:`SUMMARY_VARIANCES`).
3. **Experts and aggregation**, per component: each sensor with a summary updates the
   prediction with its own measurements alone: its local posterior is the moments of the
   mixture over which of them is the target's, with the weights of step 2 (the PDA update;
   :data:`EXPERT_UPDATES`; without gating, the update with its summary); the local
   posteriors are aggregated (PoE / GPoE / BCM / RBCM, eqs. (8)-(20), on the state;
   :func:`agents.state_space.fused_update`).
4. **Mixture**: the components' aggregates are weighted by prior probability (with turn
   modes, times the mode's predicted probability) times the exact likelihood of their
   summaries (:func:`agents.state_space.step_log_likelihood`, a sum over experts like
   eq. (22)'s) and moment-matched (:func:`baselines.kalman.reduce_mixture`): the broadcast
   posterior and the estimate; with turn modes, also each mode's posterior (the moments of
   its components) and probability. The UCB
   half-width holds with probability 1 - delta under that mixture
   (:func:`agents.aggregation.mixture_half_width`): Lemma 1 on each component's aggregate,
   with the standard deviation of the aggregate's error under the model
   (:func:`agents.state_space.aggregate_error_var`; for BCM the posterior's) and the
   component's share of delta scaled by its weight, plus its distance to the estimate; the
   larger over the components. Theorem 2's form, which bounds every expert and adds the
   bounds, ignores that the experts' errors share the prior's: about sqrt(M) times wider
   with M experts of equal variance.
5. **Learning**: q of each axis climbs the exact log marginal likelihood of the last C
   steps with data, re-filtered from the broadcast posterior before the oldest of them
   with the exact (BCM) update whatever the tracker's aggregation
   (:data:`LEARNING_FILTER`): one Newton step in log q per step, from the likelihood at
   q e^(-h), q, q e^h, warm-started from the last step's q (Sec. IV-D: few iterations,
   warm-started). Steps 1-4 use q before this step's update. The window is filtered from
   each step's network-wide sums (:class:`agents.state_space.PooledSummaries`, formed once
   when the step is taken), and many episodes in lockstep are filtered together
   (:meth:`StateSpaceDGPT.update_batch`). That is ``learning="window"``, the default;
   ``learning="recursive"`` (:data:`LEARNINGS`) takes instead the maximum of every past
   step's evidence, forgotten over :data:`LEARNING_MEMORY` steps.

An expert's local posterior depends on its own summary and the broadcast prior only (with
the joint association, which of its measurements make the summary is decided with the other
reporting sensors' measurements, all within one hop of it: see
:func:`agents.gating.target_probabilities`), and
the prior carries the earlier steps exactly because the NCV GP is Markov in its state; with
BCM each component's aggregate is the exact GP posterior given every summary (the
information filter), so the predictive variance is the model's, with nothing added on. The
likelihood is the exact one of all experts' summaries, not eq. (22)'s product of local
likelihoods: with a shared prior that product counts the prior's uncertainty once per expert
and cannot tell it from the summaries' noise.

With clutter at every sensor (``clutter_sensors="all"``), the sensors that do not sense the
target are screened out before step 2, and tracks start and restart from measurements that
the other sensors covering them confirm, as DGPT's do (:class:`agents.screening.ClutterScreen`
with the broadcast prediction). With ``silence_particles`` = N > 0 (the registered trackers)
the screen weighs all scans together (N positions drawn from the prediction), a step on
which it admits no sensor is a gap step whose particles are weighted by the likelihood ratio
of every scan of the step (:func:`agents.screening.scan_log_likelihood_ratios`; the silence
is its case without points), and a step without a track returns the posterior of its scans
alone (:meth:`_scan_estimate`) instead of the area's centre. With ``search_particles`` > 0
(the registered trackers since 0.16.0) the steps before the first track are filtered
instead, from the first scan on, by :class:`agents.search.SearchFilter`, whose births from
pairs of points of consecutive steps let the motion tell the target's points from clutter;
the first track starts where it settles (:meth:`_search`), or where the screen's start
comes first. With ``gap_birth_probability`` > 0 (the registered trackers since 0.17.0) a gap
step's particles are joined by births from such pairs too (:meth:`_scan_gap_step`), so that
a target that reappears away from them is found by its motion.

With ``silence_particles`` and clutter at the detecting sensors only, a coverage gap is
filtered by particles conditioned on the silence of the awake sensors, and at the gap's end
step 1's predictions are those particles carried to the step and conditioned on which
sensors report, with a new track spread over that region's cells as more predictions
(:data:`GAP_ENDS`, :data:`GAP_REGION_CELL`), and the hypotheses are weighed by the evidence
of the step's scans (:data:`GAP_END_EVIDENCE`).

sigma_n^2 is the sensors' noise variance, ``spec.model_noise_std ** 2`` (the hybrid filter
and the Kalman trackers use it too); only q is learnt. Steps without measurements only
predict, and the variance grows as the model says. The first measurements start the state
at their coordinate-wise median with a standard deviation of the sensing range (a
detecting sensor's target is within it) and :data:`INITIAL_SPEED_STD` for the velocity.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np

from agents import aggregation as agg
from agents.gating import gate_measurements, target_probabilities
from agents.likelihood import PoissonLikelihood
from agents.particles import kernel_scale, resample_systematic
from agents.poisson_update import gaussian_sums
from agents.screening import ClutterScreen, area_log_likelihood_ratios, scan_posterior
from agents.search import SearchFilter, weighed_births
from agents.silence import (
    draw_particles,
    particle_moments,
    propagate_particles,
    region_cells,
    reporting_and_silent,
    reporting_region,
    silent_region,
)
from agents.state_space import (
    POOLED_METHODS,
    Manoeuvre,
    PooledSummaries,
    WindowStep,
    aggregate_error_cov,
    aggregate_error_var,
    bcm_window_log_likelihood,
    condition_on_position,
    expert_posteriors,
    fused_update,
    mixture_summaries,
    ncv_predict,
    pool_summaries,
    pooled_log_likelihood,
    pooled_update,
    process_noise_components,
    step_log_likelihood,
    turn_predict,
)
from baselines.kalman import imm_mix, reduce_mixture
from dgpt_gym.problem import ProblemSpec
from dgpt_gym.tracker import Estimate, TrackerBase
from dgpt_gym.validation import check_bool, check_choice, check_integer, check_real

__all__ = [
    "StateSpaceDGPT",
    "INITIAL_SPEED_STD",
    "PROCESS_NOISE_START",
    "PROCESS_NOISE_BOUNDS",
    "newton_step",
    "grid_maximum",
    "MANOEUVRE",
    "ASSOCIATIONS",
    "LEARNING_WINDOW",
    "LEARNINGS",
    "LEARNING_MEMORY",
    "LEARNING_GRID",
    "TURN_MODES",
    "SUMMARY_VARIANCES",
    "EXPERT_UPDATES",
    "PROCESS_NOISE_PRIORS",
    "GAP_ENDS",
    "GAP_END_EVIDENCE",
    "GAP_REGION_CELL",
    "GAP_REGION_COMPONENTS",
    "kept_cells",
    "GAP_RESTART_PROBABILITY",
]

SUMMARY_VARIANCES = ("mean", "point")
"""The variance of a sensor's summary (its weighted mean, eq. (28)): ``"mean"`` (the default
since 0.11.0), sigma_n^2 sum_j w_j^2 + the weighted spread of its measurements about it, and
``"point"``, sigma_n^2 + the spread. The first is the variance of the weighted mean of points
that are all the target's (a sensor can report several: lambda_T target points per step),
with the spread for the doubt about which are; the second treats the summary as one of the
sensor's points, so a sensor that reports k target points counts as one with about twice
their mean's variance and the posterior is wider than the data warrant. With turn modes on
training seeds 1012-1023 (``python scripts/model_study.py --first-seed 1012 --seeds 12
--candidates ss-rbcm-4 ss-point-variance``), ``"mean"`` against ``"point"``: RMSE 7.62 / 13.74 m
against 7.65 / 13.69 m (reference / random paths), median NEES on detected steps 0.96
against 0.81 (nominal 1.39; S1 0.75-0.80 against 0.63-0.64), 3-sigma coverage 99.29 %
against 99.43 %."""

EXPERT_UPDATES = ("summary", "mixture")
"""How an expert updates the broadcast prediction with its sensor's measurements:
``"summary"``, the Kalman update with its summary (eq. (28)) as one measurement of the
summary variance (:data:`SUMMARY_VARIANCES`); ``"mixture"``, the moments of the mixture over
which of its measurements is the target's (the PDA update), through the pseudo-measurement
of :func:`agents.state_space.mixture_summaries`. The first is narrower: its weights come
from the prediction it then updates. Either way the hypotheses are weighed by the
summaries' likelihood. ``"mixture"`` is the default with gating since 0.24.0, chosen on
training seeds 1000-1019 (S1-S4, both path modes; ``python scripts/model_study.py
--first-seed 1000 --seeds 20 --noise-std 4 --clutter-rates 5 --candidates dgpt-rbcm-summary
dgpt-rbcm-mixture --paired-against dgpt-rbcm-summary``, and the same at sigma_z 1 and 2):
DGPT-RBCM's 3-sigma coverage on detected steps went from 99.23 to 99.44 % at sigma_z 4,
clutter 5 (each of the 8 cells up; S3's reference path 99.03 to 99.62 %), 99.49 to 99.56 %
at sigma_z 2, clutter 5, and 99.78 to 99.79 % at sigma_z 1, clutter 1 and 5, with the
paired RMSE difference -0.08 +- 0.28 / -0.41 +- 0.54 m (reference / random paths),
-0.39 +- 0.43 / -0.29 +- 0.57 m and +0.24 +- 0.30 / -0.04 +- 0.21 m; GPoE 99.02 to
99.36 % and BCM 99.17 to 99.33 % at sigma_z 4, clutter 5. At clutter 20 and 50 (seeds
1000-1009) 97.90 to 98.61 %, still short of 99 %: the spread is capped (1-7 % of the
experts' updates) where the mixture is wider than the prediction."""

ASSOCIATIONS = ("joint", "local")
"""How a sensor weighs its measurements: with every reporting sensor's (``"joint"``,
:func:`agents.gating.target_probabilities`) or with its own alone (``"local"``, eq. (27))."""

LEARNING_WINDOW = 4
"""C, the default number of steps with data whose likelihood learns q. The accuracy does not
depend on it: on training seeds 1006-1017 (S1-S4, both path modes, clutter 1 and 5,
``python scripts/model_study.py --first-seed 1006 --seeds 12 --candidates ss-rbcm-20
ss-rbcm-8 ss-rbcm-4 --paired-against ss-rbcm-20``) windows 8 and 4 gave window 20's RMSE to
+0.01 +- 0.02 / -0.01 +- 0.02 m and +0.02 +- 0.02 / -0.00 +- 0.02 m (reference / random
paths) and its 3-sigma coverage to 0.01 points (seeds 1000-1005: windows 3, 4, 5 within
0.03 m), while the learning is most of a step's cost: 2.55 ms per step with window 20,
1.44 ms with 8, 1.04 ms with 4, 0.81 ms without learning (S1, clutter 1, steps with 2-3
reporting sensors). Window 4 is the cheapest of those that tie with 20 on both path modes
(window 3 was +0.03 +- 0.03 m on the reference paths). Its likelihood is flatter than window
20's, so q reaches a bound on fewer steps (45 % against 76 %): that is not a better-identified
q. (These figures are 0.10.0's model; since 0.11.0 the ``ss-rbcm-<C>`` candidates have its
turn modes.)"""

INITIAL_SPEED_STD = 25.0
"""m/s per axis: the velocity prior of a new track, the scenarios' top speed."""

PROCESS_NOISE_START = 1.0
"""q (m^2/s^3) at the first step of an episode, per axis."""

PROCESS_NOISE_BOUNDS = (1e-4, 1e6)
"""Bounds of q (m^2/s^3): only what keeps the numerics finite (an acceleration standard
deviation of 0.01 to 1000 m/s^2 over a second); a fit on them is unidentified."""
_LOG_PROCESS_NOISE_BOUNDS = tuple(np.log(PROCESS_NOISE_BOUNDS))

MANOEUVRE = {"intensity": 400.0, "probability": 0.02}
"""The default second component of the NCV mode's process noise
(:class:`agents.state_space.Manoeuvre`): q_m = 400 m^2/s^3 (an acceleration burst of about
20 m/s^2 over a step) with prior probability 0.02 per step since 0.11.0, chosen together
with :data:`TURN_MODES` (see there). Without turn modes (0.10.0) the probability was 0.2,
chosen with the joint association on training seeds (S1-S4, both
path modes, clutter 1 and 5; learning window 20, the default then): of none and q_m 100,
400, 1600 at 0.05, 400 and 1600 at 0.2 on seeds 1000-1005 (``python scripts/model_study.py --first-seed 1000 --seeds 6 --candidates
ss-joint-m0-0 ss-joint-m100-0.05 ss-joint-m400-0.05 ss-joint-m1600-0.05 ss-joint-m400-0.2
ss-joint-m1600-0.2 ss-joint-m400-0.5``), the best three and 0.9.0's 0.5 again on seeds
1006-1017 (``--first-seed 1006 --seeds 12 --candidates ss-joint-m400-0.5 ss-joint-m400-0.05
ss-joint-m1600-0.05 ss-joint-m400-0.2 --paired-against ss-joint-m400-0.2``): against 0.5,
RMSE 9.91 / 18.43 m on the reference / random paths against 11.01 / 19.00 m (paired
-1.10 +- 0.56 / -0.58 +- 0.30 m), 3-sigma coverage on detected steps 99.14 % against
98.82 %, and the learning steps with q on a bound 76 % against 92 %; probability 0.05 had
the same RMSE (-0.21 +- 0.38 / -0.07 +- 0.30 m) with coverage 98.98 % and UCB coverage
99.72 % against 99.89 %. Without the component the RMSE rose by 7.58 +- 2.87 / 6.77 +- 2.29 m
on seeds 1000-1005: the tracker loses targets after manoeuvres. With turn modes the
component still matters (without it, 3-sigma coverage on S1 at clutter 5 fell to 96.3 %),
but a probable one competes with the turn modes for the turns."""

TURN_MODES = {"rates": (0.35, -0.35), "intensity": 5.0, "stay_probability": 0.9}
"""The default coordinated-turn modes (:class:`StateSpaceDGPT`'s ``turn_rates`` (rad/s),
``turn_process_noise`` (m^2/s^3), ``mode_stay_probability``) since 0.11.0: turns of
+-0.35 rad/s (20 deg/s) that stay with probability 0.9 per step, with the manoeuvre
probability of :data:`MANOEUVRE` lowered to 0.02. Chosen on training seeds (S1-S4, both path
modes, clutter 1 and 5, RBCM): of turn rates +-0.35 or +-0.35 and +-0.52, stay probability
0.8 / 0.9 / 0.95 and process noise 0.5 / 5 with the 0.10.0 manoeuvre component on seeds
1000-1011 (``python scripts/model_study.py --first-seed 1000 --seeds 12 --candidates
ss-rbcm-0.10 ss-turn2-s0.8-q0.5 ... ss-turn4-s0.95-q5 --paired-against ss-rbcm-0.10``;
``ss-rbcm-0.10`` is 0.10.0's default, run as ``ss-rbcm-4`` then), every
candidate beat none on the random paths (-2.1 to -2.7 m) and most on the reference paths
(+-0.35 with stay 0.95 and q 0.5: -0.95 +- 0.69 m); the best three again on seeds
1012-1023 gave -0.7 to -0.9 m and -0.6 to -1.2 m. The turns gained most on S2 once the
manoeuvre component was made rarer (it explained the turns as bursts: on seeds 1000-1011,
``ss-turn2-s0.9-q5-m400-0.05`` against ``ss-turn2-s0.9-q5``, -1.49 +- 0.54 / -0.43 +- 0.47 m;
S2's reference path at clutter 5, 14.3 m to 8.3 m); of manoeuvre probabilities 0.02 and
0.05 (q_m 400 or 1600), stay 0.95 and turn noise 0.5, and four turn modes, all within
+-0.65 m of each other there, the three best on seeds 1012-1023 against 0.10.0's default
(``--first-seed 1012 --seeds 12 --candidates ss-rbcm-0.10 ss-turn2-s0.9-q5-m400-0.05
ss-turn2-s0.9-q5-m400-0.02 ss-turn2-s0.95-q5-m400-0.05 imm-pda --paired-against
ss-rbcm-0.10``): this one, -2.30 +- 0.80 / -1.95 +- 0.93 m (RMSE 7.65 / 13.69 m against
9.95 / 15.63 m; IMM-PDA 7.26 / 13.57 m), 3-sigma coverage on detected steps 99.43 % against
99.08 %. Two turn modes cost two more hypotheses per step than none; +-0.52 rad/s (S3's
rate) as well was not better (+0.65 +- 0.58 / +0.06 +- 0.30 m on seeds 1000-1011) and costs
two more.

Searched again after 0.22.0 for the 3-sigma misses at sigma_z = 4 (S3's turns at 0.52 rad/s
are 0.17 rad/s faster than the modes, about 3.2 m/s^2 unmodelled), on seeds 1000-1023
(``python scripts/model_study.py --seeds 24 --candidates ss-rbcm-silence-1000-turn-q5
ss-rbcm-silence-1000-turn-q10 ss-rbcm-silence-1000-turn-q20 ss-rbcm-silence-1000-turn-q40
ss-rbcm-silence-1000-turn4 --paired-against ss-rbcm-silence-1000-turn-q5``, with
``--noise-std 4 --clutter-rates 5``, then at sigma_z 1): at sigma_z 4, clutter 5, turn noise
10 raised the 3-sigma coverage on detected steps from 99.23 to 99.37 % (S3 reference path
99.13 to 99.63 %) at equal RMSE (+0.03 +- 0.30 / +0.09 +- 0.33 m), and the +-0.52 modes to
99.40 %; but at sigma_z 1 noise 10 cost +0.22 +- 0.10 m on the reference paths (S2's, whose
turns are at the modes' rate, 4.11 to 4.52 m at clutter 1), 20 cost +0.49 +- 0.21 m, and the
+-0.52 modes +0.10 +- 0.13 / +0.12 +- 0.23 m. Kept at 5."""

GAP_ENDS = ("moments", "reports")
"""The prior of the first step with data after a coverage gap (with ``silence_particles``
and clutter at the detecting sensors only). ``"moments"`` (up to 0.14.0) predicts the gap's
last particles' moments by the model, as on a step without a gap. ``"reports"`` (the
default) carries the gap's particles to the step and weighs them by which sensors report:
with clutter only where the target is sensed, an awake sensor reports exactly when the
target is in its disc, so the target is in every reporting sensor's disc and in no silent
one's (:func:`agents.silence.reporting_region`). Each mode's prediction is the moments of
its particles there; with prior probability :data:`GAP_RESTART_PROBABILITY`, a new track
is anywhere in that region (since 0.22.0 one prediction per kept cell,
:data:`GAP_REGION_CELL`), for a target that turned where the particles did not follow (and
the only predictions, in every mode, when no particle is there).
That share is a fixed prior, not the posterior given the reports, which would weigh the
particles by their mass in the region: a robust prior against a gap model that misses
turns, and chosen as such below.

Why: on S1's reference path at clutter 5, 3-sigma coverage on detected steps was 98.1 %,
and its misses were the first three steps after a gap (15 %, 10 % and 6 % of their axes
against 0.15 % from the sixth step on; training seeds 1000-1029). A waypoint turn in the
gap leaves the particles' moments narrow and tens of metres off, often outside the disc
of the sensor that re-acquires the target, and the association then takes a clutter point
near them. Chosen on training seeds 1000-1011 (S1-S4, both path modes, clutter 1 and 5;
``python scripts/model_study.py --first-seed 1000 --seeds 12 --candidates
ss-rbcm-silence-1000-moments ss-rbcm-silence-1000-reports-0 ss-rbcm-silence-1000-reports-0.02
ss-rbcm-silence-1000-reports-0.1 ss-rbcm-silence-1000-reports-0.3
ss-rbcm-silence-1000-reports-0.6 --paired-against ss-rbcm-silence-1000-moments``): the region alone
(probability 0) left S1 at clutter 5 at 97.93 %; probabilities 0.02, 0.1, 0.3 and 0.6 took
it to 98.69, 98.90, 99.07 and 99.24 %, but 0.3 and 0.6 cost RMSE on S2 and S3 (+0.10 +- 0.23
and +0.14 +- 0.29 m on the reference paths), 0.1 none (-0.00 +- 0.17 / +0.09 +- 0.31 m on
the reference / random paths; 3-sigma coverage over all cells 99.60 to 99.73 %, UCB
coverage 99.84 to 99.91 %). Confirmed on seeds 1012-1023 (S1 at clutter 5 98.21 to
98.86 %, RMSE -0.07 +- 0.17 / -0.03 +- 0.31 m)."""

SEARCH = {"process_noise": 25.0, "birth_probability": 0.1, "settle_std": 3.0}
"""The search filter's settings (:class:`agents.search.SearchFilter`; with clutter at every
sensor and ``search_particles`` > 0): the NCV intensity of its particles (m^2/s^3), the
prior probability per step of a target somewhere new, and the position standard deviation
(m) at which a track starts from it."""

GAP_RESTART_PROBABILITY = 0.1
"""The prior probability of the new-track prediction at the end of a coverage gap
(:data:`GAP_ENDS`), chosen there."""

GAP_END_EVIDENCE = ("scans", "summaries")
"""What weighs the hypotheses at the end of a coverage gap (``gap_end="reports"``, with
clutter at the detecting sensors only; :data:`GAP_ENDS`). ``"summaries"`` (up to 0.20.0), as
on every other step: each hypothesis's prior probability times the likelihood of the
summaries its own association made. ``"scans"`` (the default): its prior probability times
its evidence, the integral of its Gaussian prediction against the likelihood of every
point of the step under the environment's model (each reporting sensor reports at least one
target point, the rest clutter; :func:`agents.poisson_update.gaussian_sums`, the hybrid's
update). The experts' update is the same under both; only the hypotheses' weights change.

Why: at a gap's end the hypotheses differ as at no other step, narrow particle predictions
that a turn in the gap may have left tens of metres off, and a new track spread over the
reporting region. A clutter point near a wrong narrow prediction makes its summary likely,
and a wide prediction's summary (a weighted mean of every point) is unlikely however well
its points agree. The evidence weighs the scan instead: two points from one spot, or from
two sensors, are far likelier from a target than from clutter, wherever the prediction put
it. On the other steps the hypotheses (IMM modes, process-noise components) share a mean
and the summaries weigh them well; the evidence there cost more than the step itself.

Chosen on training seeds 1000-1023 (S1-S4, both path modes, clutter 1 and 5, sigma_z 1;
``python scripts/model_study.py --first-seed 1000 --seeds 24 --candidates
ss-rbcm-silence-1000-reports-0.1 ss-rbcm-silence-1000-reports-0.02-scans
ss-rbcm-silence-1000-reports-0.1-scans ss-rbcm-silence-1000-reports-0.3-scans
--paired-against ss-rbcm-silence-1000-reports-0.1``, 2 min). With the new-track
probability 0.1 kept, ``"scans"`` took S1's reference path at clutter 5 from 98.88 to
99.26 % 3-sigma coverage on detected steps (mean of the axes), all cells from 99.70 to
99.74 %, at RMSE -0.09 +- 0.09 / +0.04 +- 0.06 m (reference / random paths, paired). A
new-track probability of 0.3 with it reached 99.45 % on S1 but cost RMSE on S2's and S3's
reference paths (5.29 to 5.81 m and 8.12 to 8.45 m at clutter 5); 0.02 reached 98.98 %.
At clutter 5 with sigma_z 2 (``--noise-std 2 --clutter-rates 5``) S1's reference path went
from 98.95 to 99.17 %, RMSE -0.07 +- 0.15 / -0.01 +- 0.16 m; with sigma_z 4 from 98.50 to
98.55 % only, -0.09 +- 0.24 / -0.09 +- 0.16 m: points 4 m apart agree by chance far more
often, and the evidence separates target from clutter less. Tried on the same seeds, not
kept: the evidence on every step with data (clutter 5, reference paths): S1 99.40 % at
sigma_z 1 and 98.83 % at 4, RMSE -0.30 +- 0.23 m at sigma_z 1, but a step of 1.6-1.9 ms
against 0.7 ms."""

GAP_REGION_CELL = 10.0
"""m: the side of the cells over which a new track at a coverage gap's end is spread
(``StateSpaceDGPT(gap_region_cell=...)``; 0 gives one Gaussian, the region's moments, as up
to 0.21.0). The target is anywhere in the region where exactly the reporting sensors see it:
a uniform density, which the cells' Gaussians (:func:`agents.silence.region_cells`)
represent and one Gaussian does not; the cells near the points become hypotheses
(:data:`GAP_REGION_COMPONENTS`). The region is often a crescent, a disc less its silent
neighbours' discs, whose moments put the mass at its middle, where it may not even be; a
target that reappears at the region's edge then has its point weighed down against clutter
near the middle by the Gaussian's tail. With the cells, every point in the region is as
likely a priori (to the cells' blur of its edges), and the scans' evidence
(:data:`GAP_END_EVIDENCE`, which the cells need) picks the cells near the points.

Why: on S1's reference path at clutter 5 the 3-sigma misses on detected steps were still
the gap ends (training seeds 1000-1099, sigma_z 4, ``python scripts/calibration_misses.py
--scenario S1 --clutter-rate 5 --noise-std 4``: 7.3 % of their axes outside, against 1.4 %
of all detected steps). At S1's waypoint turn the particles' predictions lay 60 m
off, the region's moments 2 sigma short of the target, and the target's one point lost to
clutter nearer the middle.

Chosen on training seeds 1000-1023 (S1-S4, both path modes, clutter 1 and 5; ``python
scripts/model_study.py --first-seed 1000 --seeds 24 --candidates
ss-rbcm-silence-1000-reports-0.1-scans ss-rbcm-silence-1000-reports-0.1-scans-cells-5
ss-rbcm-silence-1000-reports-0.1-scans-cells-10 ss-rbcm-silence-1000-reports-0.1-scans-cells-20
ss-rbcm-silence-1000-reports-0.03-scans-cells-10 ss-rbcm-silence-1000-reports-0.3-scans-cells-10
--paired-against ss-rbcm-silence-1000-reports-0.1-scans``, 3 min; the same with ``--noise-std 4
--clutter-rates 5``, 1 min). Against one Gaussian, cells of 10 m changed the RMSE by
-0.07 +- 0.10 / -0.19 +- 0.16 m at sigma_z 1 (reference / random paths, paired) and by
-0.55 +- 0.42 / -0.29 +- 0.33 m at sigma_z 4, and took 3-sigma coverage on detected steps on
S1's reference path at clutter 5 from 99.26 to 99.64 % (sigma_z 1) and from 98.55 to
99.17 % (sigma_z 4); over all cells from 99.74 to 99.77 % and from 99.13 to 99.23 %. Cells of
5 m tied (-0.06 +- 0.11 / -0.27 +- 0.20 m; S1 99.74 and 99.21 %) with four times the
cells, 20 m were a little worse on S1 (99.60 %). The new-track probability stays 0.1:
0.03 gave 99.57 / 98.69 % on S1, and 0.3 cost S2's reference path at clutter 5 (5.36 to
6.74 m) as with one Gaussian. The median step per cell was 0.62-1.06 ms against
0.60-0.98 ms in the same run (the random paths have more gap ends)."""

GAP_REGION_COMPONENTS = 16
"""The most cells of :data:`GAP_REGION_CELL` kept as hypotheses at a gap's end
(:func:`kept_cells`): those with the largest share times evidence, their shares scaled so
that they carry the whole region's share times evidence. Each point is near about four
cells (their standard deviation is half their spacing), so at clutter rate 5, with five
or more points in a disc, the cells of the least likely points are dropped: the new track's
weight against the particles' stays exact, and its posterior is that of the likeliest
points."""

_NEGLIGIBLE_SHARE = 1e-9


def kept_cells(log_scores: np.ndarray, count: int) -> tuple[np.ndarray, float]:
    """Which of a new track's cells become hypotheses, from their ``log_scores`` (K,), each
    cell's log share plus its log evidence: the indices of the ``count`` largest, less those
    below 1e-9 of the largest, and the log factor by which their shares are scaled so that
    the kept cells' total score is all cells', log sum_k e^(score_k) - log sum_kept
    e^(score_k). Scores that are not finite count as -inf; if none is finite, the first
    ``count`` cells are kept unscaled (the new track then has no weight)."""
    scores = np.where(np.isfinite(log_scores), log_scores, -np.inf)
    order = np.argsort(-scores, kind="stable")[:count]
    best = scores[order[0]]
    if not np.isfinite(best):
        return order, 0.0
    order = order[scores[order] >= best + np.log(_NEGLIGIBLE_SHARE)]
    return order, float(np.logaddexp.reduce(scores) - np.logaddexp.reduce(scores[order]))


PROCESS_NOISE_PRIORS = ("boundary-avoiding", "none")
"""What q's climb maximises besides the window's log marginal likelihood (step 5 of the module
docstring): ``"boundary-avoiding"`` adds log sqrt(q) per axis, the log density of a
Gamma(2, rate -> 0) prior on the acceleration's standard deviation sqrt(q) (Chung et al.,
2013, "A nondegenerate penalized likelihood estimator for variance parameters in multilevel
models", Psychometrika 78(4)): a penalty that tends to -infinity as q tends to 0 and is
nearly flat elsewhere (its slope in log q is 1/2), so the maximum is never q = 0 (in
practice the lower bound of :data:`PROCESS_NOISE_BOUNDS`) when a short window's likelihood
is flat there. ``"none"`` (the default) maximises the likelihood alone.

Why the default stays ``"none"``: the prior takes every learning step off the bound (from
28 % of them on training seeds 1000-1005), but the window's likelihood is so flat that the
slope of 1/2 carries q far: S1's median q went from 1e-4 to 2.7 m^2/s^3 (the legs' true
intensity is 0.04), S4's from 20 to 37, and the RMSE rose by 1.62 +- 0.70 / 0.30 +- 0.30 m
on the reference / random paths (``python scripts/model_study.py --first-seed 1000 --seeds
6 --candidates ss-rbcm-4 ss-rbcm-boundary-avoiding --paired-against ss-rbcm-4``); with the
silence of the sensors it was +1.78 +- 0.46 / +0.52 +- 0.29 m against the same tracker
without the prior (``ss-rbcm-silence-1000`` and ``-ba``, seeds 1000-1011). A q at the bound
is the maximum-likelihood answer for a window that cannot tell S1's small intensity from 0."""

LOG_STEP = 0.05
"""h: the log-space step of the finite differences of the Newton step."""

LEARNINGS = ("window", "recursive")
"""How q is learnt (step 5 of the module docstring). ``"window"``: one Newton step per step
on the exact likelihood of the last C steps with data under the NCV mode with its manoeuvre
component (the default). ``"recursive"``: the maximum of the tracker's own step
evidences over the episode so far (across a track's restarts, as q itself), each step's
forgotten by a factor 1 - 1 / ``learning_memory`` (:data:`LEARNING_MEMORY`) per step after
it. Each step with data (not a track's first, not a gap's end, whose predictions do not
come from q) evaluates its evidence (the full model's: the log of the hypotheses' summed
weights, turn modes included) at every q of :data:`LEARNING_GRID`, one axis at a time with
the other's q as it was, adds it to the forgotten sums, and each axis's q is their maximum
(:func:`grid_maximum`). Only the step's own prediction varies with q (the earlier
posteriors are held at the q they used), a recursive prediction-error estimate, not the
re-filtered likelihood of the whole episode: at the true q the innovations' variance
equals the predicted one, so the estimate is consistent. No prior: a maximum on the grid's
end point is the likelihood's answer and counts as on a bound (the window's learning counts
q within 1e-6 of a bound in log q; here a maximum within half a grid step of an end, a
factor 1.33, counts).

Why it is not the default: it answers whether more data than four steps identifies q, and it
does not. Under the default model (turn modes, the manoeuvre component) the whole episode's
evidence puts q on its lower bound on most steps, since the turn modes and the manoeuvre
component carry the motion: on training seeds 1000-1023 (``python scripts/ablations.py
--first-seed 1000 --runs 24 --arms dgpt-rbcm/recursive-learning dgpt-rbcm/q-floor``; S1-S4,
both path modes, clutter 1 and 5, RBCM) 85 / 87 % of its learning steps ended on the bound
(reference / random paths), against 28 / 31 % for the window's, at the same calibration
and about the same accuracy (paired RMSE +0.02 +- 0.20 / -0.13 +- 0.12 m; 3-sigma coverage
on detected steps 99.73 / 99.82 % against 99.74 / 99.80 %), while q held on the bound was
-0.07 +- 0.07 / -0.31 +- 0.21 m from the window's. The truth is q = 0.04 m^2/s^3 within S1's
legs (:class:`dgpt_gym.scenarios.NearlyConstantVelocityScenario`), 0 between S2's and S3's
turns; S4's motion is not NCV. The window's learning leaves the bound more often only
because four steps' likelihood is too flat to say where q is (:data:`LEARNING_WINDOW`); a
prior that keeps q off the bound moves it far from the truth (:data:`PROCESS_NOISE_PRIORS`).
docs/analysis.md, "Does more data identify q?", has the held-out figures."""

LEARNING_MEMORY = 50.0
"""The recursive learning's memory, in steps with data: each step's evidence is forgotten by
a factor 1 - 1/50 per step after it, a third of an episode of 150 steps, so that q can
follow a change of motion within an episode. Set before any run, not tuned."""

LEARNING_GRID = np.geomspace(*PROCESS_NOISE_BOUNDS, 41)
"""The values of q (m^2/s^3) at which the recursive learning sums the steps' evidences:
:data:`PROCESS_NOISE_BOUNDS`, four per decade; the maximum between them is the parabola's
through the best three."""

MAX_LOG_STEP = 1.0
"""The largest change of log q in one step."""

LEARNING_FILTER = "bcm"
"""The aggregation that filters the learning window, whatever the tracker's: BCM's aggregate
is the exact posterior, so the window's likelihood is the model's marginal likelihood of the
summaries, which q is meant to maximise; the tracker's own aggregation only makes the
estimate. It needs only the network-wide sums of each step
(:class:`agents.state_space.PooledSummaries`), so every tracker's window is filtered in
lockstep with the others'. Against each aggregation's own filter on training seeds 1000-1003
(``python scripts/model_study.py --seeds 4 --candidates ss-rbcm-20 ss-gpoe-20 ss-poe-20``,
RMSE on the reference / random paths): RBCM 13.84 / 23.19 m with either, GPoE 13.78 / 23.08
against 13.78 / 23.11 m, PoE 13.99 / 23.55 against 13.98 / 23.56 m; the share of learning
steps on a bound rose for GPoE (76 to 91 %) and PoE (83 to 90 %) to BCM's and RBCM's 92 %."""

_BOUND_TOLERANCE = 1e-6

_TINY_PROBABILITY = 1e-300
"""Added to the target probabilities before their log: a sensor all of whose points have
probability 0 in floating point gets their unweighted mean, finite, whose spread makes it
count little."""

_TRIAL_OFFSETS = np.array([0.0, LOG_STEP, -LOG_STEP])
"""log q + these: the three likelihoods of a Newton step (:func:`newton_step`'s order)."""


def newton_step(values: np.ndarray, h: float, max_step: float) -> np.ndarray:
    """The change of x that climbs f by one Newton step from ``values`` (3, ...) =
    f(x), f(x + h), f(x - h): -f'/f'' from the central differences where f'' < 0, else
    ``max_step`` in the direction of f'; clipped to +-``max_step``. 0 where f(x) is not
    finite; a non-finite neighbour is a step away from it."""
    centre, up, down = values
    both = np.isfinite(up) & np.isfinite(down)
    slope = np.where(both, (up - down) / (2.0 * h), np.nan)
    slope = np.where(np.isfinite(up) & ~np.isfinite(down), 1.0, slope)
    slope = np.where(~np.isfinite(up) & np.isfinite(down), -1.0, slope)
    curvature = np.where(both, (up - 2.0 * centre + down) / (h * h), np.nan)
    newton = np.where(curvature < 0, -slope / np.where(curvature < 0, curvature, -1.0), np.nan)
    step = np.where(np.isfinite(newton), newton, max_step * np.sign(slope))
    step = np.where(np.isfinite(centre) & np.isfinite(step), step, 0.0)
    return np.minimum(np.maximum(step, -max_step), max_step)  # np.clip's result, faster


def grid_maximum(values: np.ndarray, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The maximum over x of a function known at the evenly spaced points ``grid`` (K,),
    ``values`` (K, ...), all finite: at the vertex of the best point's parabola through it
    and its two neighbours (within half a spacing of it, since the best point is the largest
    of the three; a tie takes the first, so an inner best point is above the point before it
    and the parabola is strictly concave), or at the end of the grid when the best point is
    an end. Returns the maximum's x (...) and whether it is an end (...)."""
    if len(grid) < 3 or np.shape(values)[0] != len(grid):
        raise ValueError(
            "grid_maximum needs a grid of at least 3 points and values of the same length "
            f"on axis 0; got grid of {len(grid)} and values of shape {np.shape(values)}"
        )
    best = np.argmax(values, axis=0)
    inner = np.clip(best, 1, len(grid) - 2)
    below = np.take_along_axis(values, (inner - 1)[None], axis=0)[0]
    centre = np.take_along_axis(values, inner[None], axis=0)[0]
    above = np.take_along_axis(values, (inner + 1)[None], axis=0)[0]
    curvature = below - 2.0 * centre + above
    spacing = grid[1] - grid[0]
    with np.errstate(divide="ignore", invalid="ignore"):  # at an end, where it is not used
        offset = 0.5 * spacing * (below - above) / curvature
    on_edge = (best == 0) | (best == len(grid) - 1)
    return np.where(on_edge, grid[best], grid[inner] + offset), on_edge


class StateSpaceDGPT(TrackerBase):
    """Distributed GP tracker with the NCV kernel in state-space form (module docstring).

    Args:
        aggregation: ``"poe"``, ``"gpoe"``, ``"bcm"`` or ``"rbcm"``; BCM is the exact
            posterior here.
        window: C, the steps with data whose likelihood learns q with ``learning="window"``
            (:data:`LEARNING_WINDOW`).
        delta: total failure probability of the UCB, in (0, 1).
        gating: weigh each sensor's measurements (step 2); False takes their unweighted
            mean, and the experts then update with it as a summary (``expert_update``).
        manoeuvre_intensity: q_m (m^2/s^3), the extra white-acceleration intensity of a
            manoeuvre step (:class:`agents.state_space.Manoeuvre`); 0 gives the plain NCV GP.
        manoeuvre_probability: the prior probability of a manoeuvre at each step, in [0, 1).
        admission_probability: with ``clutter_sensors="all"`` only: a reporting sensor's
            measurements are used when its posterior probability of sensing the predicted
            target is at least this (:class:`agents.screening.ClutterScreen`; DGPT's 1/2).
        start_gate: with ``clutter_sensors="all"`` only: None lets a new track start at any
            measurement when no reporting sensor is admitted; a number g lets it start, while
            the track holds, only at a measurement whose squared Mahalanobis distance to the
            predicted position (the prediction's variance plus the noise's) is at most g
            (:class:`agents.screening.ClutterScreen`).
        process_noise: q (m^2/s^3) at the first step of an episode, per axis (the learning
            moves it from there), within :data:`PROCESS_NOISE_BOUNDS`.
        learn_process_noise: False keeps q at ``process_noise`` (the ablation "learning
            off").
        silence_particles: 0 (the default) predicts through a coverage gap as the model
            says; N >= 10 also conditions on the silence of every awake sensor (the target
            is in no awake sensor's disc and inside the area) with N particles drawn from
            the state at the gap's first step and collapsed to their moments at the next step
            with data (:mod:`agents.silence`; seeded by ``reset(seed)``). The estimate and
            variance in the gap are the moments of the particles' kernel density
            (:meth:`_silent_step`) and the UCB holds under that kernel density. The registered
            ``dgpt-*`` and ``gp`` use N = 1000 (:data:`agents.registration.SILENCE_PARTICLES`).
            With ``clutter_sensors="all"`` N also sets the screen's draws and the gap
            particles weigh every scan (module docstring).
        association: ``"joint"`` or ``"local"`` (:data:`ASSOCIATIONS`, step 2 of the module
            docstring).
        turn_rates: omega (rad/s) of each coordinated-turn mode beside the NCV mode (empty:
            none, the model of the module docstring). With turn modes the broadcast
            posterior is one Gaussian per mode and their probabilities, and each step is an
            IMM step (Blom & Bar-Shalom 1988) whose modes are this GP's: the modes' posteriors
            are mixed through the Markov chain of ``mode_stay_probability``
            (:func:`baselines.kalman.imm_mix`, per axis); the NCV mode predicts with its two
            process-noise components, a turn mode rotates the velocity
            (:func:`agents.state_space.turn_predict`); every prediction is a hypothesis of
            steps 2-3 with its mode's predicted probability, and each mode's posterior and
            probability is the likelihood-weighted mixture of its hypotheses. A turn carries
            through a coverage gap when its mode persists. q is learnt for the NCV mode.
        turn_process_noise: q (m^2/s^3) of the turn modes, fixed.
        mode_stay_probability: P(mode j at t | mode j at t - 1) of the modes' Markov chain,
            the rest spread evenly over the other modes, in [0, 1].
        summary_variance: ``"mean"`` or ``"point"`` (:data:`SUMMARY_VARIANCES`).
        expert_update: ``"summary"`` or ``"mixture"`` (:data:`EXPERT_UPDATES`); None
            (the default) is ``"mixture"`` with ``gating`` and ``"summary"`` without. The
            mixture is the posterior only with the association's weights: with equal ones
            its mean moves the whole Kalman gain toward the unweighted mean however spread
            the points are, where the summary update counts the spread as noise (held out,
            ``scripts/ablations.py``: +21.3 m against the default with the mixture in 0.24.0,
            +9.5 m with the summary update in 0.24.2), so ``gating=False`` with
            ``"mixture"`` is refused.
        process_noise_prior: ``"boundary-avoiding"`` or ``"none"``: the penalty q's climb
            adds to the window's likelihood (:data:`PROCESS_NOISE_PRIORS`).
        gap_end: ``"reports"`` or ``"moments"``: the prior of the first step with data after
            a coverage gap, with ``silence_particles`` and clutter at the detecting sensors
            (:data:`GAP_ENDS`).
        gap_restart_probability: the prior probability of a new track there, in [0, 1)
            (:data:`GAP_RESTART_PROBABILITY`).
        gap_end_evidence: ``"scans"`` or ``"summaries"``: what weighs the hypotheses there
            (:data:`GAP_END_EVIDENCE`).
        gap_region_cell: m, the side of the cells over which the new track there is spread:
            0 gives one Gaussian, else at least 1 (:data:`GAP_REGION_CELL`). With
            ``gap_end="reports"``, cells need ``gap_end_evidence="scans"``.
        search_particles: with clutter at every sensor only: 0 (off), or N >= 10 particles of
            the search before the first track (:class:`agents.search.SearchFilter`; the
            registered trackers use :data:`agents.registration.SEARCH_PARTICLES`).
        search_settle_std: m, the search's position standard deviation per axis at which
            the first track starts (:data:`SEARCH`).
        search_birth_probability: the search's prior probability per step of a target
            somewhere new, in (0, 1) (:data:`SEARCH`).
        gap_birth_probability: with clutter at every sensor and ``silence_particles``: the
            prior probability per gap step that the target is somewhere new, whose particles
            are born from pairs of points of consecutive steps (:meth:`_scan_gap_step`), in
            [0, 1); 0 (the default) turns the births off.
        learning: ``"window"`` or ``"recursive"`` (:data:`LEARNINGS`): how q is learnt.
        learning_memory: with ``learning="recursive"``: the steps with data over which a
            step's evidence is forgotten, at least 1 (:data:`LEARNING_MEMORY`).
    """

    name = "dgpt-bcm"

    def __init__(
        self,
        aggregation: str = "bcm",
        window: int = LEARNING_WINDOW,
        delta: float = 0.003,
        gating: bool = True,
        manoeuvre_intensity: float = MANOEUVRE["intensity"],
        manoeuvre_probability: float = MANOEUVRE["probability"],
        admission_probability: float = 0.5,
        start_gate: float | None = None,
        process_noise: float = PROCESS_NOISE_START,
        learn_process_noise: bool = True,
        silence_particles: int = 0,
        association: str = "joint",
        turn_rates: Sequence[float] = TURN_MODES["rates"],
        turn_process_noise: float = TURN_MODES["intensity"],
        mode_stay_probability: float = TURN_MODES["stay_probability"],
        summary_variance: str = "mean",
        expert_update: str | None = None,
        process_noise_prior: str = "none",
        gap_end: str = "reports",
        gap_restart_probability: float = GAP_RESTART_PROBABILITY,
        gap_end_evidence: str = "scans",
        gap_region_cell: float = GAP_REGION_CELL,
        search_particles: int = 0,
        search_settle_std: float = SEARCH["settle_std"],
        search_birth_probability: float = SEARCH["birth_probability"],
        gap_birth_probability: float = 0.0,
        learning: str = "window",
        learning_memory: float = LEARNING_MEMORY,
    ) -> None:
        self.aggregation = check_choice("aggregation", aggregation, agg.AGGREGATIONS)
        self.window = check_integer("window", window, low=1)
        self.delta = check_real(
            "delta", delta, low=0.0, high=1.0, low_inclusive=False, high_inclusive=False
        )
        self.gating = check_bool("gating", gating)
        intensity = check_real("manoeuvre_intensity", manoeuvre_intensity, low=0.0)
        probability = check_real(
            "manoeuvre_probability", manoeuvre_probability, low=0.0, high=1.0, high_inclusive=False
        )
        self.manoeuvre = (
            Manoeuvre(intensity, probability) if intensity > 0 and probability > 0 else None
        )
        self.admission_probability = check_real(
            "admission_probability", admission_probability, low=0.0, high=1.0, low_inclusive=False
        )
        self.start_gate = (
            None if start_gate is None else check_real("start_gate", start_gate, low=0.0)
        )
        self.process_noise = check_real(
            "process_noise",
            process_noise,
            low=PROCESS_NOISE_BOUNDS[0],
            high=PROCESS_NOISE_BOUNDS[1],
        )
        self.learn_process_noise = check_bool("learn_process_noise", learn_process_noise)
        self.learning = check_choice("learning", learning, LEARNINGS)
        self.learning_memory = check_real("learning_memory", learning_memory, low=1.0)
        self.silence_particles = check_integer("silence_particles", silence_particles, low=0)
        if 0 < self.silence_particles < 10:
            raise ValueError(
                f"silence_particles must be 0 (off) or at least 10; got {silence_particles!r}"
            )
        self.association = check_choice("association", association, ASSOCIATIONS)
        self.summary_variance = check_choice(
            "summary_variance", summary_variance, SUMMARY_VARIANCES
        )
        if expert_update is None:
            expert_update = "mixture" if self.gating else "summary"
        self.expert_update = check_choice("expert_update", expert_update, EXPERT_UPDATES)
        if self.expert_update == "mixture" and not self.gating:
            raise ValueError(
                "expert_update='mixture' needs the association's weights (gating=True); "
                "with gating=False use expert_update='summary' or None"
            )
        self.process_noise_prior = check_choice(
            "process_noise_prior", process_noise_prior, PROCESS_NOISE_PRIORS
        )
        if self.learning == "recursive" and self.process_noise_prior != "none":
            raise ValueError(
                "process_noise_prior applies to learning='window' only; got "
                f"process_noise_prior={process_noise_prior!r} with learning='recursive'"
            )
        self.gap_end = check_choice("gap_end", gap_end, GAP_ENDS)
        self.gap_restart_probability = check_real(
            "gap_restart_probability",
            gap_restart_probability,
            low=0.0,
            high=1.0,
            high_inclusive=False,
        )
        self.gap_end_evidence = check_choice("gap_end_evidence", gap_end_evidence, GAP_END_EVIDENCE)
        self.gap_region_cell = check_real("gap_region_cell", gap_region_cell, low=0.0)
        if 0 < self.gap_region_cell < 1:
            raise ValueError(
                "gap_region_cell must be 0 (one Gaussian) or at least 1 m (a lattice of "
                f"cells over a region up to 100 m wide); got {gap_region_cell!r}"
            )
        uses_cells = self.gap_region_cell > 0 and self.gap_end == "reports"
        if uses_cells and self.gap_end_evidence != "scans":
            raise ValueError(
                "gap_region_cell: cells (> 0) need gap_end_evidence='scans', which picks "
                f"them; got gap_region_cell={gap_region_cell!r} with gap_end_evidence="
                f"{gap_end_evidence!r} (set gap_region_cell=0 for one Gaussian)"
            )
        self.search_particles = check_integer("search_particles", search_particles, low=0)
        if 0 < self.search_particles < 10:
            raise ValueError(
                f"search_particles must be 0 (off) or at least 10; got {search_particles!r}"
            )
        self.search_settle_std = check_real(
            "search_settle_std", search_settle_std, low=0.0, low_inclusive=False
        )
        self.search_birth_probability = check_real(
            "search_birth_probability",
            search_birth_probability,
            low=0.0,
            high=1.0,
            low_inclusive=False,
            high_inclusive=False,
        )
        self.gap_birth_probability = check_real(
            "gap_birth_probability",
            gap_birth_probability,
            low=0.0,
            high=1.0,
            high_inclusive=False,
        )
        try:
            rates = tuple(turn_rates)
        except TypeError:
            raise ValueError(
                f"turn_rates must be a sequence of turn rates in rad/s; got {turn_rates!r}"
            ) from None
        self.turn_rates = tuple(
            check_real(f"turn_rates[{index}]", rate) for index, rate in enumerate(rates)
        )
        self.turn_process_noise = check_real("turn_process_noise", turn_process_noise, low=0.0)
        self.mode_stay_probability = check_real(
            "mode_stay_probability", mode_stay_probability, low=0.0, high=1.0
        )
        n_modes = 1 + len(self.turn_rates)
        self.mode_transition = np.full(
            (n_modes, n_modes), (1.0 - self.mode_stay_probability) / max(n_modes - 1, 1)
        )
        np.fill_diagonal(self.mode_transition, self.mode_stay_probability if n_modes > 1 else 1.0)
        self.name = f"dgpt-{self.aggregation}"

    def reset(self, spec: ProblemSpec, seed: int | None = None) -> None:
        self.spec_ = spec
        self.noise_var_ = spec.model_noise_std**2
        self.log_q_ = np.full(2, np.log(self.process_noise))
        self.rng_ = np.random.default_rng(seed)  # the gap particles' and the screen's draws
        self.screen_ = ClutterScreen(
            spec,
            self.admission_probability,
            self.silence_particles,
            self.rng_,
            start_gate=self.start_gate,
        )
        self.search_ = None  # before the first track, with clutter at every sensor
        if self.search_particles and spec.clutter_sensors == "all" and spec.clutter_rate > 0:
            self.search_ = SearchFilter(
                spec,
                self.search_particles,
                # its own stream (Generator.spawn's child): the tracker's draws stay as they were
                np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0]),
                INITIAL_SPEED_STD,
                SEARCH["process_noise"],
                self.search_birth_probability,
                self.search_settle_std,
            )
        self.search_estimate_ = None
        # with clutter at every sensor: the last two steps' scans, (points, sensors, awake,
        # step) each, for the births of a gap's particles
        self.previous_scan_ = self.this_scan_ = None
        self.prior_next_ = None  # (mean, var) (2,) of the position at the next step
        self.next_state_ = None  # (mean (2, 2), cov (2, 2, 2)) of the state at the next step
        self.prior_state_ = None  # the same, made at the last step for this one
        self.next_modes_ = self.prior_modes_ = None  # with turn modes: the same per mode
        # the last step's predictions, one per hypothesis, for the hybrid filter: log prior
        # probabilities (H,), means (H, 2, 2), covs (H, 2, 2, 2), modes (H,) or None; and
        # whether the last step started a track
        self.step_predictions_ = None
        self.new_track_ = False
        self.fits_ = 0
        self.fits_at_bound_ = 0
        # the recursive learning's forgotten sums of the steps' log evidences at
        # LEARNING_GRID (K, axis)
        self.evidence_sums_ = np.zeros((len(LEARNING_GRID), 2))
        self._start_track()

    def _start_track(self) -> None:
        """Forget the track (not the learnt q): the next measurements start a new one."""
        self.steps_: deque[WindowStep] = deque(maxlen=self.window)
        self.pooled_: deque[np.ndarray] = deque(maxlen=self.window)
        self.mean_: np.ndarray | None = None  # (2 axes, 2) broadcast posterior at last_step_
        self.cov_: np.ndarray | None = None  # (2, 2, 2)
        self.last_step_ = 0
        self.expert_sensors_ = np.empty(0, dtype=np.int64)
        self.expert_means_ = np.empty((2, 0, 2))  # local posteriors of the last step with data
        self.expert_covs_ = np.empty((2, 0, 2, 2))
        self.data_mean_ = self.data_cov_ = None  # broadcast posterior after the last data step
        self.data_step_ = 0
        self.particles_ = None  # (states (N, 2, 2), weights (N,), modes (N,) or None) in a gap
        # with clutter at every sensor, log p(Z_t | Z_..t-1) of the gap's last step
        # (_scan_gap_step); None outside a gap
        self.gap_evidence_: float | None = None
        # the covariance of the broadcast posterior mean's error minus the posterior's
        # (2, 2, 2): None when not carried (_carries_error_excess) and at a track's start
        self.error_excess_: np.ndarray | None = None
        self.modes_ = None  # with turn modes: (means (K, 2, 2), covs (K, 2, 2, 2), probs (K,))
        self.mixed_ = None  # (modes_, their IMM mixing: means, covs, predicted probabilities)
        self.turn_predictions_ = None  # (mixed_, dt, each turn mode's prediction from it)

    def diagnostics(self) -> dict[str, float]:
        """``share_at_bound``: the share of this episode's learning steps that left q on a
        bound on either axis (as :meth:`agents.dgpt.DGPT.diagnostics`)."""
        if not self.fits_:
            return {"share_at_bound": float("nan")}
        share = self.fits_at_bound_ / self.fits_
        return {"share_at_bound": share, "share_at_bound_process_noise": share}

    # -- one step -------------------------------------------------------------------------

    def update(self, obs: dict) -> Estimate:
        return self.update_batch([self], [obs])[0]

    @classmethod
    def update_batch(
        cls, trackers: Sequence[StateSpaceDGPT], observations: Sequence[dict]
    ) -> list[Estimate]:
        """One step of many episodes in lockstep: each tracker's steps 1-4 alone, then the
        learning of every tracker that learns at this step, their windows filtered together
        (:func:`_learn_pooled`); the numbers equal the one-by-one ones, since :meth:`update`
        is this with one tracker."""
        pending = [tracker._observe(obs) for tracker, obs in zip(trackers, observations)]
        learners = [tracker for tracker, step in zip(trackers, pending) if step is not None]
        learners = [
            tracker
            for tracker in learners
            if tracker.learn_process_noise
            and tracker.learning == "window"
            and tracker._ready_to_learn()
        ]
        groups: dict[Manoeuvre | None, list[StateSpaceDGPT]] = {}
        for tracker in learners:
            groups.setdefault(tracker.manoeuvre, []).append(tracker)
        for group in groups.values():
            _learn_pooled(group)
        return [
            tracker._keep(*step) if step is not None else tracker.last_estimate_
            for tracker, step in zip(trackers, pending)
        ]

    def _observe(self, obs: dict):
        """Steps 1-4 of a step. Returns ``(step, mean, cov, ucb, modes, var)`` for
        :meth:`_keep` after the learning, or None when the step is finished (no data; its
        estimate is in ``last_estimate_``). ``var`` is the estimate's variance on a step with
        data: the variance of its error under the model, the mixture over the hypotheses of
        each aggregate's (:func:`agents.state_space.aggregate_error_cov`, which the UCB uses
        too) and its distance to the estimate. PoE, GPoE and RBCM have a posterior variance
        of their own that is not their error's (0.11.0 reported it: RBCM's median NEES was
        0.66-0.68 on S1 at sigma_z = 2 and 4); BCM's posterior variance is its error's, and
        BCM reports it (var is None). Their prior's error is not the broadcast prior's
        either: since 0.13.0 the tracker without turn modes carries the excess of the
        error's covariance over the broadcast posterior (``error_excess_``, the hypotheses'
        mixture of ``error_cov - cov``) through the NCV transition to the next step's prior
        (:meth:`_carries_error_excess`; not with turn modes, so not in the registered
        trackers). With targets drawn from the model the mean NEES is then 1.96-1.99 for
        every aggregation (tests/test_agents/test_state_space.py); taking the broadcast
        prior as exact (0.12.0) gave GPoE 2.6 and PoE 3.7, their own variances 2.9 and 8.5.
        After a coverage gap the excess restarts at 0: the gap's particles are drawn from
        the broadcast posterior."""
        if getattr(self, "spec_", None) is None:
            raise RuntimeError("call reset(spec) before update(obs)")
        spec = self.spec_
        step = int(obs["t"])
        self.prior_state_ = self.next_state_
        self.prior_modes_ = self.next_modes_
        self.step_predictions_ = None
        self.new_track_ = False
        mask = np.asarray(obs["mask"]).astype(bool)
        points = np.asarray(obs["measurements"], dtype=float)[mask]
        sensors = np.asarray(obs["sensor"])[mask]
        scan = None  # with clutter at every sensor: every report of the step
        if spec.clutter_sensors == "all" and spec.clutter_rate > 0:
            scan = (points, sensors)
            awake = obs.get("awake")
            awake = None if awake is None else np.array(awake, dtype=bool)
            self.previous_scan_, self.this_scan_ = self.this_scan_, (points, sensors, awake, step)
            keep, started = self.screen_.screen(
                points, sensors, self.prior_next_, np.full(2, self.noise_var_), awake
            )
            if self.search_ is not None and self.mean_ is None:
                keep, started = self._search(step, points, sensors, awake, keep, started)
            points, sensors = points[keep], sensors[keep]
            if started:
                self._start_track()
        if self.search_estimate_ is not None and not points.shape[0] and self.mean_ is None:
            self.last_estimate_ = self.search_estimate_
            return None
        if self.silence_particles and not points.shape[0]:
            if self.mean_ is not None:
                self.last_estimate_ = self._silent_step(step, obs.get("awake"), scan)
                return None
            if scan is not None:
                self.last_estimate_ = self._scan_estimate(*scan, obs.get("awake"))
                return None
        gap_predictions = gap_evidence = None
        if self.particles_ is not None and self.gap_end == "reports" and scan is None:
            gap_predictions = self._reporting_predictions(step, points, sensors, obs.get("awake"))
        self.particles_ = None  # a gap ends; its last step kept the particles' moments
        self.gap_evidence_ = None
        if self.mean_ is None:
            if not points.shape[0]:
                self.last_estimate_ = Estimate.uninformed(spec)
                return None
            self.new_track_ = True  # this step starts a track (the first, or after a restart)
            self.mean_ = np.column_stack([np.median(points, axis=0), np.zeros(2)])
            self.cov_ = np.zeros((2, 2, 2))
            self.cov_[:, 0, 0] = spec.sensing_range**2
            self.cov_[:, 1, 1] = INITIAL_SPEED_STD**2
            self.last_step_ = step
        if self.turn_rates and self.modes_ is None:  # a new track: every mode equally likely
            count = len(self.mode_transition)
            self.modes_ = (
                np.broadcast_to(self.mean_, (count,) + self.mean_.shape),
                np.broadcast_to(self.cov_, (count,) + self.cov_.shape),
                np.full(count, 1.0 / count),
            )
        dt = (step - self.last_step_) * spec.dt
        if gap_predictions is None:
            predictions, modes = self._predictions(dt, np.exp(self.log_q_), self.manoeuvre)
        else:
            predictions, modes, gap_evidence = gap_predictions
        self.step_predictions_ = (
            np.log(np.maximum([probability for _, probability in predictions], 1e-300)),
            np.stack([prediction[0] for prediction, _ in predictions]),
            np.stack([prediction[1] for prediction, _ in predictions]),
            modes,
        )
        log_priors, prior_means, prior_covs, _ = self.step_predictions_
        if not points.shape[0]:
            log_weights = log_priors
            means = np.swapaxes(prior_means, 0, 1)  # (axis, H, 2)
            covs = np.swapaxes(prior_covs, 0, 1)
            mean, cov = reduce_mixture(log_weights, means, covs)
            prior_var = covs[..., 0, 0]  # (axis, H)
            var = None
            if self.error_excess_ is not None:  # the error's excess over the prediction
                self.error_excess_ = _carry(self.error_excess_, dt)
                carried_var = prior_var + self.error_excess_[:, None, 0, 0]
                if np.all(carried_var > 0):
                    prior_var = carried_var
                    var = cov[:, 0, 0] + self.error_excess_[:, 0, 0]
                else:  # not a covariance with this prediction: drop the excess
                    self.error_excess_ = None
            ucb = agg.mixture_half_width(
                np.exp(log_weights),
                prior_means[..., 0] - mean[:, 0],
                np.sqrt(prior_var.T),
                self.delta,
            )
            self.last_estimate_ = self._keep(
                step, mean, cov, ucb, self._mode_posteriors(modes, log_weights, means, covs), var
            )
            return None
        hypotheses = self._hypotheses(
            points,
            sensors,
            prior_means,
            prior_covs,
            log_priors,
            self._error_prior_covs(prior_covs, dt),
        )
        if gap_evidence is not None:
            hypotheses["log_weight"] = log_priors + gap_evidence
        learns = self.learn_process_noise and self.learning == "recursive"
        # a gap end's predictions come from the gap's particles and the reporting region,
        # not from q, and a new track's step has no prediction
        if learns and gap_predictions is None and not self.new_track_:
            self._learn_recursive(hypotheses, log_priors, prior_means, prior_covs, modes, dt)
        log_weights = hypotheses["log_weight"]
        means = np.swapaxes(hypotheses["mean"], 0, 1)  # (axis, hypothesis, 2)
        covs = np.swapaxes(hypotheses["cov"], 0, 1)
        mean, cov = reduce_mixture(log_weights, means, covs)
        mode_posteriors = self._mode_posteriors(modes, log_weights, means, covs)
        best = int(np.argmax(log_weights))
        if self.data_mean_ is None:  # the first data step: its prior is the start state
            self.data_mean_, self.data_cov_, self.data_step_ = self.mean_, self.cov_, step
        window_step = WindowStep(
            (step - self.data_step_) * spec.dt,
            hypotheses["summaries"][best],
            hypotheses["summary_var"][best] - self.noise_var_,
            self.data_mean_,
            self.data_cov_,
        )
        self.steps_.append(window_step)
        summary_var = np.full(2, self.noise_var_)[:, None] + window_step.spread
        # as an array (field, axis): the learning stacks the window's
        self.pooled_.append(np.array(pool_summaries(window_step.summaries, summary_var)))
        self.expert_sensors_ = hypotheses["sensors"]
        self.expert_means_ = hypotheses["expert_means"][best]
        self.expert_covs_ = hypotheses["expert_covs"][best]
        weights = np.exp(log_weights - np.logaddexp.reduce(log_weights))
        offsets = hypotheses["mean"][..., 0] - mean[:, 0]  # (H, 2)
        ucb = agg.mixture_half_width(weights, offsets, hypotheses["error_std"], self.delta)
        error_var = None
        if self.aggregation != "bcm":  # BCM's posterior variance is its error variance
            error_var = weights @ (hypotheses["error_std"] ** 2 + offsets**2)
        if self._carries_error_excess():
            self.error_excess_ = np.einsum(
                "h,haij->aij", weights, hypotheses["error_cov"] - hypotheses["cov"]
            )
        self.data_mean_, self.data_cov_, self.data_step_ = mean, cov, step
        return step, mean, cov, ucb, mode_posteriors, error_var

    def _silent_step(self, step: int, awake, scan=None) -> Estimate:
        """A step on which no awake sensor reports (:mod:`agents.silence`): the gap's
        particles carried to this step under the two-component process noise, weighted by
        whether they lie where no awake sensor senses them, and resampled when their
        effective number falls below half. With clutter at every sensor, ``scan`` = (points,
        sensors) holds every report of a step on which the screen admitted no sensor, and
        the weights are the scans' likelihood ratio instead (:meth:`_scan_likelihood`),
        which is that indicator when nothing is reported; with ``gap_birth_probability``
        > 0, births from pairs of points join them (:meth:`_scan_gap_step`). The estimate is
        the moments of their kernel density: Gaussian kernels of covariance
        :func:`agents.particles.kernel_scale` times the predicted particles' covariance
        (Silverman's bandwidth; after births, the resampled particles'), so that a few
        surviving particles do not report a variance near zero. The resampled particles are not jittered with those kernels: on training
        seeds 1000-1011 that drifted tracks (RMSE on the reference paths 2.15 m above
        dgpt-bcm's, against 1.10 m below without the jitter). If every particle lies in a disc (the model cannot explain the
        silence), the weights are left as they were. With turn modes each particle also
        carries a mode: drawn with the modes' probabilities at the gap's first step (its state
        from that mode's posterior), moved along the modes' Markov chain at every step, and
        turning in a turn mode; the modes' posteriors and probabilities are the moments and
        weights of their particles (a mode without particles gets the overall moments).

        The UCB holds with probability 1 - delta under the kernel density, a Gaussian
        mixture with a component per particle (:func:`agents.aggregation.mixture_half_width`,
        as the data steps' UCB over their hypotheses). Lemma 1 on the density's standard
        deviation (up to 0.11.0) assumed it Gaussian: when a waypoint turn falls in a gap,
        the few particles that turned with it carry the truth. On the gap steps of S1's
        reference path at clutter 5 (training seeds 1000-1011; ``python
        scripts/model_study.py --ucb-by-step --first-seed 1000 --seeds 12 --scenarios S1
        --trajectories fixed --clutter-rates 5 --candidates ss-rbcm-silence-1000 ss-rbcm-4``)
        that bound covered 88.9 % of the axes' errors, this one covers 99.4 %, and the model
        without the silence 99.7 %."""
        spec = self.spec_
        states, weights, modes, kernel_cov = self._advance_particles(step)
        if scan is not None and self.gap_birth_probability > 0:
            states, weights, modes, kernel_cov = self._scan_gap_step(
                step, states, weights, modes, kernel_cov, scan, awake
            )
        else:
            if scan is None:
                sensor_positions = np.asarray(spec.sensor_positions)
                if awake is not None:
                    sensor_positions = sensor_positions[np.asarray(awake, dtype=bool)]
                likelihood = silent_region(
                    states[..., 0], sensor_positions, spec.sensing_range, spec.area
                )
            else:
                likelihood = self._scan_likelihood(states[..., 0], *scan, awake)
            if np.any((likelihood > 0) & (weights > 0)):
                weights = weights * likelihood
                weights = weights / weights.sum()
        if 1.0 / np.sum(weights**2) < weights.size / 2:
            chosen = resample_systematic(weights, self.rng_)
            states = states[chosen]
            modes = None if modes is None else modes[chosen]
            weights = np.full(weights.size, 1.0 / weights.size)
        self.particles_ = (states, weights, modes)
        mean, cov, mode_states = self._kernel_moments(states, weights, modes, kernel_cov)
        ucb = agg.mixture_half_width(
            weights,
            states[:, :, 0] - mean[:, 0],
            np.broadcast_to(np.sqrt(kernel_cov[:, 0, 0]), (weights.size, 2)),
            self.delta,
        )
        return self._keep(step, mean, cov, ucb, mode_states)

    def _scan_gap_step(self, step, states, weights, modes, kernel_cov, scan, awake):
        """The weights of a gap step's particles with clutter at every sensor and
        ``gap_birth_probability`` = beta > 0: the filter of :class:`agents.search.SearchFilter`
        started from the gap's particles instead of the uniform prior. With probability
        1 - beta per step the target is where the particles carry it, weighed by the step's
        scans (:func:`agents.screening.area_log_likelihood_ratios`); with beta it is somewhere
        new. Born at the last step, it is drawn from pairs of points of that step and this one
        (:func:`agents.search.weighed_births`, ``silence_particles`` / 2 births in the no-turn
        mode, which the pair's velocity stands for) and weighed by both steps' scans over the
        last step's evidence, so that a target that reappears away from the particles (a
        waypoint turn inside a coverage gap) is found where its points move as a target can,
        not only by a new track that a second sensor confirms. With births the particles are
        resampled to ``silence_particles`` and their kernels are those of the resampled
        particles. If the scans rule out every particle and birth the weights stay as they
        were (as in :meth:`_silent_step`).

        The step's log evidence ``gap_evidence_``, which the next step's births divide by,
        is that of the particles and births plus beta times that of a target new at this
        step, uniform over the area (:func:`agents.screening.scan_posterior`'s, from
        ``silence_particles`` / 2 draws): it stays finite when the scans rule out every
        particle (the search filter restarts there instead), so that the births of the next
        step can find the target; it is None only if the scans rule out the whole area.
        Births therefore start on a gap's second step. Returns ``(states, weights, modes,
        kernel_cov)``."""
        spec, beta = self.spec_, self.gap_birth_probability
        points, sensors = scan
        with np.errstate(divide="ignore"):
            log_weight = (
                np.log(weights)
                + np.log1p(-beta)
                + area_log_likelihood_ratios(
                    states[..., 0], points, sensors, spec, self.noise_var_, awake
                )
            )
        born = None
        if self.gap_evidence_ is not None and self.previous_scan_ is not None:
            *previous_scan, previous_step = self.previous_scan_
            born = weighed_births(
                previous_scan,
                (points, sensors, awake),
                spec,
                self.noise_var_,
                (step - previous_step) * spec.dt,
                INITIAL_SPEED_STD,
                self.silence_particles // 2,
                self.rng_,
                beta,
                self.gap_evidence_,
            )
        all_states, all_modes = states, modes
        if born is not None:
            born_states, log_born = born
            all_states = np.concatenate([states, born_states])
            log_weight = np.concatenate([log_weight, log_born])
            if modes is not None:
                all_modes = np.concatenate([modes, np.zeros(born_states.shape[0], dtype=int)])
        new_target = scan_posterior(
            points,
            sensors,
            spec,
            self.noise_var_,
            self.silence_particles // 2,
            self.rng_,
            awake,
            with_log_evidence=True,
        )
        log_new = -np.inf if new_target is None else np.log(beta) + new_target[2]
        top = np.max(log_weight)
        if not np.isfinite(top):
            self.gap_evidence_ = float(log_new) if np.isfinite(log_new) else None
            return states, weights, modes, kernel_cov
        new_weights = np.exp(log_weight - top)
        self.gap_evidence_ = float(np.logaddexp(top + np.log(new_weights.sum()), log_new))
        new_weights /= new_weights.sum()
        if born is None:
            return states, new_weights, modes, kernel_cov
        chosen = resample_systematic(new_weights, self.rng_, self.silence_particles)
        states = all_states[chosen]
        modes = None if all_modes is None else all_modes[chosen]
        weights = np.full(states.shape[0], 1.0 / states.shape[0])
        kernel_cov = kernel_scale(weights.size) * particle_moments(states, weights)[1]
        return states, weights, modes, kernel_cov

    def _reporting_predictions(self, step: int, points, sensors, awake):
        """The step's predictions at the end of a coverage gap (``gap_end="reports"``,
        :data:`GAP_ENDS`) and their modes, as :meth:`_predictions` returns them, and their
        log evidence under the step's scans (None with ``gap_end_evidence="summaries"``):
        ``(predictions, modes, log_evidence)``. The gap's particles
        are carried to ``step`` and weighed by whether they lie in the disc of every sensor
        of ``sensors`` (those reporting) and of no other awake sensor
        (:func:`agents.silence.reporting_region`): one prediction per mode, the moments of
        its particles' kernel density there, with the mode's probability times
        1 - ``gap_restart_probability``. A new track in that region has
        ``gap_restart_probability``: one prediction, the region's moments
        (:meth:`_region_prediction`), or with ``gap_region_cell`` > 0 the cells of
        :meth:`_region_cells` that :func:`kept_cells` keeps, each with that probability
        times its scaled share. When no particle lies there, the new track's predictions
        are in every mode, with equal probabilities."""
        spec = self.spec_
        states, weights, modes, kernel_cov = self._advance_particles(step)
        reporting, silent = reporting_and_silent(spec.sensor_positions, sensors, awake)
        weights = weights * reporting_region(
            states[..., 0], reporting, silent, spec.sensing_range, spec.area
        )
        explained = weights.sum() > 0
        predictions, prediction_modes = [], []
        restart_probability = self.gap_restart_probability if explained else 1.0
        if explained:
            mean, cov, mode_states = self._kernel_moments(
                states, weights / weights.sum(), modes, kernel_cov
            )
            keep = 1.0 - self.gap_restart_probability
            if mode_states is None:
                predictions.append(((mean, cov), keep))
            else:
                means, covs, probabilities = mode_states
                predictions += [
                    ((means[m], covs[m]), keep * probabilities[m]) for m in range(len(means))
                ]
                prediction_modes += list(range(len(means)))
        if self.gap_region_cell > 0:
            restarts = self._region_cells(reporting, silent)
        else:
            restarts = [(self._region_prediction(reporting, silent), 1.0)]
        evidence = None
        if self.gap_end_evidence == "scans":
            likelihood = PoissonLikelihood.from_spec(spec)
            every_evidence = self._scan_evidence(
                predictions + restarts, points, sensors, likelihood
            )
            evidence, restart_evidence = np.split(every_evidence, [len(predictions)])
            if len(restarts) > 1:  # the cells that carry the new track's posterior
                kept, log_scale = kept_cells(
                    np.log([share for _, share in restarts]) + restart_evidence,
                    GAP_REGION_COMPONENTS,
                )
                restarts = [(restarts[i][0], restarts[i][1] * np.exp(log_scale)) for i in kept]
                restart_evidence = restart_evidence[kept]
        restarts = [(state, restart_probability * share) for state, share in restarts]
        if modes is None:
            predictions += restarts
            if evidence is not None:
                evidence = np.r_[evidence, restart_evidence]
            return predictions, None, evidence
        if explained:  # the new track is in the NCV mode
            predictions += restarts
            prediction_modes += [0] * len(restarts)
            if evidence is not None:
                evidence = np.r_[evidence, restart_evidence]
        else:
            count = len(self.mode_transition)
            predictions = [
                (state, share / count) for _ in range(count) for state, share in restarts
            ]
            prediction_modes = np.repeat(np.arange(count), len(restarts))
            if evidence is not None:
                evidence = np.tile(restart_evidence, count)
        return predictions, np.asarray(prediction_modes, dtype=np.int64), evidence

    @staticmethod
    def _scan_evidence(predictions, points, sensors, likelihood) -> np.ndarray:
        """The log evidence of each prediction ``((mean, cov), probability)`` under the
        step's points: its position's Gaussian integrated against the environment's
        per-sensor likelihood (:func:`agents.poisson_update.gaussian_sums`)."""
        return gaussian_sums(
            np.stack([state[0][:, 0] for state, _ in predictions]),
            np.stack([state[1][:, 0, 0] for state, _ in predictions]),
            points,
            likelihood,
            sensors=sensors,
        ).log_evidence

    def _region_cells(self, reporting_positions, silent_positions):
        """A new track's states over the region where the target is when exactly these
        sensors report, as ``[((mean (2, 2), cov (2, 2, 2)), share), ...]``: one per cell of
        :func:`agents.silence.region_cells` (side ``gap_region_cell``), with the velocity
        prior of a new track; the region's moments (:meth:`_region_prediction`) when no
        lattice point falls in it."""
        spec = self.spec_
        shares, means, variances = region_cells(
            reporting_positions,
            silent_positions,
            spec.sensing_range,
            spec.area,
            self.gap_region_cell,
        )
        if not shares.shape[0]:
            return [(self._region_prediction(reporting_positions, silent_positions), 1.0)]
        cells = []
        for share, mean, variance in zip(shares, means, variances):
            state = np.zeros((2, 2))
            state[:, 0] = mean
            cov = np.zeros((2, 2, 2))
            cov[:, 0, 0] = variance
            cov[:, 1, 1] = INITIAL_SPEED_STD**2
            cells.append(((state, cov), float(share)))
        return cells

    def _region_prediction(self, reporting_positions, silent_positions):
        """A new track's state in the region where the target is when exactly these sensors
        report (:func:`agents.silence.reporting_region`): the moments of a uniform position
        there, from ``silence_particles`` draws in the box that bounds the reporting discs'
        intersection within the area (the box's draws stand for the region if none falls in
        it), with a position variance of at least sigma_n^2 per axis, and the velocity prior
        of a new track. The floor: two discs that barely meet leave a region a metre wide,
        whose few draws can give a variance of 0, and RBCM's and GPoE's expert weights
        (eq. (11)) are 0 on a prior of variance 0."""
        spec = self.spec_
        radius = spec.sensing_range
        reporting_positions = np.asarray(reporting_positions, dtype=float)
        low = np.maximum(np.max(reporting_positions, axis=0) - radius, 0.0)
        high = np.minimum(np.min(reporting_positions, axis=0) + radius, spec.area)
        positions = self.rng_.uniform(low, high, size=(self.silence_particles, 2))
        inside = reporting_region(
            positions, reporting_positions, silent_positions, radius, spec.area
        )
        if inside.any():
            positions = positions[inside]
        mean = np.zeros((2, 2))
        mean[:, 0] = positions.mean(axis=0)
        cov = np.zeros((2, 2, 2))
        cov[:, 0, 0] = np.maximum(positions.var(axis=0), self.noise_var_)
        cov[:, 1, 1] = INITIAL_SPEED_STD**2
        return mean, cov

    def _kernel_moments(self, states, weights, modes, kernel_cov):
        """The moments ``(mean (2, 2), cov (2, 2, 2))`` of the particles' kernel density
        (kernels of covariance ``kernel_cov``) and, with turn modes, each mode's (a mode
        without particles gets the overall moments) with the modes' probabilities, as
        :meth:`_keep` takes them (None without turn modes)."""
        mean, cov = particle_moments(states, weights)
        cov = cov + kernel_cov
        if modes is None:
            return mean, cov, None
        count = len(self.mode_transition)
        probabilities = np.bincount(modes, weights, minlength=count)
        mode_means = np.broadcast_to(mean, (count, 2, 2)).copy()
        mode_covs = np.broadcast_to(cov, (count, 2, 2, 2)).copy()
        for mode in np.flatnonzero(probabilities > 1e-12):
            own = modes == mode
            mode_means[mode], mode_cov = particle_moments(
                states[own], weights[own] / probabilities[mode]
            )
            mode_covs[mode] = mode_cov + kernel_cov
        probabilities = np.maximum(probabilities, 1e-300)
        return mean, cov, (mode_means, mode_covs, probabilities / probabilities.sum())

    def _advance_particles(self, step: int):
        """The gap's particles carried to ``step`` (drawn from the broadcast state, per mode
        with turn modes, at the gap's first step): each mode moved along the modes' Markov
        chain, each state under its mode's model (:func:`agents.silence.propagate_particles`).
        Returns ``(states, weights, modes, kernel_cov)``, the last the covariance (2, 2, 2)
        of the kernels of their density (:func:`agents.particles.kernel_scale` times the
        moved particles' covariance)."""
        spec = self.spec_
        dt = (step - self.last_step_) * spec.dt
        count, n = len(self.mode_transition), self.silence_particles
        if self.particles_ is None:
            self.error_excess_ = None  # the gap's moments stand for the error from here
            modes = None
            if self.turn_rates:
                modes = self.rng_.choice(count, size=n, p=self.modes_[2])
                states = np.empty((n, 2, 2))
                for mode in range(count):
                    own = modes == mode
                    states[own] = draw_particles(
                        self.modes_[0][mode], self.modes_[1][mode], int(own.sum()), self.rng_
                    )
            else:
                states = draw_particles(self.mean_, self.cov_, n, self.rng_)
            weights = np.full(n, 1.0 / n)
        else:
            states, weights, modes = self.particles_
        turn_rates = None
        if modes is not None:
            cumulative = np.cumsum(self.mode_transition[modes], axis=1)
            modes = np.minimum((self.rng_.random((n, 1)) > cumulative).sum(axis=1), count - 1)
            turn_rates = np.r_[0.0, self.turn_rates][modes]
        intensity, probability = (
            (self.manoeuvre.intensity, self.manoeuvre.probability) if self.manoeuvre else (0, 0)
        )
        states = propagate_particles(
            states,
            dt,
            np.exp(self.log_q_),
            intensity,
            probability,
            self.rng_,
            turn_rates,
            self.turn_process_noise,
        )
        kernel_cov = kernel_scale(weights.size) * particle_moments(states, weights)[1]
        return states, weights, modes, kernel_cov

    def _scan_likelihood(self, positions, points, sensors, awake) -> np.ndarray:
        """The likelihood ratio of a step's scans (every report, clutter at every sensor)
        at ``positions`` (N, 2), scaled to a largest value of 1, and 0 outside the area
        (:func:`agents.screening.area_log_likelihood_ratios`; all zero if the scans rule
        out every position)."""
        log_ratio = area_log_likelihood_ratios(
            positions, points, sensors, self.spec_, self.noise_var_, awake
        )
        if not np.any(np.isfinite(log_ratio)):
            return np.zeros(positions.shape[0])
        return np.exp(log_ratio - np.max(log_ratio))

    def _search(self, step, points, sensors, awake, keep, started):
        """Before the first track, with clutter at every sensor: the search filter
        (:class:`agents.search.SearchFilter`) takes the step's scans, and a track starts
        from the points within 3 sqrt(2) sigma of its mean once it has settled, unless the
        screen's own start came first. Keeps the filter's estimate in ``search_estimate_``
        (its moments, and the UCB under the kernel density of its particles as in
        :meth:`_silent_step`; None when the scans rule it out). Returns ``(keep,
        started)`` as :meth:`agents.screening.ClutterScreen.screen` does."""
        self.search_estimate_ = None
        if started:
            self.search_.reset()
            return keep, started
        searched = self.search_.step(step, points, sensors, awake)
        if searched is None:
            return keep, started
        mean, var, settled = searched
        positions = self.search_.states[:, :, 0]  # resampled: equal weights
        weights = np.full(positions.shape[0], 1.0 / positions.shape[0])
        self.search_estimate_ = self._kernel_estimate(
            mean, var, positions, weights, positions.shape[0]
        )
        if settled:
            near = np.sum((points - mean) ** 2, axis=1) <= 18.0 * self.spec_.model_noise_std**2
            if near.any():
                self.screen_.track_started()
                self.search_.reset()
                self.search_estimate_ = None
                return near, True
        return keep, started

    def _scan_estimate(self, points, sensors, awake) -> Estimate:
        """A step without a track, with clutter at every sensor, on which no track starts:
        the moments of the position's posterior given this step's scans and a prior
        uniform over the area (:func:`agents.screening.scan_posterior`, 2N weighted
        positions), with kernels of :func:`agents.particles.kernel_scale` (of their effective
        number) times its covariance as in :meth:`_silent_step`, and the UCB under that
        kernel density; the uninformed estimate if the scans rule out every drawn position.
        The area's centre (0.12.0) was the largest share of the squared error with clutter
        at every sensor."""
        posterior = scan_posterior(
            points,
            sensors,
            self.spec_,
            self.noise_var_,
            2 * self.silence_particles,
            self.rng_,
            awake,
        )
        if posterior is None:
            return Estimate.uninformed(self.spec_)
        positions, weights = posterior
        mean = weights @ positions
        var = weights @ (positions - mean) ** 2
        return self._kernel_estimate(mean, var, positions, weights, 1.0 / np.sum(weights**2))

    def _kernel_estimate(self, mean, var, positions, weights, effective_number) -> Estimate:
        """The estimate of a position's weighted sample ``positions`` (N, 2), ``weights``
        (N,), of moments ``mean`` and ``var`` (2,): the moments of its kernel density, with
        Gaussian kernels of :func:`agents.particles.kernel_scale` (Silverman's rule in 2-D
        on ``effective_number``) times ``var``, and the UCB under that density."""
        kernel_var = kernel_scale(effective_number, dimension=2) * var
        ucb = agg.mixture_half_width(
            weights,
            positions - mean,
            np.broadcast_to(np.sqrt(kernel_var), positions.shape),
            self.delta,
        )
        return Estimate(mean, var + kernel_var, ucb)

    def _carries_error_excess(self) -> bool:
        """Whether the tracker carries its error's excess over the broadcast posterior from
        step to step (``error_excess_``): RBCM, GPoE and PoE without turn modes. BCM's
        posterior is its error's. With turn modes one pooled excess added to every mode's
        mixed prior over-widens GPoE and PoE (targets drawn from the NCV model: mean NEES
        1.25 and 1.09 against 1.62 and 1.71 without it, nominal 2); a per-mode excess mixed
        by the IMM would be needed, so the registered trackers (which have turn modes) take
        the broadcast prior's covariance as their prior error's, as in 0.12.0."""
        return self.aggregation != "bcm" and not self.turn_rates

    def _error_prior_covs(self, prior_covs, dt):
        """The covariance of the step's prior errors (H, 2, 2, 2): each prediction's
        covariance plus the error's excess over the broadcast posterior (``error_excess_``)
        carried ``dt`` by the NCV transition (the process noise is in both and cancels), or
        None without an excess (BCM, turn modes, a new track, after a gap). A sum that is not
        positive definite (an excess left from another prior, e.g. after the hybrid set the
        estimate) falls back to the prediction's covariance."""
        if self.error_excess_ is None:
            return None
        summed = prior_covs + _carry(self.error_excess_, dt)
        a, b, d = summed[..., 0, 0], summed[..., 0, 1], summed[..., 1, 1]
        valid = (a > 0) & (a * d - b * b > 0)
        return np.where(valid[..., None, None], summed, prior_covs)

    def _ready_to_learn(self) -> bool:
        """Whether the window holds the three summaries a Newton step needs."""
        return sum(item.summaries.shape[1] for item in self.steps_) >= 3

    def _hypotheses(
        self, points, sensors, prior_means, prior_covs, log_priors, error_prior_covs=None
    ) -> dict:
        """The step's H predictions (``prior_means`` (H, 2, 2), ``prior_covs``
        (H, 2, 2, 2), log prior probabilities ``log_priors`` (H,)) as hypotheses, all at
        once: the association around each prediction (step 2 of the module docstring), the
        experts' local posteriors, their aggregate, the exact log likelihood of the
        summaries plus the log prior probability (both axes), and the standard deviation of
        the aggregate's error (the UCB's). Arrays are per hypothesis first, then axis:
        ``summaries``, ``summary_var`` and the summaries' ``spread`` (H, 2, M; summary_var
        is the summary's noise variance plus it), ``log_weight`` (H,), ``mean`` (H, 2, 2),
        ``cov`` (H, 2, 2, 2), ``expert_means`` (H, 2, M, 2), ``expert_covs``
        (H, 2, M, 2, 2), ``error_std`` (H, 2); ``sensors`` (M,) the experts. When the
        tracker carries its error's excess (:meth:`_carries_error_excess`), also
        ``error_cov`` (H, 2, 2, 2), the covariance of the aggregate's error when
        the prior's error has covariance ``error_prior_covs`` (H, 2, 2, 2; default the
        prior's; :func:`agents.state_space.aggregate_error_cov`), whose position entry is
        then ``error_std`` squared."""
        position_mean, position_var = prior_means[..., 0], prior_covs[..., 0, 0]  # (H, 2)
        shape = position_mean.shape[:1] + points.shape
        mean = np.broadcast_to(position_mean[:, None, :], shape)
        var = np.broadcast_to(position_var[:, None, :], shape)
        log_weights = None
        if not self.gating:
            mean, var = np.broadcast_to(points, shape), np.ones(shape)
        elif self.association == "joint":
            spec = self.spec_
            log_weights = np.log(
                target_probabilities(
                    points,
                    position_mean,
                    position_var,
                    self.noise_var_,
                    spec.detection_rate,
                    spec.clutter_density,
                )
                + _TINY_PROBABILITY
            )
        gated = gate_measurements(points, sensors, mean, var + self.noise_var_, log_weights)
        summaries = np.swapaxes(gated.summaries, -1, -2)
        noise_var = self.noise_var_
        if self.summary_variance == "mean":
            noise_var = noise_var * gated.weight_squares[..., None, :]
        spread = np.swapaxes(gated.spread, -1, -2)
        summary_var = noise_var + spread
        # what the experts update with: the summaries, or the pseudo-measurements of their
        # mixture posteriors; the likelihood weighs the summaries either way
        update_summaries, update_var = summaries, summary_var
        if self.expert_update == "mixture":
            update_summaries, update_var = mixture_summaries(
                position_mean, position_var, summaries, noise_var, spread
            )
        if self.aggregation in POOLED_METHODS:  # the sums serve the likelihood and the update
            pooled = pool_summaries(summaries, summary_var)
            log_likelihood = pooled_log_likelihood(position_mean, position_var, pooled)
            if update_summaries is not summaries:
                pooled = pool_summaries(update_summaries, update_var)
            posterior = pooled_update(self.aggregation, prior_means, prior_covs, pooled)
        else:
            log_likelihood = step_log_likelihood(
                position_mean, position_var, summaries, summary_var
            )
            posterior = fused_update(
                self.aggregation, prior_means, prior_covs, update_summaries, update_var
            )
        expert_means, expert_covs = expert_posteriors(
            prior_means, prior_covs, update_summaries, update_var
        )
        hypotheses = {
            "sensors": gated.sensors,
            "summaries": summaries,
            "summary_var": summary_var,
            "spread": spread,
            "log_weight": log_priors + log_likelihood.sum(axis=-1),
            "log_likelihood": log_likelihood,
            "mean": posterior[0],
            "cov": posterior[1],
            "expert_means": expert_means,
            "expert_covs": expert_covs,
        }
        if not self._carries_error_excess():
            hypotheses["error_std"] = np.sqrt(
                aggregate_error_var(self.aggregation, position_var, update_var)
            )
        else:
            error_prior_covs = prior_covs if error_prior_covs is None else error_prior_covs
            error_cov = aggregate_error_cov(
                self.aggregation, prior_covs, error_prior_covs, update_var
            )
            hypotheses["error_cov"] = error_cov
            hypotheses["error_std"] = np.sqrt(error_cov[..., 0, 0])
        return hypotheses

    def _climb(self, log_likelihood: np.ndarray) -> None:
        """Move log q by the Newton step of the window likelihoods (3, 2) at the trial
        points plus the prior's log penalty there (:data:`PROCESS_NOISE_PRIORS`), within
        :data:`PROCESS_NOISE_BOUNDS`, and count whether it ends on a bound."""
        lower, upper = _LOG_PROCESS_NOISE_BOUNDS
        objective = log_likelihood
        if self.process_noise_prior == "boundary-avoiding":
            objective = log_likelihood + 0.5 * (self.log_q_ + _TRIAL_OFFSETS[:, None])
        change = newton_step(objective, LOG_STEP, MAX_LOG_STEP)
        self.log_q_ = np.minimum(np.maximum(self.log_q_ + change, lower), upper)
        on_bound = (self.log_q_ - lower < _BOUND_TOLERANCE) | (
            upper - self.log_q_ < _BOUND_TOLERANCE
        )
        self.fits_ += 1
        self.fits_at_bound_ += int(on_bound.any())

    def _learn_recursive(self, hypotheses, log_priors, prior_means, prior_covs, modes, dt):
        """The recursive learning of q (:data:`LEARNINGS`): the step's log evidence,
        log sum_h e^(log_weight_h), at every q of :data:`LEARNING_GRID` on each axis (the
        NCV mode's hypotheses' position variance on that axis moves by (q' - q) dt^3 / 3,
        their summaries held), added to the forgotten sums of the past steps', and q their
        maximum (:func:`grid_maximum`)."""
        ncv = np.ones(len(log_priors), dtype=bool) if modes is None else modes == 0
        shifts = (LEARNING_GRID[:, None] - np.exp(self.log_q_)) * dt**3 / 3.0  # (K, axis)
        trial_var = prior_covs[ncv][None, :, :, 0, 0] + shifts[:, None, :]  # (K, H0, axis)
        pooled = pool_summaries(hypotheses["summaries"][ncv], hypotheses["summary_var"][ncv])
        trial = pooled_log_likelihood(prior_means[ncv][None, ..., 0], trial_var, pooled)
        log_likelihood = hypotheses["log_likelihood"]  # (H, axis)
        evidence = np.empty((len(LEARNING_GRID), 2))
        for axis in range(2):
            moved = np.repeat(log_likelihood[None], len(LEARNING_GRID), axis=0)
            moved[:, ncv, axis] = trial[..., axis]
            evidence[:, axis] = np.logaddexp.reduce(log_priors + moved.sum(axis=-1), axis=-1)
        if not np.all(np.isfinite(evidence)):  # q and the sums stay as they were
            return
        keep = 1.0 - 1.0 / self.learning_memory
        # less each step's largest value, which moves no maximum and keeps the sums small
        self.evidence_sums_ = keep * self.evidence_sums_ + (evidence - evidence.max(axis=0))
        self.log_q_, on_edge = grid_maximum(self.evidence_sums_, np.log(LEARNING_GRID))
        self.fits_ += 1
        self.fits_at_bound_ += int(on_edge.any())

    def _keep(self, step, mean, cov, ucb, modes, var=None) -> Estimate:
        """Broadcast the step's posterior and ``modes`` (with turn modes, the modes'
        posteriors and probabilities; else None) and return the estimate with the next-step
        prediction (the mixture's, which the hybrid filter takes as its prior). ``var``
        (2,): the estimate's variance when it is not the posterior's (see :meth:`_observe`)."""
        self.mean_, self.cov_, self.last_step_, self.modes_ = mean, cov, step, modes
        prior_next = self._predict_next(mean, cov)
        var = cov[:, 0, 0] if var is None else var
        return Estimate(mean[:, 0].copy(), var.copy(), ucb, prior_next)

    def _predictions(self, dt: float, q: np.ndarray, manoeuvre: Manoeuvre | None):
        """The step's predictions ``[((mean (2, 2), cov (2, 2, 2)), prior probability),
        ...]`` and the mode of each (an int array, or None without turn modes): the NCV
        mode's under each process-noise component, then each turn mode's; with turn modes
        from the IMM's mixed posteriors, weighted by the predicted mode probabilities."""
        if not self.turn_rates:
            return [
                (ncv_predict(self.mean_, self.cov_, dt, intensity), probability)
                for intensity, probability in process_noise_components(q, manoeuvre)
            ], None
        if self.mixed_ is None or self.mixed_[0] is not self.modes_:
            # the mixing depends on the modes alone: the next-step prediction and the next
            # step share it
            means, covs, probabilities = self.modes_
            mixed_means, mixed_covs, predicted = imm_mix(
                np.swapaxes(means, 0, 1),
                np.swapaxes(covs, 0, 1),
                probabilities,
                self.mode_transition,
            )
            self.mixed_ = (
                self.modes_,
                np.swapaxes(mixed_means, 0, 1),
                np.swapaxes(mixed_covs, 0, 1),
                predicted,
            )
        _, mixed_means, mixed_covs, predicted = self.mixed_
        predictions = [
            (ncv_predict(mixed_means[0], mixed_covs[0], dt, intensity), predicted[0] * probability)
            for intensity, probability in process_noise_components(q, manoeuvre)
        ]
        modes = [0] * len(predictions)
        # the turn modes' predictions do not depend on q: the next-step prediction and the
        # next step share them when that step follows at once
        cached = self.turn_predictions_
        if cached is None or cached[0] is not self.mixed_ or cached[1] != dt:
            turns = [
                turn_predict(
                    mixed_means[mode], mixed_covs[mode], dt, self.turn_process_noise, omega
                )
                for mode, omega in enumerate(self.turn_rates, start=1)
            ]
            self.turn_predictions_ = cached = (self.mixed_, dt, turns)
        for mode, prediction in enumerate(cached[2], start=1):
            predictions.append((prediction, predicted[mode]))
            modes.append(mode)
        return predictions, np.array(modes)

    def _mode_posteriors(self, modes, log_weights, means, covs):
        """Each mode's posterior, the mixture of its hypotheses (``log_weights`` (H,),
        ``means`` (2, H, 2), ``covs`` (2, H, 2, 2)), and its probability; None without turn
        modes."""
        if modes is None:
            return None
        log_weights = np.maximum(log_weights - np.logaddexp.reduce(log_weights), -700.0)
        count = len(self.mode_transition)
        mode_means, mode_covs = np.empty((count, 2, 2)), np.empty((count, 2, 2, 2))
        probabilities = np.empty(count)
        for mode in range(count):
            own = np.flatnonzero(modes == mode)
            if own.size == 1:  # reduce_mixture of one component, without its cost
                (only,) = own
                mode_means[mode] = means[:, only]
                mode_covs[mode] = 0.5 * (covs[:, only] + np.swapaxes(covs[:, only], -1, -2))
                probabilities[mode] = np.exp(log_weights[only])
                continue
            mode_means[mode], mode_covs[mode] = reduce_mixture(
                log_weights[own], means[:, own], covs[:, own]
            )
            probabilities[mode] = np.exp(log_weights[own]).sum()
        probabilities = np.maximum(probabilities, 1e-300)
        return mode_means, mode_covs, probabilities / probabilities.sum()

    def _predict_next(self, mean, cov) -> tuple[np.ndarray, np.ndarray]:
        """The state's prediction one step ahead under the mixture's moments (q + p q_m; with
        turn modes, the moments of the IMM's predictions); kept in ``next_state_`` and, for
        the position, ``prior_next_``, which it returns."""
        q = np.exp(self.log_q_)
        if self.manoeuvre is not None:  # the moments of the two components' predictions
            q = q + self.manoeuvre.probability * self.manoeuvre.intensity
        if self.turn_rates:
            predictions, _ = self._predictions(self.spec_.dt, q, None)
            means = np.stack([prediction[0] for prediction, _ in predictions])
            covs = np.stack([prediction[1] for prediction, _ in predictions])
            next_mean, next_cov = reduce_mixture(
                np.log(np.maximum([probability for _, probability in predictions], 1e-300)),
                np.swapaxes(means, 0, 1),
                np.swapaxes(covs, 0, 1),
            )
            self.next_modes_ = (means, covs)
        else:
            next_mean, next_cov = ncv_predict(mean, cov, self.spec_.dt, q)
        self.next_state_ = (next_mean, next_cov)
        self.prior_next_ = (next_mean[:, 0], next_cov[:, 0, 0])
        return self.prior_next_

    def set_estimate(self, estimate, var) -> tuple[np.ndarray, np.ndarray]:
        """Take the hybrid filter's posterior of this step's position, N(``estimate``,
        ``var``) (2,) each, in place of the tracker's own: the broadcast state becomes this
        step's prior conditioned on it (:func:`agents.state_space.condition_on_position`),
        and so does the learning window's prior for the next step with data; with turn
        modes, each mode's posterior becomes that mode's prior for the step conditioned on
        it (its velocity stays the mode's), with the probabilities of the tracker's own
        update. Returns the next-step prediction (mean, var) of the position."""
        if self.prior_state_ is None:
            raise RuntimeError("set_estimate needs a prior: call it after an update that had one")
        mean, cov = condition_on_position(*self.prior_state_, estimate, var)
        if self.turn_rates:
            shape = self.prior_modes_[0].shape[:-1]  # (modes, axes)
            mode_means, mode_covs = condition_on_position(
                *self.prior_modes_, np.broadcast_to(estimate, shape), np.broadcast_to(var, shape)
            )
            self.modes_ = (mode_means, mode_covs, self.modes_[2])
        return self._take_posterior(mean, cov)

    def set_posterior(self, log_weights, position_means, position_vars):
        """Take the hybrid filter's posterior over this step's predictions
        (``step_predictions_``, one per hypothesis h) in place of the tracker's own: each
        prediction's state conditioned on its posterior position N(``position_means[h]``,
        ``position_vars[h]``) ((H, 2) each; :func:`agents.state_space.condition_on_position`),
        weighted by the posterior log probabilities ``log_weights`` (H,). The broadcast state
        is their mixture's moments and, with turn modes, each mode's posterior is the mixture
        of its own hypotheses, as in the tracker's own step; the learning window's prior for
        the next step with data is the broadcast state. Returns the next-step prediction
        (mean, var) of the position."""
        if self.step_predictions_ is None:
            raise RuntimeError("set_posterior needs this step's predictions: call it after update")
        _, prior_means, prior_covs, modes = self.step_predictions_
        means, covs = condition_on_position(prior_means, prior_covs, position_means, position_vars)
        means, covs = np.swapaxes(means, 0, 1), np.swapaxes(covs, 0, 1)  # (axis, H, ...)
        self.modes_ = self._mode_posteriors(modes, log_weights, means, covs)
        return self._take_posterior(*reduce_mixture(log_weights, means, covs))

    def _take_posterior(self, mean, cov) -> tuple[np.ndarray, np.ndarray]:
        """Broadcast the hybrid's posterior state ``mean`` (2, 2), ``cov`` (2, 2, 2), taken as
        exact (no error excess), also as the learning window's prior for the next step with
        data when this step had data; returns the next-step prediction."""
        self.mean_, self.cov_ = mean, cov
        self.error_excess_ = None
        if self.data_mean_ is not None and self.data_step_ == self.last_step_:
            self.data_mean_, self.data_cov_ = mean, cov
        return self._predict_next(mean, cov)


def _carry(excess: np.ndarray, dt: float) -> np.ndarray:
    """F E F^T for the NCV transition F = [[1, dt], [0, 1]] of each axis's (2, 2) E."""
    return ncv_predict(np.zeros(excess.shape[:-1]), excess, dt, np.zeros(excess.shape[:-2]))[1]


def _learn_pooled(trackers: Sequence[StateSpaceDGPT]) -> None:
    """Step 5 of trackers that share the manoeuvre component: one Newton step of log q per
    axis on each window's exact log likelihood at log q, log q + h and log q - h, the
    windows padded at the front to the longest and filtered together from their pooled sums
    at (episode, trial point, axis) with :data:`LEARNING_FILTER`, BCM, by
    :func:`agents.state_space.bcm_window_log_likelihood` (:func:`filter_steps`'s numbers)."""
    length = max(len(tracker.steps_) for tracker in trackers)
    # (field, step, tracker, axis), padded at the front with zero sums that are skipped
    sums = np.zeros((len(PooledSummaries._fields), length, len(trackers), 2))
    dt = np.zeros((length, len(trackers), 1, 1))
    valid = np.zeros((length, len(trackers), 1, 1), dtype=bool)
    for column, tracker in enumerate(trackers):
        start = length - len(tracker.steps_)
        # one copy per tracker (the window's (step, field, axis) sums), not one per step
        sums[:, start:, column] = np.swapaxes(np.array(tracker.pooled_), 0, 1)
        dt[start:, column, 0, 0] = [step.dt for step in tracker.steps_]
        valid[start:, column] = True
    log_q = np.stack([tracker.log_q_ for tracker in trackers])
    log_likelihood = bcm_window_log_likelihood(
        dt,
        valid,
        PooledSummaries(*sums[:, :, :, None]),
        np.stack([tracker.steps_[0].mean for tracker in trackers])[:, None],
        np.stack([tracker.steps_[0].cov for tracker in trackers])[:, None],
        np.exp(log_q[:, None, :] + _TRIAL_OFFSETS[None, :, None]),
        trackers[0].manoeuvre,
    )
    for tracker, values in zip(trackers, log_likelihood):
        tracker._climb(values)
