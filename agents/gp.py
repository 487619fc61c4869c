"""Gaussian-process core: squared-exponential kernel, log marginal likelihood with its
analytic gradient, posterior prediction and maximum-likelihood fitting (paper Sec. III).

Every function works on *batches of experts*. Shapes use ``B`` for a batch of independent
problems with their own hyperparameters (e.g. the x and y axes), ``M`` for the experts that
share them, ``n`` for training points (padded: experts hold different numbers of points) and
``d`` for input dimensions:

- ``log_params``: (*B, p) with p = d + 2, ordered ``[log sigma_f^2, log l_1 .. log l_d,
  log sigma_n^2]`` (output variance, length scales, noise variance; eq. (5), (21));
- ``X``: (*B, M, n, d) inputs; ``z``: (*B, M, n) outputs; ``mask``: (*B, M, n) or any shape
  that broadcasts to it, True for real points.

A padded point gets a unit diagonal and no covariance with anything, so it changes neither
the likelihood nor the predictions: no Python loop runs over experts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack

from agents import optimize

__all__ = [
    "NumericalError",
    "TrainingData",
    "Factorization",
    "unpack",
    "se_kernel",
    "NCVPrior",
    "factorize",
    "log_marginal_likelihood",
    "predict",
    "default_bounds",
    "FitResult",
    "fit_hyperparameters",
]

LOG_2PI = float(np.log(2.0 * np.pi))
_LAPACK_MIN_SIZE = 48
"""Matrices at least this large are factorized one by one with LAPACK potrf/potri."""


class NumericalError(ArithmeticError):
    """A covariance matrix stayed indefinite after the largest jitter."""


def unpack(log_params: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(signal variance (*B,), length scales (*B, d), noise variance (*B,)) from log parameters."""
    log_params = np.asarray(log_params, dtype=float)
    return np.exp(log_params[..., 0]), np.exp(log_params[..., 1:-1]), np.exp(log_params[..., -1])


def _scaled_squared_differences(
    x1: np.ndarray, x2: np.ndarray, lengthscales: np.ndarray
) -> np.ndarray:
    """((x1_a - x2_b) / l)^2 per input dimension: (..., n1, n2, d)."""
    diff = (x1[..., :, None, :] - x2[..., None, :, :]) / lengthscales[..., None, None, :]
    return diff * diff


def se_kernel(x1: np.ndarray, x2: np.ndarray, log_params: np.ndarray) -> np.ndarray:
    """Squared-exponential (ARD) covariance, eq. (5): sigma_f^2 exp(-1/2 sum_j (x_j - x'_j)^2 / l_j^2).

    ``x1`` (*B, M, n1, d), ``x2`` (*B, M, n2, d), ``log_params`` (*B, p); returns (*B, M, n1, n2).
    """
    signal, lengthscales, _ = unpack(np.asarray(log_params)[..., None, :])
    scaled = _scaled_squared_differences(x1, x2, lengthscales)
    return signal[..., None, None] * np.exp(-0.5 * scaled.sum(axis=-1))


@dataclass(frozen=True)
class NCVPrior:
    """The nearly-constant-velocity (NCV) Gaussian process on the relative time tau (the
    last input): the coordinate is ``x(tau) = x0 + v0 tau + w(tau)`` with the state at
    tau = 0 drawn from N(0, diag(``position_var``, ``velocity_var``)) and w the twice
    integrated white noise of intensity q on either side of 0 (independent sides),

        k(s, t) = position_var + velocity_var s t
                  + q [min(|s|, |t|)^3 / 3 + ||s| - |t|| min(|s|, |t|)^2 / 2]  (s t >= 0),

    and 0 for the last term where s t < 0 (Solin & Sarkka's integrated Wiener velocity
    kernel, the GP form of the NCV model; the first two terms are the explicit linear basis
    [1, tau] with a Gaussian prior on its coefficients integrated out, Rasmussen & Williams
    Sec. 2.7, eq. 2.39). q is the learnt hyperparameter (in the place of sigma_f^2); the
    state prior is fixed, so every expert integrates its own intercept and slope out.
    """

    position_var: float
    velocity_var: float

    def unit_kernel(self, t1: np.ndarray, t2: np.ndarray) -> np.ndarray:
        """The integrated-Wiener term with q = 1: (..., n1) x (..., n2) -> (..., n1, n2)."""
        s, t = t1[..., :, None], t2[..., None, :]
        shorter = np.minimum(np.abs(s), np.abs(t))
        value = shorter**3 / 3.0 + np.abs(np.abs(s) - np.abs(t)) * shorter**2 / 2.0
        return np.where(s * t >= 0, value, 0.0)

    def basis_kernel(self, t1: np.ndarray, t2: np.ndarray) -> np.ndarray:
        """The integrated-out state: position_var + velocity_var s t, (..., n1, n2)."""
        return self.position_var + self.velocity_var * t1[..., :, None] * t2[..., None, :]

    def prior_var(self, log_params: np.ndarray, tau: float) -> np.ndarray:
        """k(tau, tau) per problem of ``log_params`` (*B, 2)."""
        q = np.exp(np.asarray(log_params, dtype=float)[..., 0])
        return self.position_var + self.velocity_var * tau * tau + q * abs(tau) ** 3 / 3.0


