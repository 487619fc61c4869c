import dataclasses
import warnings

import numpy as np
import pytest
from conftest import z_tolerance
from scipy import stats

from dgpt_gym.benchmark import metrics
from dgpt_gym.benchmark.episodes import EpisodeResult, add_floor_ratios, summarize_runs

TRUTH = np.array([[0.0, 10.0], [10.0, 10.0], [20.0, 30.0], [40.0, 50.0]])
ESTIMATE = TRUTH + np.array([[1.0, -2.0], [-1.0, 0.0], [3.0, 2.0], [-3.0, 0.0]])


def test_rmse_by_hand():
    # x errors 1, -1, 3, -3 -> mean square 5; y errors -2, 0, 2, 0 -> mean square 2
    np.testing.assert_allclose(metrics.rmse(ESTIMATE, TRUTH), [np.sqrt(5.0), np.sqrt(2.0)])


def test_nrmse_divides_by_the_range_of_the_true_coordinate():
    # ranges: x 40 - 0 = 40, y 50 - 10 = 40
    np.testing.assert_allclose(
        metrics.nrmse(ESTIMATE, TRUTH), [np.sqrt(5.0) / 40, np.sqrt(2.0) / 40]
    )


def test_nrmse_is_nan_along_an_axis_without_motion():
    truth = np.column_stack([np.arange(4.0), np.full(4, 7.0)])
    value = metrics.nrmse(truth + 1.0, truth)
    assert value[0] == pytest.approx(1.0 / 3.0) and np.isnan(value[1])


def test_coverage_counts_errors_within_the_half_width():
    half_width = np.array([[1.0, 1.0], [1.0, 1.0], [2.0, 2.0], [3.0, 0.5]])
    # x: |1|<=1, |-1|<=1, |3|>2, |-3|<=3 -> 3/4; y: |-2|>1, 0<=1, 2<=2, 0<=0.5 -> 3/4
    np.testing.assert_allclose(metrics.coverage(ESTIMATE, TRUTH, half_width), [0.75, 0.75])
    np.testing.assert_allclose(metrics.mean_width(half_width), [3.5, 2.25])


def test_std_over_runs_is_the_sample_std():
    per_run = np.array([[1.0, 2.0], [3.0, 2.0], [5.0, 2.0]])
    np.testing.assert_allclose(metrics.std_over_runs(per_run), [2.0, 0.0])
    np.testing.assert_array_equal(metrics.std_over_runs(per_run[:1]), [0.0, 0.0])


# -- 2-D and consistency metrics ---------------------------------------------------------

VAR = np.array([[1.0, 4.0], [1.0, 1.0], [4.0, 1.0], [9.0, 4.0]])
# errors (x, y): (1, -2), (-1, 0), (3, 2), (-3, 0)


def test_rmse_2d_by_hand():
    # squared distances 5, 1, 13, 9 -> mean 7
    assert metrics.rmse_2d(ESTIMATE, TRUTH) == pytest.approx(np.sqrt(7.0))


def test_nees_by_hand():
    # 1/1 + 4/4 = 2; 1/1 + 0 = 1; 9/4 + 4/1 = 6.25; 9/9 + 0 = 1
    np.testing.assert_allclose(metrics.nees(ESTIMATE, TRUTH, VAR), [2.0, 1.0, 6.25, 1.0])
    # a zero variance is floored, so the NEES is finite and huge, never inf or NaN
    value = metrics.nees(ESTIMATE[:1], TRUTH[:1], np.zeros((1, 2)))
    assert np.isfinite(value[0]) and value[0] > 1e12


def test_sigma_coverage_by_hand():
    # sigma x: 1, 1, 2, 3; |e_x|: 1, 1, 3, 3 -> within 1 sigma: yes, yes, no, yes -> 3/4
    # sigma y: 2, 1, 1, 2; |e_y|: 2, 0, 2, 0 -> within 1 sigma: yes, yes, no, yes -> 3/4
    np.testing.assert_allclose(metrics.sigma_coverage(ESTIMATE, TRUTH, VAR, 1), [0.75, 0.75])
    # within 2 sigma: every step on both axes (3 <= 4 and 2 <= 2)
    np.testing.assert_allclose(metrics.sigma_coverage(ESTIMATE, TRUTH, VAR, 2), [1.0, 1.0])


def test_nominal_values():
    assert metrics.NOMINAL_MEDIAN_NEES == pytest.approx(stats.chi2.median(2))
    for k, value in metrics.NOMINAL_COVERAGE.items():
        assert value == pytest.approx(stats.norm.cdf(k) - stats.norm.cdf(-k))


