"""DGPT with the nearly-constant-velocity GP in state-space form: experts that share only the
broadcast estimate, and a hyperparameter the window identifies.

Each step t:

1. **Prediction**: the network's broadcast posterior of each axis's state
   [position, velocity] at the last step, carried to t under the NCV model with intensity q
   (:func:`agents.state_space.ncv_predict`): the GP prior of s_t given the past.
2. **Gating**, eqs. (27)-(28): every reporting sensor weighs its measurements by their
   predictive likelihood under its own local posterior of its last step carried to t if it
   has been an expert, under the broadcast prediction otherwise (:mod:`agents.gating`). A
   summary's variance is sigma_n^2 plus the weighted spread of the sensor's measurements
   about it: a summary whose weights cannot tell the target from clutter counts for less.
3. **Experts and aggregation**: each sensor with a summary at t updates the prediction with
   its own summary alone; the local posteriors are aggregated (PoE / GPoE / BCM / RBCM,
   eqs. (8)-(20), on the state; :func:`agents.state_space.fused_update`). The UCB
   half-width is Theorem 1 or 2 on the experts' position variances, as in
   :class:`agents.dgpt.DGPT`.
4. **Learning**: q of each axis climbs the log marginal likelihood of the last C steps with
   data, re-filtered from the broadcast posterior before the oldest of them
   (:func:`agents.state_space.filter_window`): one Newton step in log q per step, from the
   likelihood at q e^(-h), q, q e^h, warm-started from the last step's q (Sec. IV-D: few
   iterations, warm-started). Step 3 uses q before this step's update.

An expert's local posterior depends on its own summary and the broadcast prior only, and
the prior carries the earlier steps exactly because the NCV GP is Markov in its state; with
BCM the aggregate is the exact GP posterior given every summary (the information filter),
so the predictive variance is the model's, with nothing added on. The likelihood is the
exact one of all experts' summaries (:func:`agents.state_space.step_log_likelihood`), not
eq. (22)'s product of local likelihoods: with a shared prior that product counts the
prior's uncertainty once per expert and cannot tell it from the summaries' noise.

sigma_n^2 is the sensors' noise variance, ``spec.model_noise_std ** 2`` (the hybrid filter
and the Kalman trackers use it too); only q is learnt. Steps without measurements only
predict, and the variance grows as the model says. The first measurements start the state
at their coordinate-wise median with a standard deviation of the sensing range (a
detecting sensor's target is within it) and :data:`INITIAL_SPEED_STD` for the velocity.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from agents import aggregation as agg
from agents.gating import GatedSummaries, gate_measurements
from agents.state_space import WindowStep, expert_posteriors, filter_window, ncv_predict
from dgpt_gym.problem import ProblemSpec
from dgpt_gym.tracker import Estimate, TrackerBase
from dgpt_gym.validation import check_bool, check_choice, check_integer, check_real

__all__ = [
    "StateSpaceDGPT",
    "INITIAL_SPEED_STD",
    "PROCESS_NOISE_START",
    "PROCESS_NOISE_BOUNDS",
    "newton_step",
]

INITIAL_SPEED_STD = 25.0
"""m/s per axis: the velocity prior of a new track, the scenarios' top speed."""

PROCESS_NOISE_START = 1.0
"""q (m^2/s^3) at the first step of an episode, per axis."""

PROCESS_NOISE_BOUNDS = (1e-4, 1e6)
"""Bounds of q (m^2/s^3): only what keeps the numerics finite (an acceleration standard
deviation of 0.01 to 1000 m/s^2 over a second); a fit on them is unidentified."""

LOG_STEP = 0.05
"""h: the log-space step of the finite differences of the Newton step."""

MAX_LOG_STEP = 1.0
"""The largest change of log q in one step."""

_BOUND_TOLERANCE = 1e-6


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
    return np.clip(step, -max_step, max_step)