@dataclass(frozen=True)
class TrainingData:
    """Training inputs and outputs with what does not depend on the hyperparameters
    precomputed: the per-dimension squared input differences and the mask weights.
    Build it once (:meth:`build`) and evaluate many hyperparameters on it.

    With ``ncv`` (an :class:`NCVPrior`) the covariance is the NCV kernel on the last input
    instead of the squared exponential: ``log_params`` is then ``[log q, log sigma_n^2]``
    and ``unit_kernel`` / ``basis_kernel`` hold its two parts (masked)."""

    X: np.ndarray
    z: np.ndarray
    weight: np.ndarray
    pair_weight: np.ndarray
    squared_differences: np.ndarray
    padding_diagonal: np.ndarray
    identity: np.ndarray
    ncv: NCVPrior | None = None
    unit_kernel: np.ndarray | None = None
    basis_kernel: np.ndarray | None = None

    @classmethod
    def build(
        cls,
        X: np.ndarray,
        z: np.ndarray,
        mask: np.ndarray | None = None,
        ncv: NCVPrior | None = None,
    ) -> TrainingData:
        # C order throughout: numpy's reductions and einsum pick their loops from the
        # operands' memory layout, which for stacked episodes depends on what they were
        # stacked with (np.stack keeps a layout its inputs share); C-ordered inputs keep
        # every intermediate C-ordered, so that a batch rounds as each problem alone
        X = np.ascontiguousarray(X, dtype=float)
        if mask is None:
            mask = np.ones(X.shape[:-1], dtype=bool)
        weight = np.ascontiguousarray(np.broadcast_to(np.asarray(mask, dtype=float), X.shape[:-1]))
        pair_weight = weight[..., :, None] * weight[..., None, :]
        identity = np.eye(X.shape[-2])
        unit = basis = None
        if ncv is None:
            diff = X[..., :, None, :] - X[..., None, :, :]
            squared_differences = diff * diff
        else:  # no length scales: an empty last axis keeps the gradient's shapes
            squared_differences = np.zeros(X.shape[:-1] + X.shape[-2:-1] + (0,))
            tau = X[..., -1]
            unit = ncv.unit_kernel(tau, tau) * pair_weight
            basis = ncv.basis_kernel(tau, tau) * pair_weight
        return cls(
            X=X,
            z=np.ascontiguousarray(z, dtype=float) * weight,
            weight=weight,
            pair_weight=pair_weight,
            squared_differences=squared_differences,
            padding_diagonal=(1.0 - weight)[..., None] * identity,
            identity=identity,
            ncv=ncv,
            unit_kernel=unit,
            basis_kernel=basis,
        )


@dataclass(frozen=True)
class Factorization:
    """What the likelihood, its gradient and predictions share for one set of hyperparameters.

    ``kernel`` is the masked noise-free covariance K, ``inverse`` the inverse of
    Sigma = K + sigma_n^2 I (unit diagonal on padding), ``log_det`` log|Sigma| per expert,
    ``scaled`` the per-dimension scaled squared differences, ``alpha`` = Sigma^-1 z,
    ``jitter`` (per problem) what was added to the diagonal to make Sigma positive definite
    (0 normally), ``failed`` (per problem) True where even the largest jitter did not (its
    inverse, log-determinant and alpha are NaN).
    """

    kernel: np.ndarray
    inverse: np.ndarray
    log_det: np.ndarray
    scaled: np.ndarray
    alpha: np.ndarray
    jitter: np.ndarray
    failed: np.ndarray

    def check(self) -> None:
        """Raise :class:`NumericalError` if any problem failed."""
        if np.any(self.failed):
            raise NumericalError("covariance matrix is not positive definite even with jitter")


