import numpy as np
import pytest

from dgpt_gym import metrics

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
