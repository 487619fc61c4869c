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
    "Factorization",
    "n_params",
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


def n_params(d: int) -> int:
    """Number of hyperparameters of a d-dimensional ARD squared-exponential kernel plus noise."""
    return d + 2


def unpack(log_params: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(signal variance (*B,), length scales (*B, d), noise variance (*B,)) from log parameters."""
    log_params = np.asarray(log_params, dtype=float)
    return np.exp(log_params[..., 0]), np.exp(log_params[..., 1:-1]), np.exp(log_params[..., -1])


def _scaled_squared_differences(x1: np.ndarray, x2: np.ndarray, lengthscales: np.ndarray) -> np.ndarray:
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
class Factorization:
    """What the likelihood, its gradient and predictions share for one set of hyperparameters.

    ``kernel`` is the masked noise-free covariance K, ``inverse`` the inverse of
    Sigma = K + sigma_n^2 I (unit diagonal on padding), ``log_det`` log|Sigma| per expert,
    ``scaled`` the per-dimension scaled squared differences, ``jitter`` what was added to the
    diagonal to make Sigma positive definite (0 normally).
    """

    kernel: np.ndarray
    inverse: np.ndarray
    log_det: np.ndarray
    scaled: np.ndarray
    mask: np.ndarray
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
    factor = np.linalg.cholesky(matrices)
    factor_inverse = np.linalg.inv(factor)
    log_det = 2.0 * np.log(np.diagonal(factor, axis1=-2, axis2=-1)).sum(axis=-1)
    return np.swapaxes(factor_inverse, -1, -2) @ factor_inverse, log_det


def factorize(log_params: np.ndarray, X: np.ndarray, mask: np.ndarray | None = None) -> Factorization:
    """Build K and invert Sigma = K + sigma_n^2 I for every expert, with escalating jitter.

    If Sigma is not numerically positive definite, jitter of 1e-10, 1e-8, ..., 1e-2 times
    the mean diagonal is added until it is; :class:`NumericalError` if even that fails.
    """
    X = np.asarray(X, dtype=float)
    mask = np.ones(X.shape[:-1], dtype=bool) if mask is None else np.broadcast_to(mask, X.shape[:-1])
    weight = mask.astype(float)
    signal, lengthscales, noise = unpack(np.asarray(log_params)[..., None, :])
    scaled = _scaled_squared_differences(X, X, lengthscales)
    kernel = signal[..., None, None] * np.exp(-0.5 * scaled.sum(axis=-1))
    kernel *= weight[..., :, None] * weight[..., None, :]
    diagonal = noise[..., None] * weight + (1.0 - weight)
    sigma = kernel.copy()
    index = np.arange(X.shape[-2])
    sigma[..., index, index] += diagonal
    try:
        inverse, log_det = _cholesky_inverse(sigma)
        jitter = 0.0
    except np.linalg.LinAlgError:
        scale = float(np.mean(np.diagonal(sigma, axis1=-2, axis2=-1)))
        for exponent in range(-10, 0, 2):
            jitter = scale * 10.0**exponent
            jittered = sigma.copy()
            jittered[..., index, index] += jitter * weight
            try:
                inverse, log_det = _cholesky_inverse(jittered)
                break
            except np.linalg.LinAlgError:
                continue
        else:
            raise NumericalError("covariance matrix is not positive definite even with jitter") from None
    return Factorization(kernel, inverse, log_det, scaled, weight, jitter)


def log_marginal_likelihood(
    log_params: np.ndarray,
    X: np.ndarray,
    z: np.ndarray,
    mask: np.ndarray | None = None,
    with_gradient: bool = True,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Factorized log marginal likelihood, eq. (22): the sum over experts of eq. (21),
    ``-1/2 z^T Sigma^-1 z - 1/2 log|Sigma| - n/2 log 2 pi``, and its gradient with respect to
    the log hyperparameters, ``1/2 tr((alpha alpha^T - Sigma^-1) dSigma/dtheta)``.

    Returns ``(value (*B,), gradient (*B, p) or None)``.
    """
    fact = factorize(log_params, X, mask)
    z = np.asarray(z, dtype=float) * fact.mask
    alpha = np.einsum("...ij,...j->...i", fact.inverse, z)
    per_expert = -0.5 * np.einsum("...i,...i->...", z, alpha) - 0.5 * fact.log_det
    per_expert -= 0.5 * LOG_2PI * fact.mask.sum(axis=-1)
    value = per_expert.sum(axis=-1)
    if not with_gradient:
        return value, None
    inner = alpha[..., :, None] * alpha[..., None, :] - fact.inverse
    weighted = inner * fact.kernel
    grad_signal = 0.5 * weighted.sum(axis=(-1, -2))
    grad_lengthscales = 0.5 * np.einsum("...ab,...abd->...d", weighted, fact.scaled)
    _, _, noise = unpack(np.asarray(log_params)[..., None, :])
    inner_diagonal = np.diagonal(inner, axis1=-2, axis2=-1)
    grad_noise = 0.5 * noise * (inner_diagonal * fact.mask).sum(axis=-1)
    gradient = np.concatenate(
        [grad_signal[..., None], grad_lengthscales, grad_noise[..., None]], axis=-1
    ).sum(axis=-2)
    return value, gradient


def predict(
    log_params: np.ndarray,
    X: np.ndarray,
    z: np.ndarray,
    mask: np.ndarray | None,
    X_test: np.ndarray,
    factorization: Factorization | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Posterior predictive mean and latent variance of every expert, eqs. (6)-(7) with zero
    prior mean: ``mu = k*^T Sigma^-1 z``, ``sigma^2 = k** - k*^T Sigma^-1 k*``.

    ``X_test`` (*B, M, s, d); returns mean and variance (*B, M, s). The variance is clipped
    to ``[1e-12 sigma_f^2, sigma_f^2]`` against round-off.
    """
    fact = factorize(log_params, X, mask) if factorization is None else factorization
    z = np.asarray(z, dtype=float) * fact.mask
    cross = se_kernel(np.asarray(X, dtype=float), np.asarray(X_test, dtype=float), log_params)
    cross = cross * fact.mask[..., :, None]
    alpha = np.einsum("...ij,...j->...i", fact.inverse, z)
    mean = np.einsum("...ns,...n->...s", cross, alpha)
    reduction = np.einsum("...ns,...nm,...ms->...s", cross, fact.inverse, cross)
    signal, _, _ = unpack(np.asarray(log_params)[..., None, :])
    prior = signal[..., None]
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
    X: np.ndarray,
    z: np.ndarray,
    mask: np.ndarray | None = None,
    bounds: np.ndarray | None = None,
    max_iterations: int = 50,
) -> FitResult:
    """Maximum-likelihood hyperparameters with L-BFGS-B in log space, warm-started at
    ``log_params`` (*B, p); the batch's independent problems are optimised jointly (their
    likelihoods add). The result never contains NaN: if the optimisation fails, raises
    inside, or ends below the start's likelihood, the start is kept (``kept_start``).
    """
    start = np.asarray(log_params, dtype=float)
    d = start.shape[-1] - 2
    bounds = default_bounds(d) if bounds is None else np.asarray(bounds, dtype=float)
    start = np.clip(start, bounds[:, 0], bounds[:, 1])
    shape = start.shape
    counter = {"evaluations": 0}

    def objective(flat: np.ndarray) -> tuple[float, np.ndarray]:
        counter["evaluations"] += 1
        value, gradient = log_marginal_likelihood(flat.reshape(shape), X, z, mask)
        total = -float(np.sum(value))
        if not np.isfinite(total) or not np.all(np.isfinite(gradient)):
            raise NumericalError("non-finite likelihood")
        return total, -gradient.ravel()

    try:
        start_value = -objective(start.ravel())[0]
        result = optimize.minimize(
            objective,
            start.ravel(),
            jac=True,
            method="L-BFGS-B",
            bounds=np.tile(bounds, (int(np.prod(shape[:-1])), 1)),
            options={"maxiter": max_iterations},
        )
    except (NumericalError, np.linalg.LinAlgError, FloatingPointError) as error:
        value, _ = _safe_likelihood(start, X, z, mask)
        return FitResult(start, value, False, True, counter["evaluations"], str(error))
    fitted = result.x.reshape(shape)
    if not np.all(np.isfinite(fitted)) or -result.fun < start_value:
        value, _ = _safe_likelihood(start, X, z, mask)
        return FitResult(start, value, False, True, counter["evaluations"], str(result.message))
    value, _ = log_marginal_likelihood(fitted, X, z, mask, with_gradient=False)
    return FitResult(
        fitted, value, bool(result.success), False, counter["evaluations"], str(result.message)
    )


def _safe_likelihood(log_params, X, z, mask):
    try:
        return log_marginal_likelihood(log_params, X, z, mask, with_gradient=False)
    except NumericalError:
        return np.full(np.shape(log_params)[:-1], -np.inf), None