def _cholesky_inverse(matrices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse and log-determinant of a stack of symmetric positive-definite matrices.

    Raises ``np.linalg.LinAlgError`` if one is not positive definite.
    """
    n = matrices.shape[-1]
    if n >= _LAPACK_MIN_SIZE:
        flat = matrices.reshape(-1, n, n)
        inverse = np.empty_like(flat)
        log_det = np.empty(flat.shape[0])
        for index, matrix in enumerate(flat):
            factor, info = lapack.dpotrf(matrix, lower=1, clean=1)
            if info != 0:
                raise np.linalg.LinAlgError("matrix is not positive definite")
            log_det[index] = 2.0 * np.log(np.diagonal(factor)).sum()
            lower_inverse, info = lapack.dpotri(factor, lower=1)
            if info != 0:
                raise np.linalg.LinAlgError("inversion failed")
            inverse[index] = np.tril(lower_inverse) + np.tril(lower_inverse, -1).T
        return inverse.reshape(matrices.shape), log_det.reshape(matrices.shape[:-2])
    # Small matrices: the Cholesky factor proves positive definiteness and gives the
    # log-determinant; numpy's stacked inverse is faster than two triangular solves here.
    factor = np.linalg.cholesky(matrices)
    log_det = 2.0 * np.log(np.diagonal(factor, axis1=-2, axis2=-1)).sum(axis=-1)
    return np.linalg.inv(matrices), log_det


def _as_data(X, z, mask) -> TrainingData:
    return X if isinstance(X, TrainingData) else TrainingData.build(X, z, mask)


def factorize(log_params: np.ndarray, data: TrainingData) -> Factorization:
    """Build K and invert Sigma = K + sigma_n^2 I for every expert, with escalating jitter.

    Each problem of the batch (leading shape of ``log_params`` without its last axis) is
    treated on its own: if one of its matrices is not numerically positive definite, jitter
    of 1e-10, 1e-8, ..., 1e-2 times the mean diagonal of that problem's matrices is added to
    all of them until they are. A problem that fails even so gets NaN in its inverse,
    log-determinant and ``alpha`` and is flagged in ``Factorization.failed``, as is one
    whose hyperparameters are not finite; the other problems are unaffected.
    """
    log_params = np.asarray(log_params, dtype=float)
    params = np.exp(log_params)[..., None, None, None, :]
    scaled = data.squared_differences / (params[..., 1:-1] * params[..., 1:-1])
    noise_diagonal = params[..., -1] * data.weight[..., None] * data.identity
    if data.ncv is None:
        kernel = params[..., 0] * data.pair_weight * np.exp(-0.5 * scaled.sum(axis=-1))
        sigma = kernel + noise_diagonal + data.padding_diagonal
    else:  # the learnt part (q times the unit kernel) is what the gradient differentiates
        kernel = params[..., 0] * data.unit_kernel
        sigma = kernel + data.basis_kernel + noise_diagonal + data.padding_diagonal
    problems = log_params.shape[:-1]
    try:
        inverse, log_det = _cholesky_inverse(sigma)
        jitter, failed = np.zeros(problems), np.zeros(problems, dtype=bool)
    except np.linalg.LinAlgError:
        inverse, log_det, jitter, failed = _jittered_inverse(sigma, data.weight, problems)
    # non-finite hyperparameters give NaN matrices, which the Cholesky does not reject
    failed = failed | ~np.isfinite(log_det.reshape(problems + (-1,))).all(axis=-1)
    alpha = (inverse * data.z[..., None, :]).sum(axis=-1)  # last-axis sums: see below
    return Factorization(kernel, inverse, log_det, scaled, alpha, jitter, failed)


def _jittered_inverse(sigma: np.ndarray, weight: np.ndarray, problems: tuple[int, ...]):
    """:func:`factorize`'s rescue, problem by problem (a rare path, so a Python loop)."""
    n = sigma.shape[-1]
    sigma = np.broadcast_to(sigma, problems + sigma.shape[len(problems) :])
    weight = np.broadcast_to(weight, sigma.shape[:-1])
    inverse, log_det = np.full(sigma.shape, np.nan), np.full(sigma.shape[:-2], np.nan)
    jitter, failed = np.zeros(problems), np.zeros(problems, dtype=bool)
    for index in np.ndindex(*problems):
        try:
            inverse[index], log_det[index] = _cholesky_inverse(sigma[index])
            continue
        except np.linalg.LinAlgError:
            pass
        scale = float(np.mean(np.diagonal(sigma[index], axis1=-2, axis2=-1)))
        for exponent in range(-10, 0, 2):
            jitter[index] = scale * 10.0**exponent
            try:
                inverse[index], log_det[index] = _cholesky_inverse(
                    sigma[index] + (jitter[index] * weight[index])[..., None] * np.eye(n)
                )
                break
            except np.linalg.LinAlgError:
                continue
        else:
            failed[index] = True
            jitter[index] = np.nan
    return inverse, log_det, jitter, failed


def log_marginal_likelihood(
    log_params: np.ndarray,
    X: np.ndarray | TrainingData,
    z: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    with_gradient: bool = True,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Factorized log marginal likelihood, eq. (22): the sum over experts of eq. (21),
    ``-1/2 z^T Sigma^-1 z - 1/2 log|Sigma| - n/2 log 2 pi``, and its gradient with respect to
    the log hyperparameters, ``1/2 tr((alpha alpha^T - Sigma^-1) dSigma/dtheta)``.

    ``X`` may be a prepared :class:`TrainingData` (then ``z`` and ``mask`` are ignored).
    Returns ``(value (*B,), gradient (*B, p) or None)``.
    """
    data = _as_data(X, z, mask)
    fact = factorize(log_params, data)
    alpha = fact.alpha
    per_expert = -0.5 * (data.z * alpha).sum(axis=-1) - 0.5 * fact.log_det
    value = per_expert.sum(axis=-1) - 0.5 * LOG_2PI * data.weight.sum(axis=(-1, -2))
    if not with_gradient:
        return value, None
    inner = alpha[..., :, None] * alpha[..., None, :] - fact.inverse
    # Sums over the experts' pairs as one flat, contiguous last axis: their rounding then
    # does not depend on how many problems are batched (numpy's multi-axis sums, einsum and
    # matmul change their loops with the batch shape), so a batch reproduces each problem
    # alone bit for bit.
    weighted = (inner * fact.kernel).reshape(*inner.shape[:-3], -1)
    grad_signal = 0.5 * weighted.sum(axis=-1)
    scaled = np.moveaxis(fact.scaled, -1, -4).reshape(*weighted.shape[:-1], -1, weighted.shape[-1])
    grad_lengthscales = 0.5 * (weighted[..., None, :] * scaled).sum(axis=-1)
    noise = np.exp(np.asarray(log_params, dtype=float)[..., -1])
    inner_diagonal = np.diagonal(inner, axis1=-2, axis2=-1)
    grad_noise = 0.5 * noise * (inner_diagonal * data.weight).sum(axis=(-1, -2))
    gradient = np.concatenate(
        [grad_signal[..., None], grad_lengthscales, grad_noise[..., None]], axis=-1
    )
    return value, gradient


_EXACT_PREDICTION_SIZE = 1 << 16
"""Largest tests x n x n of one problem whose predictive variance :func:`predict` sums
elementwise (bit-exact under batching); larger ones use matmul. The trackers' problems are
far smaller."""


def predict(
    log_params: np.ndarray,
    X: np.ndarray | TrainingData,
    z: np.ndarray | None,
    mask: np.ndarray | None,
    X_test: np.ndarray,
    factorization: Factorization | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Posterior predictive mean and latent variance of every expert, eqs. (6)-(7) with zero
    prior mean: ``mu = k*^T Sigma^-1 z``, ``sigma^2 = k** - k*^T Sigma^-1 k*``.

    ``X_test`` (*B, M, s, d); returns mean and variance (*B, M, s). The variance is clipped
    to ``[1e-12 k**, k**]`` against round-off.
    """
    data = _as_data(X, z, mask)
    fact = factorize(log_params, data) if factorization is None else factorization
    X_test = np.asarray(X_test, dtype=float)
    if data.ncv is None:
        cross = se_kernel(data.X, X_test, log_params)
        prior = np.exp(np.asarray(log_params, dtype=float)[..., 0])[..., None, None]
    else:
        q = np.exp(np.asarray(log_params, dtype=float)[..., 0])[..., None, None, None]
        tau, tau_test = data.X[..., -1], X_test[..., -1]
        cross = q * data.ncv.unit_kernel(tau, tau_test) + data.ncv.basis_kernel(tau, tau_test)
        prior = (
            q[..., 0] * np.abs(tau_test) ** 3 / 3.0
            + data.ncv.basis_kernel(tau_test[..., None], tau_test[..., None])[..., 0, 0]
        )
    # (..., s, n) in C order: every sum below runs over the contiguous last axis, whose
    # rounding depends neither on the batch shape nor on the layout (einsum's loops do),
    # so that an episode's prediction is the same alone and in a lockstep batch
    cross = np.ascontiguousarray(np.swapaxes(cross * data.weight[..., :, None], -1, -2))
    mean = (cross * fact.alpha[..., None, :]).sum(axis=-1)
    tests, n = cross.shape[-2:]
    if tests * n * n <= _EXACT_PREDICTION_SIZE:
        solved = (cross[..., :, None, :] * fact.inverse[..., None, :, :]).sum(axis=-1)
    else:  # a (tests, n, n) product per problem would not fit: BLAS, exact only alone
        solved = np.swapaxes(fact.inverse @ np.swapaxes(cross, -1, -2), -1, -2)
    reduction = (cross * solved).sum(axis=-1)
    variance = np.clip(prior - reduction, 1e-12 * prior, prior)
    return mean, variance


def default_bounds(d: int) -> np.ndarray:
    """Loose (p, 2) bounds on the log hyperparameters: sigma_f^2 in [1e-4, 1e8], length
    scales in [1e-2, 1e5], sigma_n^2 in [1e-6, 1e6] (in the data's units)."""
    rows = [(1e-4, 1e8)] + [(1e-2, 1e5)] * d + [(1e-6, 1e6)]
    return np.log(np.array(rows))


@dataclass(frozen=True)
class FitResult:
    """Outcome of :func:`fit_hyperparameters`, per problem (the leading shape ``S`` of the
    start): ``log_params`` (S, p) to use and ``log_likelihood`` (S,) there; ``converged``
    (S,) where the projected gradient met the tolerance (a step cut short by the iteration
    limit is used all the same), ``kept_start`` (S,) where the likelihood was not finite at
    the start, which is then returned; ``n_evaluations`` likelihood rounds; ``status`` (S,)
    the optimiser's codes (:data:`agents.optimize.STATUS_MESSAGES`), or ``error`` when the
    evaluation raised."""

    log_params: np.ndarray
    log_likelihood: np.ndarray
    converged: np.ndarray
    kept_start: np.ndarray
    n_evaluations: int
    inverse_hessian: np.ndarray | None = None
    status: np.ndarray | None = None
    error: str | None = None

    @property
    def message(self) -> str:
        """How the fit ended, in words (built on demand: the fit runs every tracker step)."""
        if self.error is not None:
            return self.error
        if self.n_evaluations == 1 and np.all(self.converged):
            return "converged at the start"
        codes, counts = np.unique(self.status, return_counts=True)
        return "; ".join(
            f"{count} {optimize.STATUS_MESSAGES[code]}"
            for code, count in zip(codes.tolist(), counts.tolist())
        )


def fit_hyperparameters(
    log_params: np.ndarray,
    X: np.ndarray | TrainingData,
    z: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    bounds: np.ndarray | None = None,
    max_iterations: int = 50,
    gradient_tolerance: float = 1e-5,
    inverse_hessian: np.ndarray | None = None,
) -> FitResult:
    """Maximum-likelihood hyperparameters in log space, warm-started at ``log_params``
    (*B, p): every problem of the batch is fitted on its own, all of them with one
    likelihood evaluation per round (:func:`agents.optimize.minimize_in_box`, a projected
    BFGS method), so a problem's result does not depend on the rest of the batch.

    A problem whose projected gradient at the start is already below
    ``gradient_tolerance`` (the usual case for a warm start on a window that changed
    little) keeps its start. The result never contains NaN: where the likelihood is not
    finite at the start, or the evaluation raises, the start is kept (``kept_start``).
    """
    start = np.asarray(log_params, dtype=float)
    d = start.shape[-1] - 2
    bounds = default_bounds(d) if bounds is None else np.asarray(bounds, dtype=float)
    start = np.clip(start, bounds[:, 0], bounds[:, 1])
    shape = start.shape
    data = _as_data(X, z, mask)

    def negative_log_likelihood(flat: np.ndarray):
        value, gradient = log_marginal_likelihood(flat.reshape(shape), data)
        return -value, -gradient

    try:
        result = optimize.minimize_in_box(
            negative_log_likelihood,
            start,
            bounds,
            max_iterations,
            gradient_tolerance,
            inverse_hessian=inverse_hessian,
        )
    except (NumericalError, np.linalg.LinAlgError, FloatingPointError) as error:
        value, _ = _safe_likelihood(start, data)
        none = np.zeros(shape[:-1], dtype=bool)
        return FitResult(start, value, none, ~none, 0, error=str(error))
    return FitResult(
        result.x,
        -result.value,
        result.converged,
        result.failed,
        result.n_evaluations,
        result.inverse_hessian,
        result.status,
    )


def _safe_likelihood(log_params, data):
    try:
        return log_marginal_likelihood(log_params, data, with_gradient=False)
    except (NumericalError, np.linalg.LinAlgError, FloatingPointError):
        return np.full(np.shape(log_params)[:-1], -np.inf), None