class StateSpaceDGPT(TrackerBase):
    """Distributed GP tracker with the NCV kernel in state-space form (module docstring).

    Args:
        aggregation: ``"poe"``, ``"gpoe"``, ``"bcm"`` or ``"rbcm"``; BCM is the exact
            posterior here.
        window: C, the steps with data whose likelihood learns q.
        delta: total failure probability of the UCB, in (0, 1).
        gating: weigh each sensor's measurements by eqs. (27)-(28); False takes their
            unweighted mean.
    """

    name = "dgpt-ss"

    def __init__(
        self,
        aggregation: str = "bcm",
        window: int = 50,
        delta: float = 0.003,
        gating: bool = True,
    ) -> None:

        self.aggregation = check_choice("aggregation", aggregation, agg.AGGREGATIONS)
        self.window = check_integer("window", window, low=1)
        self.delta = check_real(
            "delta", delta, low=0.0, high=1.0, low_inclusive=False, high_inclusive=False
        )
        self.gating = check_bool("gating", gating)
        self.name = f"dgpt-{self.aggregation}-ss"

    def reset(self, spec: ProblemSpec, seed: int | None = None) -> None:
        self.spec_ = spec
        self.noise_var_ = spec.model_noise_std**2
        self.steps_: deque[WindowStep] = deque(maxlen=self.window)
        self.mean_: np.ndarray | None = None  # (2 axes, 2) broadcast posterior at last_step_
        self.cov_: np.ndarray | None = None  # (2, 2, 2)
        self.last_step_ = 0
        self.log_q_ = np.full(2, np.log(PROCESS_NOISE_START))
        self.expert_sensors_ = np.empty(0, dtype=np.int64)
        self.expert_means_ = np.empty((2, 0, 2))  # local posteriors at expert_step_
        self.expert_covs_ = np.empty((2, 0, 2, 2))
        self.expert_step_ = 0
        self.fits_ = 0
        self.fits_at_bound_ = 0

    def diagnostics(self) -> dict[str, float]:
        """``share_at_bound``: the share of this episode's learning steps that left q on a
        bound on either axis (as :meth:`agents.dgpt.DGPT.diagnostics`)."""
        if not self.fits_:
            return {"share_at_bound": float("nan")}
        share = self.fits_at_bound_ / self.fits_
        return {"share_at_bound": share, "share_at_bound_process_noise": share}

    # -- one step -------------------------------------------------------------------------

    def update(self, obs: dict) -> Estimate:
        if getattr(self, "spec_", None) is None:
            raise RuntimeError("call reset(spec) before update(obs)")
        spec = self.spec_
        step = int(obs["t"])
        mask = np.asarray(obs["mask"]).astype(bool)
        points = np.asarray(obs["measurements"], dtype=float)[mask]
        sensors = np.asarray(obs["sensor"])[mask]
        if self.mean_ is None:
            if not points.shape[0]:
                return Estimate.uninformed(spec)
            self.mean_ = np.column_stack([np.median(points, axis=0), np.zeros(2)])
            self.cov_ = np.zeros((2, 2, 2))
            self.cov_[:, 0, 0] = spec.sensing_range**2
            self.cov_[:, 1, 1] = INITIAL_SPEED_STD**2
            self.last_step_ = step
        dt = (step - self.last_step_) * spec.dt
        q = np.exp(self.log_q_)
        if not points.shape[0]:
            mean, cov = ncv_predict(self.mean_, self.cov_, dt, q)
            self.mean_, self.cov_, self.last_step_ = mean, cov, step
            return self._estimate(mean, cov, cov, None)
        gated = self._gate(points, sensors, step, dt)
        self.steps_.append(WindowStep(dt, gated.summaries.T, gated.spread.T, self.mean_, self.cov_))
        learn = sum(item.summaries.shape[1] for item in self.steps_) >= 3
        trial = self.log_q_ + (np.array([0.0, LOG_STEP, -LOG_STEP])[:, None] if learn else 0.0)
        log_likelihood, mean, cov, prior = filter_window(
            self.aggregation, list(self.steps_), np.exp(trial), np.full(2, self.noise_var_)
        )
        if learn:
            mean, cov, prior = mean[0], cov[0], (prior[0][0], prior[1][0])
            self._learn(log_likelihood)
        self.mean_, self.cov_, self.last_step_ = mean, cov, step
        self.expert_sensors_ = gated.sensors
        self.expert_means_, self.expert_covs_ = expert_posteriors(
            prior[0], prior[1], gated.summaries.T, self.noise_var_ + gated.spread.T
        )
        self.expert_step_ = step
        return self._estimate(mean, cov, prior[1], self.expert_covs_)

    def _gate(self, points, sensors, step, dt) -> GatedSummaries:
        """Eqs. (27)-(28) around each sensor's own prediction (module docstring, step 2)."""
        q = np.exp(self.log_q_)
        fused_mean, fused_cov = ncv_predict(self.mean_, self.cov_, dt, q)
        mean = np.broadcast_to(fused_mean[:, 0], points.shape).copy()
        var = np.broadcast_to(fused_cov[:, 0, 0], points.shape).copy()
        if self.expert_sensors_.size:
            local_mean, local_cov = ncv_predict(
                self.expert_means_,
                self.expert_covs_,
                (step - self.expert_step_) * self.spec_.dt,
                q[:, None],
            )
            index = np.minimum(
                np.searchsorted(self.expert_sensors_, sensors), self.expert_sensors_.size - 1
            )
            known = self.expert_sensors_[index] == sensors
            mean[known] = local_mean[:, index[known], 0].T
            var[known] = local_cov[:, index[known], 0, 0].T
        if not self.gating:
            mean, var = points, np.ones_like(points)
        return gate_measurements(points, sensors, mean, var + self.noise_var_)

    def _learn(self, log_likelihood: np.ndarray) -> None:
        """Step 4: one Newton step of log q per axis from the window's log likelihood
        (3, 2) at log q, log q + h, log q - h."""
        lower, upper = np.log(PROCESS_NOISE_BOUNDS)
        change = newton_step(log_likelihood, LOG_STEP, MAX_LOG_STEP)
        self.log_q_ = np.clip(self.log_q_ + change, lower, upper)
        on_bound = (self.log_q_ - lower < _BOUND_TOLERANCE) | (
            upper - self.log_q_ < _BOUND_TOLERANCE
        )
        self.fits_ += 1
        self.fits_at_bound_ += int(on_bound.any())

    def _estimate(self, mean, cov, prior_cov, expert_covs) -> Estimate:
        """The position estimate, its variance, the UCB half-width and the next-step
        prediction (which the hybrid filter takes as its prior)."""
        if expert_covs is None:  # no expert: the bound is the prior's
            expert_var, valid = prior_cov[:, None, 0, 0], np.zeros((2, 1), dtype=bool)
        else:
            expert_var = expert_covs[..., 0, 0]
            valid = np.ones(expert_var.shape, dtype=bool)
        ucb = agg.ucb_half_width(
            self.aggregation, expert_var, prior_cov[:, 0, 0], self.delta, valid=valid
        )
        next_mean, next_cov = ncv_predict(mean, cov, self.spec_.dt, np.exp(self.log_q_))
        return Estimate(
            mean[:, 0].copy(), cov[:, 0, 0].copy(), ucb, (next_mean[:, 0], next_cov[:, 0, 0])
        )
