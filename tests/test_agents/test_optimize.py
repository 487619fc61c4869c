"""The batched box-constrained minimiser against closed-form optima, and its independence
of the batch."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from agents import optimize


def quadratic(hessians, centres):
    """f(x) = 1/2 (x - c)^T A (x - c) per problem, with its gradient."""

    def fun(x):
        offset = x - centres
        gradient = np.einsum("pij,pj->pi", hessians, offset)
        return 0.5 * np.sum(offset * gradient, axis=-1), gradient

    return fun


def box_quadratic_optimum(hessian, centre, bounds):
    """Exact minimiser of a convex quadratic over a box by enumerating the active sets
    (3^p of them: each coordinate free, at its lower or at its upper bound)."""
    p = centre.size
    best, best_value = None, np.inf
    for code in np.ndindex(*(3,) * p):
        fixed = np.array(code) > 0
        x = np.where(np.array(code) == 1, bounds[:, 0], bounds[:, 1])
        free = ~fixed
        if free.any():
            # A_ff x_f = A_ff c_f - A_fx (x_x - c_x)
            rhs = hessian[np.ix_(free, free)] @ centre[free] - hessian[np.ix_(free, fixed)] @ (
                x[fixed] - centre[fixed]
            )
            x[free] = np.linalg.solve(hessian[np.ix_(free, free)], rhs)
        if np.any(x < bounds[:, 0] - 1e-12) or np.any(x > bounds[:, 1] + 1e-12):
            continue
        value = 0.5 * (x - centre) @ hessian @ (x - centre)
        if value < best_value:
            best, best_value = x, value
    return best


@settings(max_examples=40, deadline=None)
@given(st.integers(min_value=0, max_value=2**32 - 1), st.integers(min_value=1, max_value=4))
def test_convex_quadratics_reach_the_box_optimum(seed, p):
    rng = np.random.default_rng(seed)
    problems = 6
    roots = rng.normal(size=(problems, p, p))
    hessians = roots @ np.swapaxes(roots, -1, -2) + 0.5 * np.eye(p)
    centres = rng.normal(scale=2.0, size=(problems, p))
    bounds = np.sort(rng.normal(size=(p, 2)), axis=-1) + np.array([-0.5, 0.5])
    start = rng.uniform(bounds[:, 0], bounds[:, 1], size=(problems, p))
    result = optimize.minimize_in_box(
        quadratic(hessians, centres), start, bounds, max_iterations=200, gradient_tolerance=1e-7
    )
    assert np.all(result.converged), result.status
    for index in range(problems):
        exact = box_quadratic_optimum(hessians[index], centres[index], bounds)
        # on the optimal face |x - x*|_2 <= |projected gradient|_2 / lambda_min, with
        # lambda_min >= 0.5 and |pg|_2 <= sqrt(p) 1e-7 <= 2e-7: at most 4e-7
        np.testing.assert_allclose(result.x[index], exact, atol=4e-7)


def test_rosenbrock_in_a_box_and_values_never_increase():
    """The Rosenbrock valley from (-1.2, 1): unconstrained optimum (1, 1); with the upper
    bound 0.5 on x the optimum is (0.5, 0.25) (the valley floor y = x^2 at the bound)."""

    def rosenbrock(x):
        a, b = x[:, 0], x[:, 1]
        value = (1 - a) ** 2 + 100 * (b - a * a) ** 2
        gradient = np.stack([-2 * (1 - a) - 400 * a * (b - a * a), 200 * (b - a * a)], axis=-1)
        return value, gradient

    start = np.array([[-1.2, 1.0], [-1.2, 1.0]])
    wide = np.array([[-5.0, 5.0], [-5.0, 5.0]])
    result = optimize.minimize_in_box(rosenbrock, start[:1], wide, 500, 1e-8)
    np.testing.assert_allclose(result.x[0], [1.0, 1.0], atol=1e-6)
    capped = np.array([[-5.0, 0.5], [-5.0, 5.0]])
    result = optimize.minimize_in_box(rosenbrock, start[:1], capped, 500, 1e-8)
    np.testing.assert_allclose(result.x[0], [0.5, 0.25], atol=1e-6)
    values = [rosenbrock(start[:1])[0][0]]
    for iterations in range(1, 30):
        values.append(optimize.minimize_in_box(rosenbrock, start[:1], wide, iterations).value[0])
    assert np.all(np.diff(values) <= 0)


def test_a_problem_is_solved_the_same_in_any_batch():
    rng = np.random.default_rng(3)
    p, problems = 3, 7
    roots = rng.normal(size=(problems, p, p))
    hessians = roots @ np.swapaxes(roots, -1, -2) + 0.1 * np.eye(p)
    centres = rng.normal(scale=3.0, size=(problems, p))
    start = rng.normal(size=(problems, p))
    bounds = np.array([[-1.0, 1.0]] * p)
    together = optimize.minimize_in_box(quadratic(hessians, centres), start, bounds, 5, 1e-6)
    for index in range(problems):
        alone = optimize.minimize_in_box(
            quadratic(hessians[index : index + 1], centres[index : index + 1]),
            start[index : index + 1],
            bounds,
            5,
            1e-6,
        )
        np.testing.assert_array_equal(alone.x[0], together.x[index])
        assert alone.status[0] == together.status[index]


def test_non_finite_start_fails_only_its_problem_and_non_finite_trials_shorten_the_step():
    """f = (x - 3)^2 with f = NaN beyond x = 2: from 0 the first trial (x = 1, the step cap)
    is fine; a later overshoot past 2 must be pulled back, never accepted."""

    def fun(x):
        value = np.where(x[:, 0] > 2.0, np.nan, (x[:, 0] - 3.0) ** 2)
        return value, 2.0 * (x - 3.0)

    start = np.array([[0.0], [2.5]])
    result = optimize.minimize_in_box(fun, start, np.array([[-10.0, 10.0]]), 50, 1e-8)
    assert result.failed.tolist() == [False, True]
    assert result.x[1, 0] == 2.5  # the failed problem keeps its start
    assert 1.9 < result.x[0, 0] <= 2.0 and np.isfinite(result.value[0])


def test_a_start_at_the_optimum_costs_one_evaluation():
    fun = quadratic(np.eye(2)[None], np.array([[0.3, -0.2]]))
    result = optimize.minimize_in_box(fun, np.array([[0.3, -0.2]]), np.array([[-1, 1]] * 2), 5)
    assert result.n_evaluations == 1 and result.converged[0] and result.iterations[0] == 0


def test_a_warm_started_curvature_takes_the_newton_step():
    """Given the exact inverse Hessian of a quadratic, the first step is Newton's and lands
    on the (interior) optimum: one iteration, two evaluations. Without it, more are needed;
    the result hands back a curvature for the next call."""
    hessian = np.array([[[4.0, 1.0], [1.0, 3.0]]])
    centre = np.array([[0.3, -0.2]])
    bounds = np.array([[-1.0, 1.0]] * 2)
    start = np.array([[0.9, 0.8]])
    warm = optimize.minimize_in_box(
        quadratic(hessian, centre), start, bounds, 5, 1e-9, inverse_hessian=np.linalg.inv(hessian)
    )
    assert (warm.iterations[0], warm.n_evaluations) == (1, 2) and warm.converged[0]
    np.testing.assert_allclose(warm.x[0], centre[0], atol=1e-12)
    cold = optimize.minimize_in_box(quadratic(hessian, centre), start, bounds, 5, 1e-9)
    assert cold.n_evaluations > 2 and np.all(np.isfinite(cold.inverse_hessian))
