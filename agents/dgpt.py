"""Distributed-GP tracking, DGPT (paper Sec. IV), with the UCBs of Sec. V.

Each step t:

1. **Gating**, eqs. (27)-(28): every reporting sensor weighs its measurements by their joint
   x-y predictive likelihood under the previous step's model: its own local prediction of
   step t if it was an expert, the aggregated prediction otherwise; the weighted mean is its
   one training point of the step (:mod:`agents.gating`).
2. **Experts**: the sensors with at least one summary in the sliding window of the last C
   steps (:mod:`agents.window`); each is a local GP on its own summaries, per axis, on time
   (TGP) or on the previous estimate of the coordinate and time (STGP, eqs. (25)-(26)).
3. **Learning**: the hyperparameters, shared by all experts (one set per axis), maximise
   the factorized log marginal likelihood, eq. (22), by a few projected-BFGS iterations
   (:mod:`agents.optimize`) warm-started from the previous step's values and curvature
   (Sec. IV-D); each axis is its own problem, and all are solved in one batch.
4. **Prediction**: each expert predicts steps t and t + 1, eqs. (6)-(7); the predictions are
   aggregated by PoE / GPoE / BCM / RBCM (:mod:`agents.aggregation`); the UCB half-width
   comes from Theorem 1 or 2 with the failure probability ``delta`` split over the experts.

Many episodes can be stepped in lockstep (:func:`update_batch`, which ``update`` calls with
one): steps 1-2 run per episode, steps 3-4 once for all episodes whose expert arrays pad to
the same shape (:func:`agents.window.padded_size`), and every episode's numbers are bit for
bit those of the episode alone.

Start of an episode: before any model exists the gate is centred on the coordinate-wise
median of the step's measurements with a variance of the squared sensing range (a target
is within the sensing range of every sensor that detects it), and the GP starts from
documented hyperparameters (:data:`INITIAL_HYPERPARAMETERS`). Steps without measurements:
the tracker predicts from the most recent window that had data; its variance grows with
the distance in time. No NaN is ever returned.

Clutter at every sensor (``clutter_sensors="all"``, not the paper's setting): the paper's
gating would make every sensor that reports clutter an expert. Before step 1, the sensors
that do not sense the target are screened out and tracks are started and restarted from
measurements that the other sensors covering them confirm (:mod:`agents.screening`,
:meth:`DGPT._screen`); with clutter only at detecting sensors nothing changes.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from agents import aggregation as agg
from agents import gp
from agents.gating import gate_measurements
from agents.screening import MAX_TARGET_SPEED, ClutterScreen
from agents.window import PRIOR_MEANS, ExpertData, SlidingWindow, StepRecord, padded_size
from dgpt_gym.problem import ProblemSpec
from dgpt_gym.tracker import Estimate, TrackerBase
from dgpt_gym.validation import check_bool, check_choice, check_integer, check_real

__all__ = [
    "DGPT",
    "INITIAL_HYPERPARAMETERS",
    "HYPERPARAMETER_BOUNDS",
    "FIT_GRADIENT_TOLERANCE",
    "BOUND_TOLERANCE",
    "INPUTS",
    "KERNELS",
    "BOUNDS",
    "NCV_STATE_PRIOR_STD",
    "update_batch",
    "MAX_TARGET_SPEED",
]

INPUTS = ("tgp", "stgp")
KERNELS = ("se", "ncv")
BOUNDS = ("tracking", "loose")

BOUND_TOLERANCE = 1e-6
"""A fitted log hyperparameter this close to a bound counts as on it (the projected
optimiser puts a parameter exactly on the bound it hits)."""

FIT_GRADIENT_TOLERANCE = 1e-2
"""Projected-gradient tolerance of the online fit, in nats per unit log hyperparameter:
a step of 0.01 in log space then changes the likelihood by less than 1e-4 nats."""

INITIAL_HYPERPARAMETERS = {
    "signal_var": 400.0,  # m^2: deviations of ~20 m from the window's trend
    "time_lengthscale": 5.0,  # s
    "space_lengthscale": 200.0,  # m (STGP only)
    "noise_var": 1.0,  # m^2
    "process_noise": 1.0,  # m^2/s^3 (NCV kernel)
}
"""Start of the hyperparameter search at the first step of an episode (per axis)."""

HYPERPARAMETER_BOUNDS = {
    "signal_var": (100.0, 1e6),
    "time_lengthscale": (1.0, 30.0),
    "space_lengthscale": (1.0, 1e4),
    "noise_var": (0.1, 1e4),
    "process_noise": (1e-3, 1e5),
}
"""Bounds of the fit (m^2, s, m). They encode what the data of a short window cannot: a
length scale below the sampling period or far beyond the window is not identifiable, and
without a floor on the signal variance the likelihood of a straight stretch drives the
model to "trend plus white noise", whose over-confident predictions then make the gate lock
onto clutter at the next manoeuvre (measured: DGPT-RBCM mean NRMSE over S1-S4 x clutter
1, 5 fell from 4.1 % to 3.0 % with these bounds and window 5)."""


NCV_STATE_PRIOR_STD = {"position": 50.0, "velocity": 10.0}
"""Standard deviations (m, m/s) of the NCV kernel's state prior at the current step around
the broadcast prediction (:class:`agents.gp.NCVPrior`): a detecting sensor's target lies
within its sensing range (50 m in every scenario), and the velocity relative to the
predicted one changes by less than 10 m/s between steps at the scenarios' accelerations. Wide
enough that an expert with two or more points barely feels it."""


class DGPT(TrackerBase):
    """Distributed Gaussian-process tracker (DGPT): see the module docstring.

    Args:
        aggregation: ``"poe"``, ``"gpoe"``, ``"bcm"`` or ``"rbcm"`` (eqs. (8)-(20)).
        inputs: ``"tgp"`` (time) or ``"stgp"`` (previous estimate and time).
        kernel: ``"se"`` (squared exponential, eq. (5)) or ``"ncv"`` (the
            nearly-constant-velocity kernel, :class:`agents.gp.NCVPrior`, TGP only; with it
            every expert integrates out its own position and velocity and learns the
            process-noise intensity q through eq. (22)).
        hyperparameter_bounds: ``"tracking"`` (:data:`HYPERPARAMETER_BOUNDS`, the default)
            or ``"loose"`` (:func:`agents.gp.default_bounds`: only what keeps the numerics
            finite; the paper states no bounds).
        window: C, the sliding-window length in steps (>= 2).
        delta: total failure probability of the UCB, in (0, 1); 0.003 is the paper's 99.7 %.
        mean: the GP prior mean over the window (:func:`agents.window.window_prior_mean`):
            ``"linear"`` (least-squares constant-velocity trend, the default), ``"window"``
            (the window's mean) or ``"zero"`` (raw coordinates, as in the paper).
        max_iterations: quasi-Newton iterations per step and axis (warm-started, few are
            needed).
        anytime_ucb: use Lemma 2's gamma_t (a bound holding at every step at once, the
            terms of Theorem 3) instead of the one-step gamma of Theorems 1-2.
        gating: weigh each sensor's measurements by eqs. (27)-(28) (the default); False
            takes their unweighted mean (an ablation).
        gate_threshold: None (the paper: soft gating only) or a hard validation gate in
            front of eqs. (27)-(28): measurements whose Mahalanobis distance
            sqrt(sum_axes (z - mu_*)^2 / (sigma_*^2 + sigma_n^2)) from the aggregated
            prediction exceeds it are dropped before the weighted mean. The RL gating
            environment sets it step by step.
        admission_probability: with ``clutter_sensors="all"`` only: a reporting sensor's
            measurements are used when its posterior probability of sensing the predicted
            target is at least this (:func:`agents.screening.sensing_probability`; 1/2, the
            Bayes decision, was the best of 0.05, 0.15, 0.3, 0.5 on training seeds).
    """

    name = "dgpt"
    pooled = False  # one expert per sensor; the centralized GP pools them

    def __init__(
        self,
        aggregation: str = "rbcm",
        inputs: str = "tgp",
        window: int = 4,
        delta: float = 0.003,
        mean: str = "linear",
        max_iterations: int = 5,
        anytime_ucb: bool = False,
        gating: bool = True,
        gate_threshold: float | None = None,
        kernel: str = "se",
        hyperparameter_bounds: str = "tracking",
        admission_probability: float = 0.5,
    ) -> None:
        self.aggregation = check_choice("aggregation", aggregation, agg.AGGREGATIONS)
        self.inputs = check_choice("inputs", inputs, INPUTS)
        self.kernel = check_choice("kernel", kernel, KERNELS)
        self.hyperparameter_bounds = check_choice(
            "hyperparameter_bounds", hyperparameter_bounds, BOUNDS
        )
        if self.kernel == "ncv" and self.inputs != "tgp":
            raise ValueError(f"kernel='ncv' takes inputs='tgp'; got inputs={inputs!r}")
        self.window = check_integer("window", window, low=2)
        self.delta = check_real(
            "delta", delta, low=0.0, high=1.0, low_inclusive=False, high_inclusive=False
        )
        self.mean = check_choice("mean", mean, PRIOR_MEANS)
        self.max_iterations = check_integer("max_iterations", max_iterations, low=1)
        self.anytime_ucb = check_bool("anytime_ucb", anytime_ucb)
        self.gating = check_bool("gating", gating)
        self.gate_threshold = (
            None
            if gate_threshold is None
            else check_real("gate_threshold", gate_threshold, low=0.0, low_inclusive=False)
        )
        self.admission_probability = check_real(
            "admission_probability",
            admission_probability,
            low=0.0,
            high=1.0,
            low_inclusive=False,
        )
        self.name = f"{'gp' if self.pooled else 'dgpt-' + self.aggregation}-{self.inputs}"

    # -- hyperparameters ------------------------------------------------------------------

    @property
    def _spatial(self) -> bool:
        return self.inputs == "stgp"

    def _named_parameters(self) -> list[str]:
        if self.kernel == "ncv":
            return ["process_noise", "noise_var"]
        middle = (
            ["space_lengthscale", "time_lengthscale"] if self._spatial else ["time_lengthscale"]
        )
        return ["signal_var", *middle, "noise_var"]

    def initial_log_params(self) -> np.ndarray:
        """(2, p) log hyperparameters of both axes at the start of an episode."""
        row = np.log([INITIAL_HYPERPARAMETERS[name] for name in self._named_parameters()])
        return np.tile(row, (2, 1))

    def initial_curvature(self) -> np.ndarray:
        """(2, p, p) NaN: no BFGS curvature before the first fit of an episode."""
        p = len(self._named_parameters())
        return np.full((2, p, p), np.nan)

    def bounds(self) -> np.ndarray:
        """(p, 2) bounds of the log hyperparameters."""
        if self.hyperparameter_bounds == "loose":
            return gp.default_bounds(len(self._named_parameters()) - 2)
        return np.log([HYPERPARAMETER_BOUNDS[name] for name in self._named_parameters()])

    def ncv_prior(self) -> gp.NCVPrior | None:
        """The NCV kernel's state prior (None for the SE kernel)."""
        if self.kernel != "ncv":
            return None
        return gp.NCVPrior(
            NCV_STATE_PRIOR_STD["position"] ** 2, NCV_STATE_PRIOR_STD["velocity"] ** 2
        )

    def prior_var(self, log_params: np.ndarray, relative_time: float) -> np.ndarray:
        """(..., 2) prior variance k(x*, x*) of the GP at ``relative_time``."""
        ncv = self.ncv_prior()
        if ncv is None:
            return np.exp(np.asarray(log_params)[..., 0])
        return ncv.prior_var(log_params, relative_time)

    # -- Tracker API ----------------------------------------------------------------------

    def reset(self, spec: ProblemSpec, seed: int | None = None) -> None:
        self.spec_ = spec
        self.window_ = SlidingWindow(self.window)
        self.log_params_ = self.initial_log_params()
        self.curvature_ = self.initial_curvature()  # BFGS inverse Hessians of the last fit
        self.estimate_: np.ndarray | None = None
        self.prior_next_: tuple[np.ndarray, np.ndarray] | None = None
        self.expert_sensors_ = np.empty(0, dtype=np.int64)
        self.expert_next_mean_ = np.empty((0, 2))
        self.expert_next_var_ = np.empty((0, 2))
        self.n_experts_ = 0
        self.fit_failures_ = 0
        self.fits_ = 0  # steps whose hyperparameters were fitted
        self.fits_at_bound_ = np.zeros(len(self._named_parameters()), dtype=int)  # per name
        self.fits_any_bound_ = 0
        self.last_innovation_ = np.empty((0, 2))  # gated summaries - their predictions
        self.last_gated_out_ = 0  # measurements the hard gate dropped at the last step
        self._data: ExpertData | None = None  # the window's expert data of the last step
        self.step_ = -1
        self.screen_ = ClutterScreen(spec, self.admission_probability)

    def diagnostics(self) -> dict[str, float]:
        """``share_at_bound``: the share of this episode's fitted steps whose maximum-
        likelihood hyperparameters ended on a bound (within :data:`BOUND_TOLERANCE` in log
        space, on either axis): a fit the window's data cannot identify; then
        ``share_at_bound_<name>`` per hyperparameter."""
        if not self.fits_:
            return {"share_at_bound": float("nan")}
        shares = {
            f"share_at_bound_{name}": count / self.fits_
            for name, count in zip(self._named_parameters(), self.fits_at_bound_)
        }
        return {"share_at_bound": self.fits_any_bound_ / self.fits_, **shares}

    def set_window(self, window: int, keep: int | None = None) -> None:
        """Use the window length C = ``window`` from now on in this episode (the RL window
        environment does, step by step; ``reset`` returns to the constructor's ``window``).
        ``keep``: steps of history to retain so that C can grow again later."""
        window = check_integer("window", window, low=2)
        self.window_.length = window
        self.window_.capacity = max(window, keep or 0, self.window_.capacity)

    def update(self, obs: dict) -> Estimate:
        return update_batch([self], [obs])[0]

    @classmethod
    def update_batch(cls, trackers: Sequence[DGPT], observations: Sequence[dict]) -> list[Estimate]:
        """One step of many episodes in lockstep, batching learning and prediction
        (:func:`update_batch`)."""
        return update_batch(trackers, observations)

    def _numerics_key(self) -> tuple:
        """What the batched learning and prediction share within a group of trackers."""
        return (
            type(self),
            self.aggregation,
            self.inputs,
            self.kernel,
            self.hyperparameter_bounds,
            self.delta,
            self.anytime_ucb,
            self.max_iterations,
        )

    # -- steps of the algorithm -----------------------------------------------------------

    def _gate_prediction(self, points: np.ndarray, sensors: np.ndarray):
        """Per measurement: the predicted mean and variance of its sensor's model for this
        step (local if the sensor was an expert, aggregated otherwise), plus sigma_n^2."""
        if self.prior_next_ is None:
            centre = np.median(points, axis=0)
            var = np.full(2, self.spec_.sensing_range**2)
            return np.broadcast_to(centre, points.shape), np.broadcast_to(var, points.shape)
        mean = np.broadcast_to(self.prior_next_[0], points.shape).copy()
        var = np.broadcast_to(self.prior_next_[1], points.shape).copy()
        if self.expert_sensors_.size:
            index = np.searchsorted(self.expert_sensors_, sensors)
            index = np.minimum(index, self.expert_sensors_.size - 1)
            known = self.expert_sensors_[index] == sensors
            mean[known] = self.expert_next_mean_[index[known]]
            var[known] = self.expert_next_var_[index[known]]
        noise = np.exp(self.log_params_[:, -1])
        return mean, var + noise

    def _record(self, step: int, points: np.ndarray, sensors: np.ndarray) -> bool:
        """Gate the step's measurements into one summary per sensor and add them to the
        window; False if the hard gate dropped every measurement."""
        mean, var = self._gate_prediction(points, sensors)
        self.last_gated_out_ = 0
        if self.gate_threshold is not None and self.prior_next_ is not None:
            # a validation gate around the fused prediction: a sensor whose own model follows
            # clutter must not vouch for its clutter
            fused_var = self.prior_next_[1] + np.exp(self.log_params_[:, -1])
            distance2 = np.sum((points - self.prior_next_[0]) ** 2 / fused_var, axis=1)
            inside = distance2 <= self.gate_threshold**2
            self.last_gated_out_ = int(inside.size - inside.sum())
            points, sensors, mean, var = points[inside], sensors[inside], mean[inside], var[inside]
            if not points.shape[0]:
                self.last_innovation_ = np.empty((0, 2))
                return False
        if not self.gating:  # equal likelihoods: every measurement of a sensor gets the same weight
            mean, var = points, np.ones_like(points)
        gated = gate_measurements(points, sensors, mean, var)
        predicted = self._gate_prediction(gated.summaries, gated.sensors)[0]
        self.last_innovation_ = gated.summaries - predicted
        previous = self.estimate_ if self.estimate_ is not None else np.median(points, axis=0)
        self.window_.add(StepRecord(step, gated.sensors, gated.summaries, previous))
        return True

    def _window_data(self, obs: dict) -> Estimate | tuple[ExpertData, bool]:
        """Steps 1-2 of one episode: gate the step's measurements into the window and
        arrange it into expert arrays. Returns the estimate when there is no data yet, else
        the data and whether the hyperparameters are to be re-learnt (new summaries and at
        least three points)."""
        if self.spec_ is None:
            raise RuntimeError("call reset(spec) before update(obs)")
        step = int(obs["t"])
        mask = np.asarray(obs["mask"]).astype(bool)
        points = np.asarray(obs["measurements"], dtype=float)[mask]
        sensors = np.asarray(obs["sensor"])[mask]
        if self.spec_.clutter_sensors == "all" and self.spec_.clutter_rate > 0:
            points, sensors = self._screen(points, sensors, obs.get("awake"))
        origin = self._origin(points) if self.mean == "prediction" else None
        recorded = bool(points.shape[0]) and self._record(step, points, sensors)
        data = self.window_.expert_data(step, self._spatial, self.mean, self.pooled, origin)
        if data is None:  # nothing seen yet in this episode
            return Estimate.uninformed(self.spec_)
        self.step_ = step
        return data, recorded and data.n_points >= 3

    def _screen(self, points: np.ndarray, sensors: np.ndarray, awake: np.ndarray | None):
        """With clutter at every sensor: the measurements of the sensors that sense the
        target (:class:`agents.screening.ClutterScreen`, with the broadcast prediction and
        the learnt noise variance); a track that starts anew empties the window."""
        keep, started = self.screen_.screen(
            points, sensors, self.prior_next_, np.exp(self.log_params_[:, -1]), awake
        )
        if started:
            self.window_ = SlidingWindow(self.window_.length, self.window_.capacity)
            self.prior_next_ = None
            self.expert_sensors_ = np.empty(0, dtype=np.int64)
        return points[keep], sensors[keep]

    def _origin(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The line the experts model deviations from (``mean="prediction"``): the broadcast
        prediction for this step and the predicted displacement per step; before any
        prediction, the median of the step's measurements at rest."""
        if self.prior_next_ is not None and self.estimate_ is not None:
            position = np.asarray(self.prior_next_[0], dtype=float)
            return position, position - self.estimate_
        centre = np.median(points, axis=0) if points.shape[0] else np.zeros(2)
        return centre, np.zeros(2)

    def _test_inputs(self, data: ExpertData, relative_time: float, previous: np.ndarray):
        """(E, 2, M, 1, d) test inputs at ``relative_time`` with spatial inputs ``previous``
        (E, 2) for stacked ``data``."""
        time = np.full(data.X.shape[:-2] + (1, 1), relative_time)
        if not self._spatial:
            return time
        space = np.broadcast_to((previous - data.intercept)[:, :, None, None, None], time.shape)
        return np.concatenate([space, time], axis=-1)

    def _aggregate(self, mean, var, prior_var, data, relative_time, residual_var, valid):
        """Aggregate the experts' residual predictions (E, 2, M) and add back the prior
        mean; its estimation variance adds to the aggregate's
        (:meth:`ExpertData.prior_mean_variance`)."""
        combined = agg.aggregate(self.aggregation, mean, var, prior_var, valid)
        trend_var = data.prior_mean_variance(relative_time, residual_var)
        return combined.mean + data.prior_mean(relative_time), combined.var + trend_var

    def set_estimate(self, estimate: np.ndarray, var=None) -> tuple[np.ndarray, np.ndarray]:
        """Take ``estimate`` (2,) as this step's estimate (the hybrid filter feeds its
        posterior back here) and return the next-step prediction (mean, var). With STGP the
        estimate is the spatial input of that prediction, which is recomputed; with TGP it
        does not depend on the estimate. ``var`` (the posterior's variance) is not used:
        the GP predicts from its window, not from the estimate's uncertainty."""
        self.estimate_ = np.asarray(estimate, dtype=float).copy()
        if self._spatial:
            group = _Group([self], [self._data])
            group.predict_next(self.log_params_[None], group.factorize(self.log_params_[None]))
        return self.prior_next_


class _Group:
    """Episodes whose tracker numerics agree (:meth:`DGPT._numerics_key`) and whose expert
    arrays pad to the same shape (:func:`agents.window.padded_size`): their learning and
    prediction run as one batch, each episode exactly as it would alone."""

    def __init__(self, trackers: Sequence[DGPT], data: Sequence[ExpertData]) -> None:
        n_experts = padded_size(data[0].mask.shape[0])
        n_points = padded_size(data[0].mask.shape[1])
        self.trackers, self.own_data = list(trackers), list(data)
        self.first = self.trackers[0]
        self.data = ExpertData.stack([item.padded(n_experts, n_points) for item in data])
        self.valid = self.data.experts[:, None, :]  # (E, 1, M)
        self.training = gp.TrainingData.build(
            self.data.X, self.data.z, self.data.mask[..., None, :, :], ncv=self.first.ncv_prior()
        )

    def fit(self, log_params: np.ndarray) -> np.ndarray:
        """Step 3: the maximum-likelihood fit of every episode's (2, p), warm-started from
        the last step's hyperparameters and BFGS curvature."""
        result = gp.fit_hyperparameters(
            log_params,
            self.training,
            bounds=self.first.bounds(),
            max_iterations=self.first.max_iterations,
            gradient_tolerance=FIT_GRADIENT_TOLERANCE,
            inverse_hessian=np.stack([tracker.curvature_ for tracker in self.trackers]),
        )
        bounds = self.first.bounds()
        on_bound = np.any(  # (E, p): parameter on either bound on either axis
            (np.abs(result.log_params - bounds[:, 0]) < BOUND_TOLERANCE)
            | (np.abs(result.log_params - bounds[:, 1]) < BOUND_TOLERANCE),
            axis=-2,
        )
        for tracker, kept, curvature, at_bound in zip(
            self.trackers, result.kept_start, result.inverse_hessian, on_bound
        ):
            tracker.fit_failures_ += int(np.any(kept))
            tracker.curvature_ = curvature
            tracker.fits_ += 1
            tracker.fits_at_bound_ += at_bound.astype(int)
            tracker.fits_any_bound_ += int(at_bound.any())
        return result.log_params

    def factorize(self, log_params: np.ndarray) -> gp.Factorization:
        """Factorize every episode's covariances; an episode whose matrices stay indefinite
        even with jitter restarts from :data:`INITIAL_HYPERPARAMETERS` (``log_params`` is
        changed in place)."""
        fact = gp.factorize(log_params, self.training)
        broken = np.any(fact.failed, axis=-1)
        if np.any(broken):
            log_params[broken] = self.first.initial_log_params()
            for index in np.flatnonzero(broken):
                self.trackers[index].curvature_ = self.first.initial_curvature()
            fact = gp.factorize(log_params, self.training)
            fact.check()
        return fact

    def predict(self, steps: np.ndarray, log_params: np.ndarray) -> list[Estimate]:
        """Step 4 at the current step, then the next-step prediction that gates the next
        measurements."""
        first = self.first
        fact = self.factorize(log_params)
        prior_var = first.prior_var(log_params, 0.0)
        residual_var = prior_var + np.exp(log_params[..., -1])  # marginal variance of a summary
        previous = np.stack(
            [
                tracker.estimate_ if tracker.estimate_ is not None else item.prior_mean(-1.0)
                for tracker, item in zip(self.trackers, self.own_data)
            ]
        )
        x_now = first._test_inputs(self.data, 0.0, previous)
        mean_now, var_now = gp.predict(log_params, self.training, None, None, x_now, fact)
        estimate, estimate_var = first._aggregate(
            mean_now[..., 0], var_now[..., 0], prior_var, self.data, 0.0, residual_var, self.valid
        )
        # The estimate aggregates the residual GPs; each expert's and the prior's coordinate
        # also carries the trend's estimation variance.
        trend_var = self.data.prior_mean_variance(0.0, residual_var)
        ucb = agg.ucb_half_width(
            first.aggregation,
            var_now[..., 0],
            prior_var,
            first.delta,
            valid=self.valid,
            step=(steps + 1)[:, None] if first.anytime_ucb else None,
            extra_var=trend_var,
        )
        for index, (tracker, item) in enumerate(zip(self.trackers, self.own_data)):
            tracker.log_params_ = log_params[index].copy()
            tracker.n_experts_ = item.sensors.size
            tracker.estimate_ = estimate[index].copy()
            tracker._data = item
        self.predict_next(log_params, fact)
        return [
            Estimate(estimate[i].copy(), estimate_var[i], ucb[i], self.trackers[i].prior_next_)
            for i in range(len(self.trackers))
        ]

    def predict_next(self, log_params: np.ndarray, fact: gp.Factorization) -> None:
        """The aggregated next-step prediction from each tracker's ``estimate_`` (stored in
        ``prior_next_``) and each expert's, which gate the next step's measurements."""
        first = self.first
        prior_var = first.prior_var(log_params, 1.0)
        residual_var = prior_var + np.exp(log_params[..., -1])
        estimates = np.stack([tracker.estimate_ for tracker in self.trackers])
        x_next = first._test_inputs(self.data, 1.0, estimates)
        mean, var = gp.predict(log_params, self.training, None, None, x_next, fact)
        mean, var = mean[..., 0], var[..., 0]
        prior_next = first._aggregate(
            mean, var, prior_var, self.data, 1.0, residual_var, self.valid
        )
        trend_mean = self.data.prior_mean(1.0)
        trend_var = self.data.prior_mean_variance(1.0, residual_var)
        for index, (tracker, item) in enumerate(zip(self.trackers, self.own_data)):
            tracker.prior_next_ = (prior_next[0][index], prior_next[1][index])
            if first.pooled:
                tracker.expert_sensors_ = np.empty(0, dtype=np.int64)
                continue
            experts = item.sensors.size
            tracker.expert_sensors_ = item.sensors
            tracker.expert_next_mean_ = (mean[index, :, :experts] + trend_mean[index][:, None]).T
            tracker.expert_next_var_ = (var[index, :, :experts] + trend_var[index][:, None]).T


def update_batch(trackers: Sequence[DGPT], observations: Sequence[dict]) -> list[Estimate]:
    """One step of many DGPT episodes in lockstep: ``trackers[i]`` takes
    ``observations[i]``; returns their estimates, each identical to
    ``trackers[i].update(observations[i])`` (which is this with one episode).

    Gating and the window (steps 1-2) run per episode; learning and prediction (steps 3-4)
    run for each group of episodes with the same numerics and padded shape at once
    (:class:`_Group`), which is where a single episode spends most of its time on
    per-call overhead. The trackers may differ in every setting.
    """
    if len(trackers) != len(observations):
        raise ValueError(
            f"trackers and observations must have the same length; got {len(trackers)} "
            f"and {len(observations)}"
        )
    estimates: list[Estimate | None] = [None] * len(trackers)
    groups: dict[tuple, list[tuple[int, DGPT, ExpertData]]] = {}
    for index, (tracker, obs) in enumerate(zip(trackers, observations)):
        prepared = tracker._window_data(obs)
        if isinstance(prepared, Estimate):
            estimates[index] = prepared
            continue
        data, learn = prepared
        shape = tuple(padded_size(size) for size in data.mask.shape)
        groups.setdefault((tracker._numerics_key(), shape, learn), []).append(
            (index, tracker, data)
        )
    for (_, _, learn), members in groups.items():
        indices, members_trackers, members_data = zip(*members)
        group = _Group(members_trackers, members_data)
        log_params = np.stack([tracker.log_params_ for tracker in members_trackers])
        if learn:
            log_params = group.fit(log_params)
        steps = np.array([tracker.step_ for tracker in members_trackers])
        for index, estimate in zip(indices, group.predict(steps, log_params)):
            estimates[index] = estimate
    return estimates
