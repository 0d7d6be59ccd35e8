"""An empty place of a recorded crowd (``humans.model: replay``, parked far outside the world) is nobody: no metric, mean or
exported trajectory measures it. The recording is written by the test (no data ships)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from crowdnav.evaluation.leaderboard import met_mean
from crowdnav.evaluation.metrics import Trajectory, episode_metrics, min_time_to_collision
from crowdnav.evaluation.rollout import HeldOutEpisodes
from crowdnav.evaluation.trajectories import tidy_table, trajnet_lines

from crowdnav.crowd.replay import PARKING, empty_places, parked

ROBOT_RADIUS = HUMAN_RADIUS = 0.3


def _trajectory(humans: np.ndarray, robot: np.ndarray | None = None, walking_group: np.ndarray | None = None) -> Trajectory:
    """A robot standing at the origin (unless ``robot`` is given) among ``humans`` (T + 1, n)."""
    steps, n = humans.shape
    robot = np.zeros(steps, dtype=complex) if robot is None else robot
    return Trajectory(positions=np.column_stack([robot, humans]), radii=np.full(n + 1, ROBOT_RADIUS), goal=5 + 0j,
                      goal_radius=0.3, dt=0.2, social_force=np.zeros(steps - 1), max_speed=1.0, walking_group=walking_group)


def test_min_human_distance_is_the_distance_to_the_people_present_only():
    spots = parked(2)
    humans = np.array([[spots[0], 3 + 0j], [spots[0], 3 + 0j], [2 + 0j, 3 + 0j], [spots[0], 4 + 0j]])  # place 0: someone at step 2
    metrics = episode_metrics(_trajectory(humans), success=False)
    assert metrics["min_human_distance"] == pytest.approx(2 - ROBOT_RADIUS - HUMAN_RADIUS)  # not the parking place's 28,284 km
    assert metrics["social_share"] == 1.0 and metrics["psc"] == 1.0


def test_nobody_present_reads_inf_no_zone_full_compliance_and_no_intrusion():
    humans = np.tile(parked(3), (6, 1))
    metrics = episode_metrics(_trajectory(humans, walking_group=np.array([0, 0, 0])), success=False)
    assert metrics["min_human_distance"] == math.inf
    assert metrics["min_time_to_collision"] == math.inf
    assert (metrics["intimate_share"], metrics["personal_share"], metrics["social_share"], metrics["psc"]) == (0.0, 0.0, 0.0, 1.0)
    assert metrics["group_intrusions"] == 0


def test_a_person_entering_a_place_has_no_time_to_collision_from_the_parking_place():
    appears = 1 + 1j  # from PARKING toward the origin: the jump "moves" straight at the robot
    humans = np.array([[PARKING], [appears], [appears + 0.2]])
    trajectory = _trajectory(humans)
    assert min_time_to_collision(trajectory.positions, trajectory.radii, 0.2) < 1e-3  # the jump, counted as a velocity
    assert episode_metrics(trajectory, success=False)["min_time_to_collision"] == math.inf  # walking away from the robot


def test_the_leaderboard_mean_of_min_human_distance_is_over_the_episodes_that_met_someone():
    assert met_mean(np.array([1.0, math.inf, 3.0])) == 2.0
    assert met_mean(np.array([math.inf, math.inf])) == math.inf
    assert math.isnan(met_mean(np.array([])))


def _write(path) -> None:
    """Two people at 2.5 Hz, 0-10 s and 50-60 s (frame id x y): windows of 6 s in between hold nobody."""
    rows = []
    for person, (t0, t1, a, b) in {1: (0.0, 10.0, -4 - 1j, 4 - 1j), 2: (50.0, 60.0, 4 + 1j, -4 + 1j)}.items():
        for k in range(round(t0 / 0.4), round(t1 / 0.4) + 1):
            where = a + (b - a) * (k * 0.4 - t0) / (t1 - t0)
            rows.append((k * 10, person, where.real, where.imag))
    path.write_text("".join(f"{f}\t{p}\t{x:.4f}\t{y:.4f}\n" for f, p, x, y in sorted(rows)))


def test_replayed_episodes_measure_and_export_only_the_people_present(tmp_path):
    _write(tmp_path / "walk.txt")
    overrides = {"humans.model": "replay", "humans.count": 1, "humans.replay": {"file": str(tmp_path / "walk.txt")}, "max_steps": 30}
    held = HeldOutEpisodes({"scenario": "open_space", "modalities": ["goal"], "overrides": overrides}, list(range(12)))
    try:
        episodes = held.run(lambda sim: np.zeros(2), privileged=True, record=True)
    finally:
        held.close()
    distance = np.array([episode["min_human_distance"] for episode in episodes])
    met = np.isfinite(distance)
    assert met.any() and (~met).any()  # windows with and without a person
    assert (distance == math.inf)[~met].all() and (np.abs(distance[met]) < 20).all()  # the world is 10 m wide
    assert all(episode["social_force"] == 0.0 for episode, seen in zip(episodes, met, strict=True) if not seen)
    for episode, seen in zip(episodes, met, strict=True):  # someone present in the frames exactly when the metric met them
        present = ~empty_places(episode["frames"]["positions"][1:, 1:])
        assert present.any() == seen
    table = tidy_table(episodes)
    assert set(table["agent"]) <= {"robot", "human_0"} and (table[["x", "y"]].abs() < 20).all().all()
    tracks = [json.loads(line)["track"] for line in trajnet_lines(episodes) if '"track"' in line]
    assert tracks and all(abs(track["x"]) < 20 and abs(track["y"]) < 20 for track in tracks)
