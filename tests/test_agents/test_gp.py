"""The GP core against dense textbook formulas, finite differences and known truths."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agents import gp


def random_problem(rng, batch=2, experts=3, points=6, dims=2, fill=0.7):
    X = rng.normal(size=(batch, experts, points, dims))
    z = rng.normal(size=(batch, experts, points))
    mask = rng.random((experts, points)) < fill
    mask[:, 0] = True
    log_params = rng.normal(scale=0.4, size=(batch, dims + 2))
    return log_params, X, z, mask


def dense_expert(log_params, x, y):
    """Covariance, inverse and log-likelihood of one expert with explicit inverse and det."""
    signal, lengthscales, noise = (
        np.exp(log_params[0]),
        np.exp(log_params[1:-1]),
        np.exp(log_params[-1]),
    )
    scaled = ((x[:, None, :] - x[None, :, :]) / lengthscales) ** 2
    kernel = signal * np.exp(-0.5 * scaled.sum(-1))
    sigma = kernel + noise * np.eye(len(x))
    inverse = np.linalg.inv(sigma)
    value = (
        -0.5 * y @ inverse @ y
        - 0.5 * np.log(np.linalg.det(sigma))
        - 0.5 * len(x) * np.log(2 * np.pi)
    )
    return value, inverse


def dense_likelihood(log_params, X, z, mask):
    return np.array(
        [
            sum(
                dense_expert(log_params[b], X[b, m][mask[m]], z[b, m][mask[m]])[0]
                for m in range(X.shape[1])
            )
            for b in range(X.shape[0])
        ]
    )


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), dims=st.integers(1, 3), points=st.integers(1, 7))
def test_likelihood_equals_dense_formula(seed, dims, points):
    log_params, X, z, mask = random_problem(np.random.default_rng(seed), points=points, dims=dims)
    value, _ = gp.log_marginal_likelihood(log_params, X, z, mask)
    np.testing.assert_allclose(
        value, dense_likelihood(log_params, X, z, mask), rtol=1e-9, atol=1e-9
    )


def test_factorized_likelihood_is_the_sum_of_single_experts():
    log_params, X, z, mask = random_problem(np.random.default_rng(1), batch=1, experts=4)
    together, gradient = gp.log_marginal_likelihood(log_params, X, z, mask)
    singles = [
        gp.log_marginal_likelihood(log_params, X[:, m : m + 1], z[:, m : m + 1], mask[m : m + 1])
        for m in range(4)
    ]
    np.testing.assert_allclose(together, sum(value for value, _ in singles), rtol=1e-12)
    np.testing.assert_allclose(gradient, sum(grad for _, grad in singles), rtol=1e-10)


@pytest.mark.parametrize("seed", range(5))
def test_gradient_matches_central_differences(seed):
    log_params, X, z, mask = random_problem(np.random.default_rng(seed))
    _, gradient = gp.log_marginal_likelihood(log_params, X, z, mask)
    step = 1e-6
    numeric = np.zeros_like(log_params)
    for index in np.ndindex(log_params.shape):
        shift = np.zeros_like(log_params)
        shift[index] = step
        plus, _ = gp.log_marginal_likelihood(log_params + shift, X, z, mask, with_gradient=False)
        minus, _ = gp.log_marginal_likelihood(log_params - shift, X, z, mask, with_gradient=False)
        numeric[index] = (plus[index[0]] - minus[index[0]]) / (2 * step)
    np.testing.assert_allclose(gradient, numeric, rtol=1e-6, atol=1e-7)


def test_large_matrices_take_the_lapack_path_with_the_same_result():
    rng = np.random.default_rng(3)
    x = rng.uniform(size=(1, 1, 120, 2))
    y = np.sin(6 * x[..., 0]) + 0.1 * rng.normal(size=(1, 1, 120))
    log_params = np.log([[1.0, 0.3, 0.2, 0.01]])
    value, gradient = gp.log_marginal_likelihood(log_params, x, y)
    expected, _ = dense_expert(log_params[0], x[0, 0], y[0, 0])
    assert value[0] == pytest.approx(expected, rel=1e-9)
    # the LAPACK inverse feeds the gradient: central differences of the value
    step = 1e-6
    for j in range(4):
        shift = np.zeros_like(log_params)
        shift[0, j] = step
        plus, _ = gp.log_marginal_likelihood(log_params + shift, x, y, with_gradient=False)
        minus, _ = gp.log_marginal_likelihood(log_params - shift, x, y, with_gradient=False)
        assert gradient[0, j] == pytest.approx(
            (plus[0] - minus[0]) / (2 * step), rel=1e-5, abs=1e-5
        )


@pytest.mark.parametrize("exact_size", [gp._EXACT_PREDICTION_SIZE, 0])
def test_prediction_equals_dense_formula(exact_size, monkeypatch):
    """Both ways of the predictive variance: the elementwise sums (bit-exact under
    batching) and the matmul that large problems fall back to (``exact_size`` 0)."""
    monkeypatch.setattr(gp, "_EXACT_PREDICTION_SIZE", exact_size)
    rng = np.random.default_rng(4)
    log_params, X, z, mask = random_problem(rng, dims=1)
    X_test = rng.normal(size=(2, 3, 4, 1))
    mean, var = gp.predict(log_params, X, z, mask, X_test)
    for b in range(2):
        for m in range(3):
            x, y = X[b, m][mask[m]], z[b, m][mask[m]]
            _, inverse = dense_expert(log_params[b], x, y)
            signal, length = np.exp(log_params[b, 0]), np.exp(log_params[b, 1])
            cross = signal * np.exp(
                -0.5 * ((x[:, None, 0] - X_test[b, m][None, :, 0]) / length) ** 2
            )
            np.testing.assert_allclose(mean[b, m], cross.T @ inverse @ y, rtol=1e-9, atol=1e-12)
            expected_var = signal - np.einsum("ns,nm,ms->s", cross, inverse, cross)
            np.testing.assert_allclose(var[b, m], expected_var, rtol=1e-8, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    batch=st.integers(2, 6),
    axes=st.integers(1, 2),
    experts=st.integers(1, 8),
    points=st.integers(1, 50),
    tests=st.integers(1, 3),
)
def test_a_batch_reproduces_each_problem_alone_bit_for_bit(
    seed, batch, axes, experts, points, tests
):
    """Likelihood, gradient and prediction of a stack of problems (episodes x axes, as the
    lockstep trackers stack them) equal each problem's alone, to the last bit, also when
    the problem alone comes in another memory layout (an episode's window arrays are built
    axis-last and transposed; a stack of episodes of different layouts is C-ordered), with
    up to 50 points per expert, past the LAPACK path's 48: the RL vector environments and
    the sweep's blocks rely on it. numpy's einsum picks its loop, and so its rounding,
    from the operands' layout (0.17.0's likelihood, gradient and prediction did)."""
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(batch, axes, experts, points, 1))
    z = rng.normal(size=(batch, axes, experts, points))
    mask = rng.random((batch, 1, experts, points)) < 0.8
    mask[..., 0] = True
    log_params = rng.normal(scale=0.4, size=(batch, axes, 3))
    X_test = rng.normal(size=(batch, axes, experts, tests, 1))
    together = gp.TrainingData.build(X, z, mask)
    value, gradient = gp.log_marginal_likelihood(log_params, together)
    mean, var = gp.predict(log_params, together, None, None, X_test)
    for b in range(batch):
        # the values of problem b, stored axis-last as an episode's window builds them
        X_b = np.moveaxis(np.moveaxis(X[b : b + 1], 1, -2).copy(), -2, 1)
        z_b = np.moveaxis(np.moveaxis(z[b : b + 1], 1, -1).copy(), -1, 1)
        alone = gp.TrainingData.build(X_b, z_b, mask[b : b + 1])
        value_b, gradient_b = gp.log_marginal_likelihood(log_params[b : b + 1], alone)
        mean_b, var_b = gp.predict(log_params[b : b + 1], alone, None, None, X_test[b : b + 1])
        np.testing.assert_array_equal(value[b], value_b[0])
        np.testing.assert_array_equal(gradient[b], gradient_b[0])
        np.testing.assert_array_equal(mean[b], mean_b[0])
        np.testing.assert_array_equal(var[b], var_b[0])


def test_padding_does_not_change_anything():
    rng = np.random.default_rng(5)
    log_params, X, z, mask = random_problem(rng, batch=1, experts=1, points=5, fill=1.1)
    padded_X = np.concatenate([X, rng.normal(size=(1, 1, 3, 2))], axis=2)
    padded_z = np.concatenate([z, rng.normal(size=(1, 1, 3))], axis=2)
    padded_mask = np.concatenate([mask, np.zeros((1, 3), bool)], axis=1)
    a = gp.log_marginal_likelihood(log_params, X, z, mask)
    b = gp.log_marginal_likelihood(log_params, padded_X, padded_z, padded_mask)
    np.testing.assert_allclose(a[0], b[0], rtol=1e-12)
    np.testing.assert_allclose(a[1], b[1], rtol=1e-10)


def test_duplicate_inputs_without_noise_are_rescued_by_jitter():
    X = np.zeros((1, 1, 4, 1))  # four identical inputs: K is rank one
    z = np.array([[[1.0, 1.0, 1.0, 1.0]]])
    log_params = np.array([[0.0, 0.0, -800.0]])  # noise variance exp(-800) = 0
    fact = gp.factorize(log_params, gp.TrainingData.build(X, z))
    assert fact.jitter.shape == (1,) and fact.jitter[0] > 0 and not fact.failed[0]
    value, gradient = gp.log_marginal_likelihood(log_params, X, z)
    assert np.all(np.isfinite(value)) and np.all(np.isfinite(gradient))
    # with the jitter as noise the data are four equal observations of one value
    # (to the accuracy the condition number 4 / jitter allows in double precision)
    condition = 4.0 / fact.jitter[0]
    np.testing.assert_allclose(
        fact.alpha, 1.0 / (4.0 + fact.jitter[0]), rtol=10 * condition * 2.2e-16
    )


def test_fit_recovers_generating_hyperparameters():
    """Data drawn from the prior (40 experts x 25 points, 1-D): the MLE lands within four
    asymptotic standard errors of the truth, the errors from the observed information
    (finite differences of the analytic gradient) at the estimate."""
    rng = np.random.default_rng(6)
    truth = np.log([4.0, 0.7, 0.25])
    experts, points = 40, 25
    X = rng.uniform(0, 10, size=(1, experts, points, 1))
    sigma = 4.0 * np.exp(
        -0.5 * ((X[0, :, :, None, 0] - X[0, :, None, :, 0]) / 0.7) ** 2
    ) + 0.25 * np.eye(points)
    z = np.einsum("mab,mb->ma", np.linalg.cholesky(sigma), rng.normal(size=(experts, points)))[None]
    result = gp.fit_hyperparameters(np.log([[1.0, 2.0, 1.0]]), X, z, max_iterations=200)
    assert result.converged and not result.kept_start
    estimate = result.log_params[0]
    step = 1e-5
    hessian = np.zeros((3, 3))
    for j in range(3):
        shift = np.zeros(3)
        shift[j] = step
        plus = gp.log_marginal_likelihood((estimate + shift)[None], X, z)[1][0]
        minus = gp.log_marginal_likelihood((estimate - shift)[None], X, z)[1][0]
        hessian[:, j] = (plus - minus) / (2 * step)
    standard_errors = np.sqrt(np.diag(np.linalg.inv(-hessian)))
    assert np.all(np.abs(estimate - truth) <= 4 * standard_errors), (
        estimate,
        truth,
        standard_errors,
    )
    assert np.all(standard_errors < 0.2)  # the test has power: the errors are small


def test_fit_keeps_the_start_when_the_likelihood_breaks(monkeypatch):
    rng = np.random.default_rng(7)
    log_params, X, z, mask = random_problem(rng)

    def broken(*args, **kwargs):
        raise gp.NumericalError("forced")

    monkeypatch.setattr(gp, "log_marginal_likelihood", broken)
    result = gp.fit_hyperparameters(log_params, X, z, mask)
    assert np.all(result.kept_start) and not np.any(result.converged)
    assert result.message == "forced"
    np.testing.assert_array_equal(result.log_params, np.clip(log_params, *gp.default_bounds(2).T))
    assert not np.any(np.isnan(result.log_params))


def test_fit_stops_at_once_at_an_optimum():
    rng = np.random.default_rng(8)
    log_params, X, z, mask = random_problem(rng)
    first = gp.fit_hyperparameters(
        log_params, X, z, mask, max_iterations=500, gradient_tolerance=1e-6
    )
    second = gp.fit_hyperparameters(first.log_params, X, z, mask, gradient_tolerance=1e-3)
    assert second.message == "converged at the start" and second.n_evaluations == 1
    np.testing.assert_array_equal(second.log_params, first.log_params)


def test_full_gp_equals_scikit_learn():
    """The same data, kernel and hyperparameters in scikit-learn (ConstantKernel x ARD RBF +
    WhiteKernel, parameters in the same log order) give the same likelihood and gradient."""
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

    rng = np.random.default_rng(9)
    x = rng.uniform(size=(80, 2))
    z = 5 * x[:, 0] ** 2 + np.sin(12 * x[:, 1]) + 0.5 * rng.normal(size=80)
    kernel = ConstantKernel(2.0) * RBF([0.3, 0.2]) + WhiteKernel(0.3)
    model = GaussianProcessRegressor(kernel, alpha=0.0, optimizer=None).fit(x, z)
    theta = model.kernel_.theta
    expected_value, expected_gradient = model.log_marginal_likelihood(theta, eval_gradient=True)
    value, gradient = gp.log_marginal_likelihood(theta[None], x[None, None], z[None, None])
    assert value[0] == pytest.approx(expected_value, rel=1e-10)
    np.testing.assert_allclose(gradient[0], expected_gradient, rtol=1e-8)


def test_an_indefinite_problem_does_not_disturb_the_rest_of_the_batch():
    """Problem 0 has duplicate inputs and no noise (rescued by its own jitter), problem 1
    is well conditioned: its factorization equals the one computed alone, without jitter."""
    rng = np.random.default_rng(11)
    X = np.concatenate([np.zeros((1, 1, 4, 1)), rng.normal(size=(1, 1, 4, 1))])
    z = rng.normal(size=(2, 1, 4))
    log_params = np.array([[0.0, 0.0, -800.0], [0.0, 0.0, -1.0]])
    together = gp.factorize(log_params, gp.TrainingData.build(X, z))
    alone = gp.factorize(log_params[1:], gp.TrainingData.build(X[1:], z[1:]))
    assert together.jitter[0] > 0 and together.jitter[1] == 0 and not together.failed.any()
    np.testing.assert_array_equal(together.inverse[1], alone.inverse[0])
    np.testing.assert_array_equal(together.log_det[1], alone.log_det[0])


def test_a_problem_beyond_rescue_is_flagged_not_raised():
    X = np.zeros((2, 1, 3, 1))
    z = np.ones((2, 1, 3))
    log_params = np.array([[0.0, 0.0, 0.0], [np.nan, 0.0, 0.0]])  # NaN signal: no jitter helps
    fact = gp.factorize(log_params, gp.TrainingData.build(X, z))
    assert fact.failed.tolist() == [False, True] and np.all(np.isfinite(fact.alpha[0]))
    with pytest.raises(gp.NumericalError):
        fact.check()
    result = gp.fit_hyperparameters(log_params, X, z)
    assert result.kept_start.tolist() == [False, True]
    assert np.all(np.isfinite(result.log_params[0]))
