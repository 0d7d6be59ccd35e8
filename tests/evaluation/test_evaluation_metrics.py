"""Per-episode metrics on hand-built trajectories with known answers, and on real test episodes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from crowdnav.evaluation.metrics import (
    METRIC_COLUMNS,
    Trajectory,
    closest_distance,
    cumulative_social_force,
    episode_metrics,
    min_time_to_collision,
    motion_magnitudes,
    path_length,
    personal_space_compliance,
    spl,
    stl,
    straight_line_distance,
    surface_distances,
    time_to_collision,
    zone_shares,
)
from crowdnav.evaluation.rollout import HeldOutEpisodes


def test_path_length_sums_the_segment_lengths():
    assert path_length(np.array([0, 3, 3 + 4j])) == pytest.approx(7.0)
    assert path_length(np.array([1 + 1j])) == 0.0


def test_straight_line_distance_stops_at_the_goal_disc():
    assert straight_line_distance(0j, 3 + 4j, 0.3) == pytest.approx(4.7)
    assert straight_line_distance(0j, 0.1, 0.3) == 0.0


def test_spl_is_success_times_shortest_over_the_longer_of_path_and_shortest():
    assert spl(True, 6.0, 4.5) == pytest.approx(0.75)
    assert spl(True, 4.0, 4.5) == 1.0  # a path cannot be shorter than the shortest: capped at 1
    assert spl(False, 4.5, 4.5) == 0.0
    assert spl(True, 0.0, 0.0) == 1.0


def test_surface_distance_subtracts_both_radii_and_goes_negative_on_overlap():
    robot = np.array([0j, 0j])
    humans = np.array([[2 + 0j, 3j], [0.5 + 0j, -1j]])
    distances = surface_distances(robot, humans, 0.3, np.array([0.3, 0.2]))
    np.testing.assert_allclose(distances, [[1.4, 2.5], [-0.1, 0.5]])
    np.testing.assert_allclose(closest_distance(distances), [1.4, -0.1])
    assert np.isinf(closest_distance(np.zeros((3, 0)))).all()


def test_zone_shares_count_the_closest_human_per_step():
    closest = np.array([-0.1, 0.2, 0.45, 1.0, 1.2, 2.0, 3.6, 5.0, np.inf, 0.3])
    assert zone_shares(closest) == pytest.approx({"intimate_share": 0.3, "personal_share": 0.2, "social_share": 0.2})


def test_speed_acceleration_and_jerk_by_finite_differences_from_rest():
    # steps of 1, 2, 3 m in 0.5 s: speeds 2, 4, 6 m/s; from rest the accelerations are 4, 4, 4 m/s^2; jerk 0
    speed, acceleration, jerk = motion_magnitudes(np.array([0, 1, 3, 6], dtype=complex), 0.5)
    np.testing.assert_allclose(speed, [2, 4, 6])
    np.testing.assert_allclose(acceleration, [4, 4, 4])
    np.testing.assert_allclose(jerk, [0, 0])
    # a turn: +x at 1 m/s, then +y at 1 m/s (dt 1): |a| = |1j - 1| = sqrt 2; jerk |(1j - 1) - 1| = sqrt 5
    speed, acceleration, jerk = motion_magnitudes(np.array([0, 1, 1 + 1j]), 1.0)
    np.testing.assert_allclose(speed, [1, 1])
    np.testing.assert_allclose(acceleration, [1, math.sqrt(2)])
    np.testing.assert_allclose(jerk, [math.sqrt(5)])


def test_time_to_collision_of_head_on_offset_receding_and_touching_discs():
    offsets = np.array([5 + 0j, 5 + 0.5j, 5 + 0j, 0.5 + 0j, 5 + 0j, 3j])
    velocities = np.array([-1 + 0j, -1 + 0j, 1 + 0j, 1 + 0j, 0j, -1 + 0j])
    expected = [4.0, 5 - math.sqrt(0.75), math.inf, 0.0, math.inf, math.inf]
    np.testing.assert_allclose(time_to_collision(offsets, velocities, 1.0), expected)


def test_min_time_to_collision_along_a_trajectory_uses_each_step_velocity():
    # robot +x at 1 m/s from 0, human -x at 1 m/s from 10, radii 0.3: after step t they are 10 - 2t apart
    t = np.arange(4)
    positions = np.stack([t + 0j, 10 - t + 0j], axis=1)
    assert min_time_to_collision(positions, np.array([0.3, 0.3]), 1.0) == pytest.approx((10 - 2 * 3 - 0.6) / 2)
    assert min_time_to_collision(positions[:, :1], np.array([0.3]), 1.0) == math.inf


def test_cumulative_social_force_integrates_the_magnitude_over_time():
    assert cumulative_social_force(np.array([1.0, 2.0, 3.0]), 0.2) == pytest.approx(1.2)


def _straight_episode(success: bool = True) -> Trajectory:
    # the robot goes from 0 to 4 along x in 4 steps of 1 s; one human stands still at (2, 1.6), radii 0.3
    robot = np.arange(5, dtype=complex)
    human = np.full(5, 2 + 1.6j)
    return Trajectory(positions=np.stack([robot, human], axis=1), radii=np.array([0.3, 0.3]), goal=4.2 + 0j, goal_radius=0.3,
                      dt=1.0, social_force=np.array([0.1, 0.2, 0.2, 0.1]), max_speed=2.0)


def test_episode_metrics_of_a_straight_run_past_a_standing_human():
    metrics = episode_metrics(_straight_episode(), success=True)
    assert list(metrics) == list(METRIC_COLUMNS)
    # surface distances after each step: |(1,0)-(2,1.6)| - 0.6, ..., closest 1.6 - 0.6 = 1.0 at x = 2
    after = np.abs(np.arange(1, 5) - (2 + 1.6j)) - 0.6
    assert metrics["steps"] == 4 and metrics["time_to_goal"] == 4.0
    assert metrics["path_length"] == pytest.approx(4.0)
    assert metrics["straight_line_distance"] == pytest.approx(3.9)
    assert metrics["spl"] == pytest.approx(3.9 / 4.0)
    assert metrics["stl"] == pytest.approx((3.9 / 2.0) / 4.0)  # 3.9 m at 2 m/s against the 4 s it took
    assert metrics["min_human_distance"] == pytest.approx(1.0)
    assert metrics["psc"] == 1.0  # never closer than 1.0 m > 0.45 m
    assert metrics["personal_share"] == pytest.approx(np.mean((after >= 0.45) & (after < 1.2)))
    assert metrics["social_share"] == pytest.approx(np.mean((after >= 1.2) & (after < 3.6)))
    assert metrics["intimate_share"] == 0.0
    assert (metrics["mean_speed"], metrics["max_speed"]) == (1.0, 1.0)
    assert (metrics["mean_acceleration"], metrics["max_acceleration"]) == (0.25, 1.0)  # only the start accelerates
    assert (metrics["mean_jerk"], metrics["max_jerk"]) == (pytest.approx(1 / 3), 1.0)
    assert metrics["min_time_to_collision"] == math.inf  # passes 1.6 m from the human's centre, contact at 0.6
    assert metrics["social_force"] == pytest.approx(0.6)


def test_failed_episode_has_no_time_to_goal_and_zero_spl_and_stl():
    metrics = episode_metrics(_straight_episode(), success=False)
    assert math.isnan(metrics["time_to_goal"]) and metrics["spl"] == 0.0 and metrics["stl"] == 0.0


def test_stl_is_one_at_full_speed_on_the_straight_line_and_never_above_one():
    assert stl(True, duration=2.0, fastest=2.0) == 1.0 and stl(True, duration=4.0, fastest=2.0) == 0.5
    assert stl(True, duration=1.0, fastest=2.0) == 1.0  # faster than t* (a goal disc reached early) is capped
    assert stl(True, 0.0, 0.0) == 1.0 and stl(False, 2.0, 2.0) == 0.0


def test_personal_space_compliance_counts_steps_with_every_human_beyond_the_personal_space():
    closest = np.array([1.0, 0.44, 0.45, -0.1])
    assert personal_space_compliance(closest) == 0.5  # 0.44 and the overlap intrude, 0.45 does not
    assert personal_space_compliance(np.full(3, np.inf)) == 1.0 and personal_space_compliance(np.array([])) == 1.0


def _goal_seeking(batch):
    """Holonomic robot, polar goal (distance, sin, cos) in the robot frame: head for it, slowing at the end."""
    goal = batch["goal"]
    speed = np.minimum(1.0, goal[:, 0] / 0.2)  # max_speed 1 m/s, dt 0.2 s: do not overshoot
    return np.stack([goal[:, 2] * speed, goal[:, 1] * speed], axis=1)


def test_held_out_episodes_of_a_goal_seeking_policy_in_an_empty_world_succeed_with_spl_near_one():
    episodes = HeldOutEpisodes({"scenario": "open_space", "modalities": ["goal"], "overrides": {"humans.count": 0}}, [3, 4, 5])
    rows = episodes.run(_goal_seeking)
    again = episodes.run(_goal_seeking)
    episodes.close()
    assert [row["test_seed"] for row in rows] == [3, 4, 5]
    assert all(row["outcome"] == "success" and row["collision_kind"] == "" for row in rows)
    assert all(row["spl"] > 0.95 and row["spl"] <= 1.0 for row in rows)
    assert all(row["min_human_distance"] == math.inf and row["social_force"] == 0.0 for row in rows)
    assert all(row["max_speed"] <= 1.0 + 1e-9 for row in rows)
    assert rows == again  # same seeds, deterministic policy: the same episodes


def test_held_out_episodes_of_a_policy_fleeing_the_goal_end_out_of_bounds_with_zero_spl():
    episodes = HeldOutEpisodes({"scenario": "open_space", "modalities": ["goal"], "overrides": {"humans.count": 0}}, [3, 4])
    rows = episodes.run(lambda batch: -batch["goal"][:, [2, 1]])  # full speed away from the goal bearing (cos, sin)
    episodes.close()
    assert all(row["outcome"] == "out_of_bounds" and row["collision_kind"] == "" for row in rows)
    assert all(row["spl"] == 0.0 and math.isnan(row["time_to_goal"]) for row in rows)
    assert all(row["steps"] < 150 for row in rows)  # ended when it left the world, not at the time limit


def test_test_episodes_count_the_crowd_s_stalls_single_and_batched():
    """human_stalls: the episode's stalls (humans.stall), the same whether the episodes run one env each or as one batch."""
    from crowdnav.evaluation.rollout import HeldOutEpisodes

    from crowdnav.planning.scripted import StraightToGoal

    options = {"scenario": "open_space", "modalities": ["goal"], "overrides": {"humans.count": 8, "humans.stall.time": 1.0}}
    scripted = HeldOutEpisodes(options, [3, 4]).run(StraightToGoal(), privileged=True)
    assert all(row["human_stalls"] == int(row["human_stalls"]) for row in scripted) and sum(row["human_stalls"] for row in scripted) > 0
    still = HeldOutEpisodes(options, [3, 4])
    batched, single = still.run(lambda obs: np.zeros((len(obs["goal"]), 2))), still.run(lambda obs: np.zeros((len(obs["goal"]), 2)), batched=False)
    assert [row["human_stalls"] for row in batched] == [row["human_stalls"] for row in single]
    assert sum(row["human_stalls"] for row in batched) > 0
