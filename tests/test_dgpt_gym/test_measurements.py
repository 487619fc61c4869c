import numpy as np
import pytest
from conftest import z_tolerance
from scipy import stats

from dgpt_gym.measurements import simulate_scans, uniform_in_discs, zero_truncated_poisson
from dgpt_gym.network import SensorNetwork, probability_uncovered
from dgpt_gym.scenarios import SCENARIOS


def ztp_moments(rate):
    mean = rate / (1.0 - np.exp(-rate))
    return mean, mean * (1.0 + rate - mean)


@pytest.mark.parametrize("rate", [0.05, 1.0, 4.0])
def test_zero_truncated_poisson_law(rate):
    n = 200_000
    draws = zero_truncated_poisson(np.random.default_rng(1), rate, n)
    assert draws.min() >= 1
    mean, variance = ztp_moments(rate)
    assert abs(draws.mean() - mean) <= z_tolerance(np.sqrt(variance / n))
    # the probability mass of each of the first counts
    for k in range(1, 5):
        p = stats.poisson.pmf(k, rate) / (1.0 - np.exp(-rate))
        assert abs(np.mean(draws == k) - p) <= z_tolerance(np.sqrt(p * (1 - p) / n)) + 1e-12


def test_mean_target_count_for_lambda_1_is_1_582():
    assert ztp_moments(1.0)[0] == pytest.approx(1.58198, abs=1e-5)


@pytest.fixture(scope="module")
def many_scans():
    """Ten random S2 episodes with lambda_c = 3 and sigma_z = 2 on the default layout."""
    network = SensorNetwork.uniform(250, 1000.0, 50.0, layout_seed=0)
    rng = np.random.default_rng(2024)
    episodes = []
    for _ in range(10):
        positions = SCENARIOS["S2"].sample(rng).positions
        episodes.append((positions, simulate_scans(rng, network, positions, 2.0, 1.0, 3.0)))
    return network, episodes


def test_target_count_per_detecting_sensor(many_scans):
    _, episodes = many_scans
    n_target = sum(scans.is_target.sum() for _, scans in episodes)
    n_detecting = sum(scans.detecting.sum() for _, scans in episodes)
    mean, variance = ztp_moments(1.0)
    assert abs(n_target / n_detecting - mean) <= z_tolerance(np.sqrt(variance / n_detecting))


def test_clutter_count_per_producing_sensor(many_scans):
    _, episodes = many_scans
    n_clutter = sum((~scans.is_target).sum() for _, scans in episodes)
    n_producing = sum(scans.detecting.sum() for _, scans in episodes)
    assert abs(n_clutter / n_producing - 3.0) <= z_tolerance(np.sqrt(3.0 / n_producing))


def test_target_measurement_noise_has_std_sigma_z(many_scans):
    _, episodes = many_scans
    residuals = np.vstack(
        [
            scans.measurements[scans.is_target]
            - positions[
                np.repeat(np.arange(scans.n_steps), np.diff(scans.offsets))[scans.is_target]
            ]
            for positions, scans in episodes
        ]
    )
    n = residuals.shape[0]
    assert np.all(np.abs(residuals.mean(axis=0)) <= z_tolerance(2.0 / np.sqrt(n)))
    # the sample standard deviation has standard error sigma / sqrt(2 n)
    assert np.all(np.abs(residuals.std(axis=0) - 2.0) <= z_tolerance(2.0 / np.sqrt(2 * n)))


def test_clutter_is_uniform_in_the_sensing_disc(many_scans):
    network, episodes = many_scans
    radii = np.concatenate(
        [
            np.linalg.norm(
                scans.measurements[~scans.is_target]
                - network.positions[scans.sensor[~scans.is_target]],
                axis=1,
            )
            for _, scans in episodes
        ]
    )
    assert radii.max() <= 50.0
    # P(R <= r) = r^2 / R^2; a Kolmogorov-Smirnov test at the 0.1 % level, seed fixed
    assert stats.kstest(radii, lambda r: (r / 50.0) ** 2).pvalue > 1e-3


def test_uniform_in_discs_angles_are_uniform():
    points = uniform_in_discs(np.random.default_rng(3), np.zeros((50_000, 2)), 1.0)
    angles = np.arctan2(points[:, 1], points[:, 0])
    assert stats.kstest(angles, stats.uniform(-np.pi, 2 * np.pi).cdf).pvalue > 1e-3


