import dataclasses

import numpy as np
import pytest

from dgpt_gym.scenarios import SCENARIOS, CoordinatedTurnScenario, SingerScenario, get_scenario

N_RANDOM = 60


def trajectories(name):
    """The reference trajectory and N_RANDOM random draws of a scenario."""
    scenario = SCENARIOS[name]
    rng = np.random.default_rng(7)
    return [scenario.reference()] + [scenario.sample(rng) for _ in range(N_RANDOM)]


def turn_runs(rates, tol=1e-9):
    """(rate, length) of each maximal run of equal non-zero turn rates."""
    runs, start = [], None
    for k, rate in enumerate(np.r_[rates, 0.0]):
        if start is not None and abs(rate - rates[start]) > tol:
            runs.append((rates[start], k - start))
            start = None
        if start is None and abs(rate) > tol and k < len(rates):
            start = k
    return runs


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_stays_inside_area_and_lasts_100_to_200_steps(name):
    for trajectory in trajectories(name):
        assert 100 <= trajectory.n_steps <= 200
        assert trajectory.positions.min() >= 50.0 and trajectory.positions.max() <= 950.0
        speed = np.linalg.norm(trajectory.velocities, axis=1)
        assert speed.min() >= 10.0 - 1e-9 and speed.max() <= 25.0 + 1e-9


@pytest.mark.parametrize("name, rate_deg, duration", [("S2", 20.0, 10), ("S3", 30.0, 9)])
def test_coordinated_turn_rates_and_durations(name, rate_deg, duration):
    for trajectory in trajectories(name):
        runs = turn_runs(trajectory.turn_rates())
        assert runs, "a coordinated-turn trajectory without turns"
        rates = np.array([rate for rate, _ in runs])
        np.testing.assert_allclose(np.abs(np.rad2deg(rates)), rate_deg, rtol=1e-9)
        lengths = [length for _, length in runs]
        # every turn lasts the full duration except possibly one cut by the episode's end
        assert all(length == duration for length in lengths[:-1])
        assert lengths[-1] <= duration
        if len(runs) >= 2:
            assert rates.min() < 0 < rates.max(), "turns go both left and right"


def test_coordinated_turn_positions_follow_the_velocity():
    # Exact arc integration: the chord of each step equals the integral of the velocity.
    trajectory = SCENARIOS["S3"].reference()
    rates = trajectory.turn_rates()
    speed = np.linalg.norm(trajectory.velocities[0])
    chord = np.linalg.norm(np.diff(trajectory.positions, axis=0), axis=1)
    expected = np.where(
        rates == 0, speed, 2 * speed / np.maximum(np.abs(rates), 1e-300) * np.sin(np.abs(rates) / 2)
    )
    np.testing.assert_allclose(chord, expected, rtol=1e-9)


def test_singer_accelerations_stay_within_the_bound():
    bound = SCENARIOS["S4"].max_acceleration
    largest = 0.0
    for trajectory in trajectories("S4"):
        acceleration = np.linalg.norm(trajectory.accelerations(), axis=1)
        largest = max(largest, acceleration.max())
        assert acceleration.max() <= bound + 1e-9
    assert largest > 5.0, "the Singer target should manoeuvre"


def test_singer_variance_is_singers_formula():
    scenario = SingerScenario(
        max_acceleration=30.0, prob_no_acceleration=0.2, prob_max_acceleration=0.1
    )
    # sigma_m^2 = A^2 / 3 (1 + 4 P_max - P_0) = 900 / 3 * 1.2 = 360
    assert scenario.acceleration_std == pytest.approx(np.sqrt(360.0))


def test_nearly_constant_velocity_has_abrupt_changes_at_waypoints():
    for trajectory in trajectories("S1"):
        heading_change = np.abs(np.rad2deg(trajectory.turn_rates()))
        abrupt = heading_change > 45.0
        assert abrupt.sum() >= 3
        # between waypoints the heading barely changes (NCV noise only)
        assert np.median(heading_change[~abrupt]) < 2.0


def test_reference_is_the_draw_from_the_reference_seed():
    for scenario in SCENARIOS.values():
        again = scenario.sample(np.random.default_rng(scenario.reference_seed))
        np.testing.assert_array_equal(scenario.reference().positions, again.positions)


def test_random_draws_differ_and_repeat_with_the_seed():
    scenario = SCENARIOS["S2"]
    first = scenario.sample(np.random.default_rng(1)).positions
    assert not np.array_equal(first, scenario.sample(np.random.default_rng(2)).positions)
    np.testing.assert_array_equal(first, scenario.sample(np.random.default_rng(1)).positions)


def test_unknown_scenario_names_the_choices():
    with pytest.raises(ValueError, match=r"scenario must be one of \['S1', 'S2', 'S3', 'S4'\]"):
        get_scenario("S5")


def test_impossible_scenario_raises_instead_of_looping():
    too_long = dataclasses.replace(CoordinatedTurnScenario(), area=120.0, max_attempts=5)
    with pytest.raises(RuntimeError, match="no trajectory fitted"):
        too_long.sample(np.random.default_rng(0))


def test_the_usage_guide_quotes_the_current_scenario_parameters():
    from pathlib import Path

    from dgpt_gym.scenarios import scenario_table_markdown

    guide = (Path(__file__).resolve().parents[2] / "docs" / "usage.md").read_text()
    assert scenario_table_markdown() in guide
