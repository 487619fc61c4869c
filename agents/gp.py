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
from scipy import optimize
from scipy.linalg import lapack

__all__ = [
    "NumericalError",
    "TrainingData",
    "Factorization",
    "unpack",
    "se_kernel",
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
class TrainingData:
    """Training inputs and outputs with what does not depend on the hyperparameters
    precomputed: the per-dimension squared input differences and the mask weights.
    Build it once (:meth:`build`) and evaluate many hyperparameters on it."""

    X: np.ndarray
    z: np.ndarray
    weight: np.ndarray
    pair_weight: np.ndarray
    squared_differences: np.ndarray
    padding_diagonal: np.ndarray
    identity: np.ndarray

    @classmethod
    def build(cls, X: np.ndarray, z: np.ndarray, mask: np.ndarray | None = None) -> TrainingData:
        X = np.asarray(X, dtype=float)
        if mask is None:
            mask = np.ones(X.shape[:-1], dtype=bool)
        weight = np.broadcast_to(np.asarray(mask, dtype=float), X.shape[:-1])
        diff = X[..., :, None, :] - X[..., None, :, :]
        identity = np.eye(X.shape[-2])
        return cls(
            X=X,
            z=np.asarray(z, dtype=float) * weight,
            weight=weight,
            pair_weight=weight[..., :, None] * weight[..., None, :],
            squared_differences=diff * diff,
            padding_diagonal=(1.0 - weight)[..., None] * identity,
            identity=identity,
        )


@dataclass(frozen=True)
class Factorization:
    """What the likelihood, its gradient and predictions share for one set of hyperparameters.

    ``kernel`` is the masked noise-free covariance K, ``inverse`` the inverse of
    Sigma = K + sigma_n^2 I (unit diagonal on padding), ``log_det`` log|Sigma| per expert,
    ``scaled`` the per-dimension scaled squared differences, ``alpha`` = Sigma^-1 z,
    ``jitter`` what was added to the diagonal to make Sigma positive definite (0 normally).
    """

    kernel: np.ndarray
    inverse: np.ndarray
    log_det: np.ndarray
    scaled: np.ndarray
    alpha: np.ndarray
    jitter: float


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

    If Sigma is not numerically positive definite, jitter of 1e-10, 1e-8, ..., 1e-2 times
    the mean diagonal is added until it is; :class:`NumericalError` if even that fails.
    """
    params = np.exp(np.asarray(log_params, dtype=float))[..., None, None, None, :]
    scaled = data.squared_differences / (params[..., 1:-1] * params[..., 1:-1])
    kernel = params[..., 0] * data.pair_weight * np.exp(-0.5 * scaled.sum(axis=-1))
    noise_diagonal = params[..., -1] * data.weight[..., None] * data.identity
    sigma = kernel + noise_diagonal + data.padding_diagonal
    n = kernel.shape[-1]
    jitter = 0.0
    try:
        inverse, log_det = _cholesky_inverse(sigma)
    except np.linalg.LinAlgError:
        scale = float(np.mean(np.diagonal(sigma, axis1=-2, axis2=-1)))
        for exponent in range(-10, 0, 2):
            jitter = scale * 10.0**exponent
            try:
                inverse, log_det = _cholesky_inverse(
                    sigma + (jitter * data.weight)[..., None] * np.eye(n)
                )
                break
            except np.linalg.LinAlgError:
                continue
        else:
            raise NumericalError(
                "covariance matrix is not positive definite even with jitter"
            ) from None
    alpha = np.einsum("...ij,...j->...i", inverse, data.z)
    return Factorization(kernel, inverse, log_det, scaled, alpha, jitter)


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
    per_expert = -0.5 * np.einsum("...i,...i->...", data.z, alpha) - 0.5 * fact.log_det
    value = per_expert.sum(axis=-1) - 0.5 * LOG_2PI * data.weight.sum(axis=(-1, -2))
    if not with_gradient:
        return value, None
    inner = alpha[..., :, None] * alpha[..., None, :] - fact.inverse
    weighted = inner * fact.kernel
    grad_signal = 0.5 * weighted.sum(axis=(-1, -2, -3))
    grad_lengthscales = 0.5 * np.einsum("...mab,...mabd->...d", weighted, fact.scaled)
    noise = np.exp(np.asarray(log_params, dtype=float)[..., -1])
    inner_diagonal = np.diagonal(inner, axis1=-2, axis2=-1)
    grad_noise = 0.5 * noise * (inner_diagonal * data.weight).sum(axis=(-1, -2))
    gradient = np.concatenate(
        [grad_signal[..., None], grad_lengthscales, grad_noise[..., None]], axis=-1
    )
    return value, gradient


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
    to ``[1e-12 sigma_f^2, sigma_f^2]`` against round-off.
    """
    data = _as_data(X, z, mask)
    fact = factorize(log_params, data) if factorization is None else factorization
    cross = (
        se_kernel(data.X, np.asarray(X_test, dtype=float), log_params) * data.weight[..., :, None]
    )
    mean = np.einsum("...ns,...n->...s", cross, fact.alpha)
    reduction = np.einsum("...ns,...nm,...ms->...s", cross, fact.inverse, cross)
    prior = np.exp(np.asarray(log_params, dtype=float)[..., 0])[..., None, None]
    variance = np.clip(prior - reduction, 1e-12 * prior, prior)
    return mean, variance


def default_bounds(d: int) -> np.ndarray:
    """Loose (p, 2) bounds on the log hyperparameters: sigma_f^2 in [1e-4, 1e8], length
    scales in [1e-2, 1e5], sigma_n^2 in [1e-6, 1e6] (in the data's units)."""
    rows = [(1e-4, 1e8)] + [(1e-2, 1e5)] * d + [(1e-6, 1e6)]
    return np.log(np.array(rows))


@dataclass(frozen=True)
class FitResult:
    """Outcome of :func:`fit_hyperparameters`: the hyperparameters to use and the log
    likelihood there; ``converged`` when L-BFGS-B met its tolerance (an improvement cut by
    the iteration limit is used all the same), ``kept_start`` when the optimisation failed
    and the start is returned."""

    log_params: np.ndarray
    log_likelihood: np.ndarray
    converged: bool
    kept_start: bool
    n_evaluations: int
    message: str


def fit_hyperparameters(
    log_params: np.ndarray,
    X: np.ndarray | TrainingData,
    z: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    bounds: np.ndarray | None = None,
    max_iterations: int = 50,
    gradient_tolerance: float = 1e-5,
) -> FitResult:
    """Maximum-likelihood hyperparameters with L-BFGS-B in log space, warm-started at
    ``log_params`` (*B, p); the batch's independent problems are optimised jointly (their
    likelihoods add).

    When the projected gradient at the start is already below ``gradient_tolerance`` (the
    usual case for a warm start on a window that changed little), the start is returned
    without calling the optimiser. The result never contains NaN: if the optimisation
    fails, raises inside, or ends below the start's likelihood, the start is kept
    (``kept_start``).
    """
    start = np.asarray(log_params, dtype=float)
    d = start.shape[-1] - 2
    bounds = default_bounds(d) if bounds is None else np.asarray(bounds, dtype=float)
    start = np.clip(start, bounds[:, 0], bounds[:, 1])
    shape = start.shape
    data = _as_data(X, z, mask)
    memo: dict[bytes, tuple[float, np.ndarray, np.ndarray]] = {}

    def evaluate(flat: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        key = flat.tobytes()
        if key not in memo:
            value, gradient = log_marginal_likelihood(flat.reshape(shape), data)
            total = -float(np.sum(value))
            if not np.isfinite(total) or not np.all(np.isfinite(gradient)):
                raise NumericalError("non-finite likelihood")
            memo[key] = (total, -gradient.ravel(), value)
        return memo[key]

    def objective(flat: np.ndarray) -> tuple[float, np.ndarray]:
        total, gradient, _ = evaluate(flat)
        return total, gradient

    flat_bounds = np.tile(bounds, (int(np.prod(shape[:-1])), 1))
    try:
        start_total, start_gradient, start_value = evaluate(start.ravel())
        blocked = ((start.ravel() <= flat_bounds[:, 0]) & (start_gradient > 0)) | (
            (start.ravel() >= flat_bounds[:, 1]) & (start_gradient < 0)
        )
        if np.max(np.abs(np.where(blocked, 0.0, start_gradient))) <= gradient_tolerance:
            return FitResult(start, start_value, True, False, len(memo), "converged at the start")
        result = optimize.minimize(
            objective,
            start.ravel(),
            jac=True,
            method="L-BFGS-B",
            bounds=flat_bounds,
            options={"maxiter": max_iterations, "gtol": gradient_tolerance},
        )
        fitted = result.x.reshape(shape)
        if not np.all(np.isfinite(fitted)) or result.fun > start_total:
            return FitResult(start, start_value, False, True, len(memo), str(result.message))
        _, _, value = evaluate(result.x)
    except (NumericalError, np.linalg.LinAlgError, FloatingPointError) as error:
        value, _ = _safe_likelihood(start, data)
        return FitResult(start, value, False, True, len(memo), str(error))
    return FitResult(fitted, value, bool(result.success), False, len(memo), str(result.message))


def _safe_likelihood(log_params, data):
    try:
        return log_marginal_likelihood(log_params, data, with_gradient=False)
    except NumericalError:
        return np.full(np.shape(log_params)[:-1], -np.inf), None
