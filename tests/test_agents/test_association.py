"""The joint association: target probabilities of a step's measurements
(:func:`agents.gating.target_probabilities`) and the state-space tracker that weighs each
sensor's measurements by them."""

import numpy as np
import pytest
from conftest import measurement_obs, problem_spec
from scipy.stats import multivariate_normal

from agents.gating import target_probabilities
from agents.state_space_dgpt import StateSpaceDGPT
from dgpt_gym.measurements import simulate_scans
from dgpt_gym.network import SensorNetwork


def _subset_weight(points, mean, var, noise_var, scale):
    """(lambda_T / c)^k times the joint density of k target points that share s ~ N(mean,
    diag(var)): per axis a, the points are jointly Gaussian with covariance
    var[a] 1 1^T + noise_var I."""
    k = points.shape[0]
    var = np.broadcast_to(var, (2,))
    return scale**k * np.prod(
        [
            multivariate_normal(
                np.full(k, mean[a]), var[a] * np.ones((k, k)) + noise_var * np.eye(k)
            ).pdf(points[:, a])
            for a in range(2)
        ]
    )


def test_two_points_by_hand_from_the_subset_weights():
    """Two measurements: the subsets {1}, {2}, {1, 2} have weights w_1, w_2, w_12 (the
    other point clutter of density c); anchors reach {1, 2} twice, so P(1) = (w_1 + 2 w_12)
    / (w_1 + w_2 + 2 w_12), the docstring's formula, from scipy's densities."""
    points = np.array([[3.0, -1.0], [4.5, 0.5]])
    mean, var, noise_var = np.array([2.0, 0.0]), 9.0, 1.0
    detection_rate, clutter_density = 1.3, 0.004
    scale = detection_rate / clutter_density
    w1 = _subset_weight(points[:1], mean, var, noise_var, scale)
    w2 = _subset_weight(points[1:], mean, var, noise_var, scale)
    w12 = _subset_weight(points, mean, var, noise_var, scale)
    expected = np.array([w1 + 2 * w12, w2 + 2 * w12]) / (w1 + w2 + 2 * w12)
    probabilities = target_probabilities(
        points, mean, np.full(2, var), noise_var, detection_rate, clutter_density
    )
    np.testing.assert_allclose(probabilities, expected, rtol=1e-10)
    # far apart, one of them is clutter: the two probabilities sum to about 1
    far = np.array([[3.0, -1.0], [40.0, 30.0]])
    split = target_probabilities(far, mean, np.full(2, var), noise_var, 1.0, 0.004)
    assert split[0] > 0.999 and split[1] < 1e-6


def test_three_points_by_hand_from_the_subset_weights():
    """Three measurements and unequal axis variances: anchor a reaches the subsets that
    contain z_a through e_a prod_(i != a) (1 + rho_ai) with e_a = w_a and rho_ai = w_ai / w_a,
    so its weight is w_a (1 + w_ab / w_a) (1 + w_ac / w_a), and beta_ai = w_ai / (w_a + w_ai);
    P(i) = sum_a W_a (1 if a = i else beta_ai) / sum_a W_a, from scipy's densities."""
    points = np.array([[3.0, -1.0], [4.5, 0.5], [1.0, 2.5]])
    mean, var, noise_var = np.array([2.0, 0.0]), np.array([9.0, 4.0]), 1.5
    scale = 0.8 / 0.002
    single = [_subset_weight(points[[a]], mean, var, noise_var, scale) for a in range(3)]
    pair = {
        (a, i): _subset_weight(points[[a, i]], mean, var, noise_var, scale)
        for a in range(3)
        for i in range(3)
        if a != i
    }
    anchor, beta = np.zeros(3), np.eye(3)
    for a in range(3):
        others = [i for i in range(3) if i != a]
        anchor[a] = single[a] * np.prod([1.0 + pair[a, i] / single[a] for i in others])
        for i in others:
            beta[a, i] = pair[a, i] / (single[a] + pair[a, i])
    expected = anchor @ beta / anchor.sum()
    probabilities = target_probabilities(points, mean, var, noise_var, 0.8, 0.002)
    np.testing.assert_allclose(probabilities, expected, rtol=1e-10)
    assert target_probabilities(np.empty((0, 2)), mean, var, noise_var, 0.8, 0.002).shape == (0,)