def test_consistency_of_gaussian_errors_with_the_stated_covariance():
    """Errors drawn with the stated variances give ANEES 2, median NEES 2 ln 2 and the
    nominal coverages, within 5 standard errors of each statistic at n = 20000; the same
    errors scored with 4x the variance give ANEES 0.5 (a wrong formula would not)."""
    rng = np.random.default_rng(7)
    n = 20000
    var = np.column_stack([rng.uniform(0.5, 3.0, n), rng.uniform(5.0, 20.0, n)])
    truth = rng.uniform(0.0, 1000.0, (n, 2))
    estimates = truth + rng.normal(size=(n, 2)) * np.sqrt(var)
    values = metrics.nees(estimates, truth, var)
    # NEES ~ chi2(2): variance 4, so the mean has standard error 2 / sqrt(n)
    assert abs(values.mean() - 2.0) < z_tolerance(2.0 / np.sqrt(n))
    # the sample median's asymptotic standard error is 1 / (2 f(m) sqrt(n)), f the chi2(2)
    # density at its median m (f(m) = 1/4)
    median = metrics.NOMINAL_MEDIAN_NEES
    median_se = 1.0 / (2.0 * stats.chi2.pdf(median, 2) * np.sqrt(n))
    assert abs(np.median(values) - median) < z_tolerance(median_se)
    for k, nominal in metrics.NOMINAL_COVERAGE.items():
        se = np.sqrt(nominal * (1.0 - nominal) / n)
        covered = metrics.sigma_coverage(estimates, truth, var, k)
        assert np.all(np.abs(covered - nominal) < z_tolerance(se)), (k, covered)
    inflated = metrics.nees(estimates, truth, 4.0 * var).mean()
    assert abs(inflated - 0.5) < z_tolerance(0.5 / np.sqrt(n))