def test_rows_are_grouped_by_step_and_sensor(many_scans):
    _, episodes = many_scans
    for _, scans in episodes:
        for step in range(scans.n_steps):
            sensors = scans.sensor[scans.rows(step)]
            assert np.all(np.diff(sensors) >= 0)
            assert set(sensors) <= set(np.flatnonzero(scans.detecting[step]))


def test_target_and_clutter_are_interleaved_within_a_sensor(many_scans):
    """Within a sensor's group the order is random: the first row is a target measurement
    with probability n_target / n_rows of that group."""
    _, episodes = many_scans
    first_is_target, expected = [], []
    for _, scans in episodes:
        for step in range(scans.n_steps):
            rows = scans.rows(step)
            sensors, truth = scans.sensor[rows], scans.is_target[rows]
            for sensor in np.unique(sensors):
                group = truth[sensors == sensor]
                if group.any() and not group.all():
                    first_is_target.append(group[0])
                    expected.append(group.mean())
    p = np.mean(expected)
    n = len(first_is_target)
    assert abs(np.mean(first_is_target) - p) <= z_tolerance(np.sqrt(p * (1 - p) / n))


def test_clutter_from_all_sensors():
    network = SensorNetwork.uniform(100, 1000.0, 50.0, layout_seed=3)
    positions = SCENARIOS["S1"].reference().positions
    scans = simulate_scans(np.random.default_rng(5), network, positions, 1.0, 1.0, 2.0, "all")
    n_clutter = (~scans.is_target).sum()
    n_pairs = 100 * scans.n_steps
    assert abs(n_clutter / n_pairs - 2.0) <= z_tolerance(np.sqrt(2.0 / n_pairs))
    assert len(np.unique(scans.sensor[~scans.is_target])) == 100


def test_no_clutter_when_rate_is_zero():
    network = SensorNetwork.uniform(250, 1000.0, 50.0, layout_seed=0)
    positions = SCENARIOS["S1"].reference().positions
    scans = simulate_scans(np.random.default_rng(5), network, positions, 1.0, 1.0, 0.0)
    assert scans.is_target.all()


def test_fraction_of_steps_without_detection_matches_geometry():
    """Over independent layouts, a step has no detecting sensor with probability
    (1 - pi r^2 / A^2)^n: the target is always at least r from the border."""
    rng = np.random.default_rng(11)
    fractions = []
    for layout_seed in range(200):
        network = SensorNetwork.uniform(250, 1000.0, 50.0, layout_seed=layout_seed)
        positions = SCENARIOS["S4"].sample(rng).positions
        fractions.append(np.mean(~network.in_range(positions).any(axis=1)))
    expected = probability_uncovered(250, 50.0, 1000.0)
    assert expected == pytest.approx(0.13928, abs=1e-5)
    standard_error = np.std(fractions, ddof=1) / np.sqrt(len(fractions))
    assert abs(np.mean(fractions) - expected) <= z_tolerance(standard_error)


def test_in_range_matches_brute_force():
    network = SensorNetwork.uniform(30, 200.0, 40.0, layout_seed=1)
    points = np.random.default_rng(0).uniform(0, 200, (50, 2))
    brute = np.array([[np.hypot(*(p - s)) <= 40.0 for s in network.positions] for p in points])
    np.testing.assert_array_equal(network.in_range(points), brute)


def test_max_sensors_in_range_bounds_every_point():
    network = SensorNetwork.uniform(250, 1000.0, 50.0, layout_seed=0)
    axis = np.arange(0.0, 1000.0, 5.0)
    grid = np.stack(np.meshgrid(axis, axis), -1).reshape(-1, 2)
    assert network.in_range(grid).sum(axis=1).max() <= network.max_sensors_in_range()


def test_uncovered_fraction_of_one_centred_sensor():
    network = SensorNetwork(np.array([[50.0, 50.0]]), 50.0, 100.0)
    # a disc of radius 50 in a 100 x 100 square leaves 1 - pi / 4 uncovered
    assert network.uncovered_fraction(0.0, 100.0, resolution=0.5) == pytest.approx(
        1 - np.pi / 4, abs=2e-3
    )