def test_without_clutter_every_point_is_the_targets():
    points = np.random.default_rng(0).normal(0.0, 20.0, (6, 2))
    np.testing.assert_array_equal(
        target_probabilities(points, np.zeros(2), np.full(2, 4.0), 1.0, 1.0, 0.0), np.ones(6)
    )


def test_a_cluster_of_several_sensors_outweighs_a_point_nearer_the_prediction():
    """A wide prediction (standard deviation 30 m) at the origin: a lone point 3 m from it
    and four points 25 m away within 1 m of each other. The lone point is nearer, but the
    cluster is where the target's points of different sensors agree (measured: 2.8e-7
    against 0.992-0.994)."""
    lone = np.array([[3.0, 0.0]])
    cluster = np.array([25.0, 5.0]) + np.array([[0.3, 0.2], [-0.5, 0.1], [0.2, -0.6], [0.0, 0.4]])
    probabilities = target_probabilities(
        np.vstack([lone, cluster]), np.zeros(2), np.full(2, 900.0), 1.0, 1.0, 5.0 / 7854.0
    )
    assert probabilities[0] < 1e-5
    assert np.all(probabilities[1:] > 0.98)


def test_target_probabilities_on_simulated_scans():
    """Scans of the paper's model (clutter 5 per detecting sensor, sigma_z = 1, 250 sensors)
    around a prediction 10 m off on average. The sum of the probabilities is the expected
    number of target points; the anchors' double count of clustered points makes it at least
    the number drawn, by at most 3 standard deviations sqrt(sum p (1 - p)) on these 300 scans
    (seed 1: 966.7 against 951, 2.5 standard deviations; a clutter density off by a factor 2
    either way, or 10, falls outside). The points with probability >= 0.95 or < 0.05 are the
    target's as often as their mean probability says, within 3 binomial standard errors."""
    rng = np.random.default_rng(1)
    network = SensorNetwork.uniform(250, 1000.0, 50.0, layout_seed=0)
    probabilities, is_target = [], []
    for _ in range(300):
        position = rng.uniform(100.0, 900.0, (1, 2))
        scans = simulate_scans(rng, network, position, 1.0, 1.0, 5.0)
        rows = scans.rows(0)
        if rows.stop == rows.start:
            continue
        prediction = position[0] + rng.normal(0.0, 10.0, 2)
        probabilities.append(
            target_probabilities(
                scans.measurements[rows], prediction, np.full(2, 100.0), 1.0, 1.0, 5.0 / 7854.0
            )
        )
        is_target.append(scans.is_target[rows])
    p, target = np.concatenate(probabilities), np.concatenate(is_target)
    excess = p.sum() - target.sum()
    assert 0.0 <= excess < 3.0 * np.sqrt(np.sum(p * (1.0 - p)))
    for selected in (p >= 0.95, p < 0.05):
        mean = p[selected].mean()
        error = 3.0 * np.sqrt(max(mean * (1.0 - mean), 1e-4) / selected.sum())
        assert abs(target[selected].mean() - mean) < error


@pytest.mark.parametrize("association", ["joint", "local"])
def test_joint_association_takes_the_point_the_other_sensors_confirm(association):
    """A track at (10, 10) moving at (1, 0) m/s, then a step on which the target has jumped
    to (19, 10): sensor 0 reports a clutter point at the predicted (11, 10) and the
    target's point; sensors 1 and 2 report only the target's. Eq. (27) weighs sensor 0's
    points by the prediction alone and puts about half the weight on the clutter, 8 m
    off (at least a quarter: the summary more than 2 m from the target); the joint
    association follows sensors 1 and 2 to the target's point (within 1 m)."""
    spec = problem_spec(sensor_positions=((10.0, 10.0), (30.0, 10.0), (10.0, 30.0)))
    rng = np.random.default_rng(4)
    tracker = StateSpaceDGPT(aggregation="rbcm", association=association)
    tracker.reset(spec)
    for t in range(8):
        truth = np.array([3.0 + t, 10.0])
        tracker.update(measurement_obs(t, truth + rng.normal(0.0, 0.3, (3, 2)), [0, 1, 2]))
    target = np.array([19.0, 10.0])
    points = np.vstack([[11.0, 10.0], target + rng.normal(0.0, 0.3, (3, 2))])
    tracker.update(measurement_obs(8, points, [0, 0, 1, 2]))
    sensor_zero_summary = tracker.steps_[-1].summaries[:, 0]
    distance = np.linalg.norm(sensor_zero_summary - target)
    if association == "joint":
        assert distance < 1.0
    else:
        assert distance > 2.0