def episode_with_error(errors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    truth = np.zeros((errors.size, 2))
    return truth + np.column_stack([errors, np.zeros(errors.size)]), truth


def test_track_loss_needs_ten_consecutive_steps_above_the_threshold():
    errors = np.full(50, 5.0)
    errors[3:12] = 150.0  # 9 steps: not a loss
    errors[20:30] = 150.0  # 10 steps: a loss, exactly these steps
    # 15 steps exactly at the threshold: long enough, but not above it, so not lost
    errors[35:50] = 100.0
    lost = metrics.track_loss(*episode_with_error(errors), threshold=100.0)
    expected = np.zeros(50, dtype=bool)
    expected[20:30] = True
    np.testing.assert_array_equal(lost, expected)
    # a run that lasts to the end of the episode counts too
    errors = np.full(15, 5.0)
    errors[5:] = 101.0
    np.testing.assert_array_equal(
        metrics.track_loss(*episode_with_error(errors), threshold=100.0), errors > 100.0
    )


def test_episode_metrics_split_detected_and_gap_steps():
    rng = np.random.default_rng(3)
    n = 12
    truth = rng.uniform(0.0, 100.0, (n, 2))
    mean = truth + rng.normal(0.0, 2.0, (n, 2))
    var = rng.uniform(1.0, 5.0, (n, 2))
    n_detecting = np.array([2, 0, 0, 3, 1, 1, 0, 2, 2, 1, 0, 4])
    result = EpisodeResult(
        truth=truth,
        mean=mean,
        var=var,
        ucb=np.full((n, 2), np.nan),
        step_time=np.full(n, 1e-4),
        n_measurements=n_detecting * 2,
        n_detecting=n_detecting,
        sensing_range=50.0,
    )
    values = result.metrics()
    for suffix, steps in (("_detected", n_detecting > 0), ("_gap", n_detecting == 0)):
        assert values["rmse_2d" + suffix] == pytest.approx(
            metrics.rmse_2d(mean[steps], truth[steps])
        )
        nees = metrics.nees(mean[steps], truth[steps], var[steps])
        assert values["anees" + suffix] == pytest.approx(nees.mean())
        assert values["nees_median" + suffix] == pytest.approx(np.median(nees))
        covered = metrics.sigma_coverage(mean[steps], truth[steps], var[steps], 2)
        assert values["coverage_2sigma_y" + suffix] == pytest.approx(covered[1])
    assert values["track_lost"] == 0.0 and values["no_detection_fraction"] == pytest.approx(4 / 12)
    # an episode without gap steps: the gap metrics are NaN (and no RuntimeWarning is raised,
    # which pytest would turn into an error)
    always = EpisodeResult(
        truth=truth,
        mean=mean,
        var=var,
        ucb=np.full((n, 2), np.nan),
        step_time=np.full(n, 1e-4),
        n_measurements=np.full(n, 2),
        n_detecting=np.ones(n, dtype=int),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gap_values = {key: value for key, value in always.metrics().items() if key.endswith("_gap")}
    assert len(gap_values) == 15 and all(np.isnan(value) for value in gap_values.values())


def test_episode_ucb_and_rmse_per_axis_on_detected_and_gap_steps():
    # x errors 1, 5, 3, 0.5 under half-widths 2, 2, 2, 2 and y errors 0, 1, 4, 2 under 3, 3,
    # 3, 1; the second step is a coverage gap
    errors = np.array([[1.0, 0.0], [5.0, 1.0], [3.0, 4.0], [0.5, 2.0]])
    truth = np.zeros((4, 2))
    ucb = np.array([[2.0, 3.0], [2.0, 3.0], [2.0, 3.0], [2.0, 1.0]])
    result = EpisodeResult(
        truth=truth,
        mean=truth + errors,
        var=np.ones((4, 2)),
        ucb=ucb,
        step_time=np.full(4, 1e-4),
        n_measurements=np.ones(4, dtype=int),
        n_detecting=np.array([1, 0, 2, 1]),
    )
    values = result.metrics()
    # detected steps 0, 2, 3: x covered where 1 <= 2 and 0.5 <= 2; y where 0 <= 3
    assert values["ucb_coverage_x_detected"] == pytest.approx(2 / 3)
    assert values["ucb_coverage_y_detected"] == pytest.approx(1 / 3)
    assert values["ucb_width_x_detected"] == pytest.approx(4.0)
    assert values["ucb_width_y_detected"] == pytest.approx(2 * (3 + 3 + 1) / 3)
    assert values["rmse_x_detected"] == pytest.approx(np.sqrt((1 + 9 + 0.25) / 3))
    assert values["rmse_y_detected"] == pytest.approx(np.sqrt((0 + 16 + 4) / 3))
    # the gap step: 5 > 2 on x, 1 <= 3 on y
    assert values["ucb_coverage_x_gap"] == 0.0 and values["ucb_coverage_y_gap"] == 1.0
    assert values["rmse_x_gap"] == pytest.approx(5.0)
    # over all steps the per-axis keys keep their names
    assert values["ucb_coverage_x"] == pytest.approx(2 / 4)
    assert "rmse_x_detected_detected" not in values
    # a tracker without a UCB: NaN on every subset
    no_ucb = dataclasses.replace(result, ucb=np.full((4, 2), np.nan))
    assert np.isnan(no_ucb.metrics()["ucb_coverage_x_detected"])
    assert np.isnan(no_ucb.metrics()["ucb_width_y_gap"])


def test_summarize_runs_intervals_and_floor_ratios():
    rows = [
        {
            "seed": s,
            "nrmse_x": x,
            "nrmse_y": 0.01,
            "rmse_x": 1.0,
            "rmse_y": 1.0,
            "rmse_2d": r,
            "track_lost": lost,
            "coverage_3sigma_x_detected": 0.97 + x,
            "ucb_coverage_y_detected": 0.99 - x,
        }
        for s, x, r, lost in ((0, 0.01, 2.0, 0.0), (1, 0.02, 4.0, 1.0), (2, 0.03, 9.0, 0.0))
    ]
    summary = summarize_runs(rows)
    # three runs, so 2 degrees of freedom: t(0.975, 2) = 4.3027
    quantile = stats.t.ppf(0.975, 2)
    # nrmse_x (0.01, 0.02, 0.03): mean 0.02, squared deviations 1e-4 + 0 + 1e-4, / 2 -> std 0.01
    assert summary["nrmse_x_ci95"] == pytest.approx(quantile * 0.01 / np.sqrt(3), rel=1e-9)
    # rmse_2d (2, 4, 9): mean 5, squared deviations 9 + 1 + 16 = 26, / 2 -> std sqrt(13)
    assert summary["rmse_2d_ci95"] == pytest.approx(quantile * np.sqrt(13 / 3), rel=1e-9)
    assert summary["nrmse_y_ci95"] == pytest.approx(0.0, abs=1e-15)
    # the coverage on detected steps has nrmse_x's spread; y's coverage was not reported
    assert summary["coverage_3sigma_x_detected_ci95"] == pytest.approx(
        quantile * 0.01 / np.sqrt(3), rel=1e-9
    )
    assert "coverage_3sigma_y_detected_ci95" not in summary
    # and so has the UCB's coverage on detected steps (its interval is the calibration
    # table's "surely below")
    assert summary["ucb_coverage_y_detected_ci95"] == pytest.approx(
        quantile * 0.01 / np.sqrt(3), rel=1e-9
    )
    assert summary["track_loss_rate"] == pytest.approx(1 / 3) and summary["n_runs"] == 3
    # one run has no spread to estimate: the interval is NaN
    assert np.isnan(summarize_runs(rows[:1])["nrmse_x_ci95"])
    cells = [
        {
            "tracker": "clairvoyant",
            "scenario": "S1",
            "noise_std": 1.0,
            "clutter_rate": 1.0,
            "rmse_2d": 2.0,
        },
        {"tracker": "pda", "scenario": "S1", "noise_std": 1.0, "clutter_rate": 1.0, "rmse_2d": 5.0},
        {"tracker": "pda", "scenario": "S2", "noise_std": 1.0, "clutter_rate": 1.0, "rmse_2d": 5.0},
    ]
    ratios = [row["rmse_ratio_to_floor"] for row in add_floor_ratios(cells)]
    assert ratios[:2] == [1.0, 2.5] and np.isnan(ratios[2])
