"""Box-constrained minimisation of many independent small problems at once.

The online hyperparameter fit of a GP tracker (Sec. IV-D) is a handful of quasi-Newton
iterations on 3-4 log hyperparameters per axis. Run one episode at a time, scipy's L-BFGS-B
spends more on its per-call overhead than on the likelihood; run many Monte Carlo episodes
in lockstep (:func:`agents.dgpt.update_batch`), the problems must be solved together, with
one likelihood evaluation for all of them per round, and yet each exactly as if it were
alone. scipy has no batched bound-constrained optimiser, hence this module.

:func:`minimize_in_box` is a projected BFGS method (Bertsekas' projected quasi-Newton with
an Armijo line search along the projection arc, Nocedal & Wright Alg. 6.1 for the update).
Every problem has its own iterate, inverse-Hessian approximation, step length and stopping
state, and every operation is elementwise over problems, so a problem's iterates do not
depend on which other problems share the batch.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["BoxResult", "minimize_in_box", "projected_gradient", "STATUS_MESSAGES"]

RUNNING, CONVERGED, ITERATION_LIMIT, LINE_SEARCH_FAILED, FAILED_AT_START = range(5)
STATUS_MESSAGES = {
    CONVERGED: "projected gradient below tolerance",
    ITERATION_LIMIT: "iteration limit reached",
    LINE_SEARCH_FAILED: "line search found no decrease",
    FAILED_AT_START: "objective not finite at the start",
}
_ARMIJO = 1e-4
_MAX_BACKTRACKS = 10


@dataclass(frozen=True)
class BoxResult:
    """Outcome per problem (leading shape ``S`` of the start): ``x`` (S, p), ``value`` (S,)
    and ``gradient`` (S, p) there, ``status`` (S,) a key of :data:`STATUS_MESSAGES`,
    ``iterations`` (S,) accepted steps; ``n_evaluations`` rounds of the objective (each
    evaluates every problem); ``inverse_hessian`` (S, p, p) the final BFGS approximation,
    NaN where no curvature was gathered (to warm-start a related problem)."""

    x: np.ndarray
    value: np.ndarray
    gradient: np.ndarray
    status: np.ndarray
    iterations: np.ndarray
    n_evaluations: int
    inverse_hessian: np.ndarray

    @property
    def converged(self) -> np.ndarray:
        return self.status == CONVERGED

    @property
    def failed(self) -> np.ndarray:
        return self.status == FAILED_AT_START


def projected_gradient(x: np.ndarray, gradient: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """The gradient with the components that point out of the box at an active bound set to
    zero: a point is optimal for the box-constrained problem where this vanishes."""
    blocked = ((x <= bounds[:, 0]) & (gradient > 0)) | ((x >= bounds[:, 1]) & (gradient < 0))
    return np.where(blocked, 0.0, gradient)


def _matvec(matrices: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """(P, p, p) x (P, p) -> (P, p), summed elementwise (no BLAS: identical per problem)."""
    return (matrices * vectors[:, None, :]).sum(axis=-1)


def _bfgs_update(inverse_hessian, s, y, fresh):
    """BFGS update of the inverse Hessian H with step s and gradient change y (N&W eq.
    (6.17)); where ``fresh`` (no curvature yet) H is first scaled to s.y / y.y I (eq.
    (6.20)). Problems with s.y <= 0 keep H."""
    sy = (s * y).sum(axis=-1)
    yy = (y * y).sum(axis=-1)
    curved = sy > 1e-12 * np.sqrt((s * s).sum(axis=-1) * yy)
    H = inverse_hessian
    if fresh.any():
        scale = np.where(curved, sy / np.where(yy > 0, yy, 1.0), 1.0)
        H = np.where(fresh[:, None, None], scale[:, None, None] * np.eye(s.shape[-1]), H)
    rho = np.where(curved, 1.0 / np.where(curved, sy, 1.0), 0.0)[:, None, None]
    Hy = _matvec(H, y)
    yHy = (y * Hy).sum(axis=-1)[:, None, None]
    cross = Hy[:, :, None] * s[:, None, :]
    updated = (
        H
        - rho * (cross + np.swapaxes(cross, -1, -2))
        + (rho + rho * rho * yHy) * (s[:, :, None] * s[:, None, :])
    )
    return np.where(curved[:, None, None], updated, inverse_hessian), fresh & ~curved


def minimize_in_box(
    fun: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    x0: np.ndarray,
    bounds: np.ndarray,
    max_iterations: int = 50,
    gradient_tolerance: float = 1e-5,
    max_step: float = 1.0,
    inverse_hessian: np.ndarray | None = None,
) -> BoxResult:
    """Minimise independent problems ``fun`` over the box ``bounds``.

    Args:
        fun: ``x`` (P, p) -> (value (P,), gradient (P, p)); called with every problem in
            each round (finished problems at their final point). Non-finite values are
            allowed: at the start they fail the problem, at a trial point they shorten the
            step.
        x0: (*S, p) starts, clipped into the box.
        bounds: (p, 2) lower and upper bounds, shared by all problems.
        max_iterations: accepted steps per problem.
        gradient_tolerance: stop a problem when the largest component of its projected
            gradient (:func:`projected_gradient`) is at most this.
        max_step: the first step of a problem, which has no curvature information yet, is
            scaled to at most this in every coordinate.
        inverse_hessian: (*S, p, p) starting BFGS approximations of the inverse Hessians
            (a previous result's, when the problems change little from call to call); NaN
            or None where there is none.

    Each iteration takes the quasi-Newton direction on the coordinates not held at a bound,
    moves along the projection of that ray onto the box and backtracks (safeguarded
    quadratic interpolation) until the Armijo condition holds; if ten backtracks find no
    decrease, the iteration is retried along the projected steepest descent with the
    curvature forgotten. A problem stops when its projected gradient is small, after
    ``max_iterations`` accepted steps, or when steepest descent finds no decrease either.
    Values never increase.
    """
    x0 = np.asarray(x0, dtype=float)
    bounds = np.asarray(bounds, dtype=float)
    shape, p = x0.shape[:-1], x0.shape[-1]
    if bounds.shape != (p, 2):
        raise ValueError(f"bounds must have shape ({p}, 2); got {bounds.shape}")
    lower, upper = bounds[:, 0], bounds[:, 1]
    x = np.clip(x0.reshape(-1, p), lower, upper)
    n_problems = x.shape[0]

    def evaluate(points):
        value, gradient = fun(points)
        value = np.asarray(value, dtype=float).reshape(n_problems)
        gradient = np.asarray(gradient, dtype=float).reshape(n_problems, p)
        finite = np.isfinite(value) & np.isfinite(gradient).all(axis=-1)
        return value, gradient, finite

    value, gradient, finite = evaluate(x)
    n_evaluations = 1
    status = np.where(finite, RUNNING, FAILED_AT_START)
    gradient = np.where(finite[:, None], gradient, 0.0)
    status[(status == RUNNING) & _small(x, gradient, bounds, gradient_tolerance)] = CONVERGED
    iterations = np.zeros(n_problems, dtype=np.int64)
    if inverse_hessian is None:
        fresh = np.ones(n_problems, dtype=bool)
        inverse_hessian = np.broadcast_to(np.eye(p), (n_problems, p, p)).copy()
    else:
        inverse_hessian = np.asarray(inverse_hessian, dtype=float).reshape(n_problems, p, p)
        fresh = ~np.all(np.isfinite(inverse_hessian), axis=(-1, -2))
        inverse_hessian = np.where(fresh[:, None, None], np.eye(p), inverse_hessian)
    direction = np.zeros_like(x)
    step_length = np.ones(n_problems)
    backtracks = np.zeros(n_problems, dtype=np.int64)
    steepest = np.zeros(n_problems, dtype=bool)  # retrying an iteration along -g
    new_direction = status == RUNNING
    max_rounds = 2 * max_iterations * (_MAX_BACKTRACKS + 1)
    while (status == RUNNING).any() and n_evaluations <= max_rounds:
        if new_direction.any():
            candidate = _direction(x, gradient, inverse_hessian, fresh, steepest, bounds, max_step)
            direction = np.where(new_direction[:, None], candidate, direction)
            step_length = np.where(new_direction, 1.0, step_length)
            backtracks = np.where(new_direction, 0, backtracks)
        running = status == RUNNING
        trial = np.where(
            running[:, None],
            np.minimum(np.maximum(x + step_length[:, None] * direction, lower), upper),
            x,
        )
        trial_value, trial_gradient, trial_finite = evaluate(trial)
        n_evaluations += 1
        step = trial - x
        slope = (gradient * step).sum(axis=-1)
        accepted = running & trial_finite & (slope < 0) & (trial_value <= value + _ARMIJO * slope)
        if accepted.any():
            # the gradient change on the coordinates that moved: the curvature of the face
            # the step ran along (coordinates held at a bound would add spurious terms)
            y = np.where(accepted[:, None] & (step != 0), trial_gradient - gradient, 0.0)
            updated, still_fresh = _bfgs_update(inverse_hessian, step, y, fresh)
            inverse_hessian = np.where(accepted[:, None, None], updated, inverse_hessian)
            fresh = np.where(accepted, still_fresh, fresh)
            x = np.where(accepted[:, None], trial, x)
            value = np.where(accepted, trial_value, value)
            gradient = np.where(accepted[:, None], trial_gradient, gradient)
            iterations += accepted
            small = _small(x, gradient, bounds, gradient_tolerance)
            status[accepted & small] = CONVERGED
            status[accepted & ~small & (iterations >= max_iterations)] = ITERATION_LIMIT
        steepest &= ~accepted
        new_direction = accepted & (status == RUNNING)
        rejected = running & ~accepted
        if not rejected.any():  # the usual round: the full step was taken everywhere
            continue
        shrunk = _backtrack(step_length, slope, value, trial_value, trial_finite)
        step_length = np.where(rejected, shrunk, step_length)
        backtracks += rejected
        stuck = rejected & ((backtracks > _MAX_BACKTRACKS) | (slope >= 0))
        if stuck.any():
            # a quasi-Newton direction that finds no decrease is retried once along -g
            # with fresh curvature; a steepest-descent one that finds none ends the problem
            status[stuck & steepest] = LINE_SEARCH_FAILED
            retry = stuck & ~steepest
            steepest |= retry
            fresh |= retry
            inverse_hessian = np.where(retry[:, None, None], np.eye(p), inverse_hessian)
            new_direction |= retry
    status[status == RUNNING] = ITERATION_LIMIT
    return BoxResult(
        x=x.reshape(x0.shape),
        value=value.reshape(shape),
        gradient=gradient.reshape(x0.shape),
        status=status.reshape(shape),
        iterations=iterations.reshape(shape),
        n_evaluations=n_evaluations,
        inverse_hessian=np.where(fresh[:, None, None], np.nan, inverse_hessian).reshape(
            shape + (p, p)
        ),
    )


def _small(x, gradient, bounds, tolerance) -> np.ndarray:
    """Where the projected gradient's largest component is at most ``tolerance``."""
    return np.abs(projected_gradient(x, gradient, bounds)).max(axis=-1) <= tolerance


def _direction(x, gradient, inverse_hessian, fresh, steepest, bounds, max_step):
    """Quasi-Newton direction -H g on the free coordinates: those not held at a bound,
    neither by the gradient nor by the direction itself (a coordinate at a bound that the
    direction would push out of the box is fixed and the direction recomputed, so that a
    short step along it stays a descent direction: a principal submatrix of H is positive
    definite). Steepest descent where ``steepest`` or where that fails; scaled to
    ``max_step`` per coordinate while there is no curvature yet."""
    lower, upper = bounds[:, 0], bounds[:, 1]
    at_lower, at_upper = x <= lower, x >= upper
    if (at_lower | at_upper).any():
        free_gradient = projected_gradient(x, gradient, bounds)
        free = free_gradient != 0.0
        for _ in range(x.shape[-1]):
            restricted = inverse_hessian * (free[:, :, None] & free[:, None, :])
            direction = -_matvec(restricted, np.where(free, gradient, 0.0))
            leaving = free & ((at_lower & (direction < 0)) | (at_upper & (direction > 0)))
            if not leaving.any():
                break
            free &= ~leaving
        direction = np.where(free, direction, 0.0)
    else:  # the interior: the same, without masks (a zero gradient component stays fixed)
        free_gradient = gradient
        free = gradient != 0.0
        if free.all():
            direction = -_matvec(inverse_hessian, gradient)
        else:
            restricted = inverse_hessian * (free[:, :, None] & free[:, None, :])
            direction = np.where(free, -_matvec(restricted, gradient), 0.0)
    descent = (direction * gradient).sum(axis=-1) < 0
    fallback = steepest | ~descent
    direction = np.where(fallback[:, None], -free_gradient, direction)
    largest = np.abs(direction).max(axis=-1)
    first = fresh | fallback
    scale = np.where(first & (largest > max_step), max_step / np.maximum(largest, 1e-300), 1.0)
    return direction * scale[:, None]


def _backtrack(step_length, slope, value, trial_value, trial_finite):
    """Next step length after a rejected trial: the minimiser of the quadratic through the
    value and slope at 0 and the trial value, kept within [0.1, 0.5] of the last length
    (0.25 of it where the trial was not finite)."""
    curvature = trial_value - value - slope
    with np.errstate(divide="ignore", invalid="ignore"):
        quadratic = step_length * (-slope) / (2.0 * curvature)
    quadratic = np.where(trial_finite & (curvature > 0), quadratic, 0.25 * step_length)
    return np.clip(quadratic, 0.1 * step_length, 0.5 * step_length)
