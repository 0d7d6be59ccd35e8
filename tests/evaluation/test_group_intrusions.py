"""group_intrusions: steps in which the robot cuts between two members of a walking group (hand-built and recorded episodes)."""

from __future__ import annotations

import numpy as np
from crowdnav.evaluation.metrics import Trajectory, episode_metrics, group_intrusions
from crowdnav.evaluation.rollout import HeldOutEpisodes


def _walk_between(gap: float, offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The robot walks along y = offset from x = -3 to 3 (1 m per step); a couple stands at (0, +-gap/2), a stranger at (0, -5)."""
    robot = np.arange(-3.0, 4.0) + 1j * offset
    humans = np.tile([0.5j * gap, -0.5j * gap, -5j], (len(robot), 1))
    return robot, humans


def test_the_robot_walking_between_a_couple_counts_the_steps_its_body_crosses_the_line_between_them():
    robot, humans = _walk_between(1.6)
    couple = np.array([0, 0, -1])
    # only the step at x = 0 puts the robot (radius 0.3) on the segment from (0, 0.8) to (0, -0.8)
    assert group_intrusions(robot, humans, couple, robot_radius=0.3) == 1
    # a wider robot (radius 1.2) touches the segment from x = -1 to x = 1: three steps
    assert group_intrusions(robot, humans, couple, robot_radius=1.2) == 3


def test_no_intrusion_past_a_group_beside_it_between_strangers_or_between_members_over_two_metres_apart():
    robot, humans = _walk_between(1.6, offset=1.0)  # passes 0.2 m beyond the upper member's centre: not between them
    assert group_intrusions(robot, humans, np.array([0, 0, -1]), robot_radius=0.3) == 0
    robot, humans = _walk_between(1.6)
    assert group_intrusions(robot, humans, np.array([-1, -1, -1]), robot_radius=0.3) == 0  # strangers: no group
    assert group_intrusions(robot, humans, np.array([0, 1, -1]), robot_radius=0.3) == 0  # two different groups
    assert group_intrusions(robot, humans, None, robot_radius=0.3) == 0
    robot, humans = _walk_between(2.2)  # members 2.2 m apart: not linked, the robot may pass between them
    assert group_intrusions(robot, humans, np.array([0, 0, -1]), robot_radius=0.3) == 0


def test_episode_metrics_report_group_intrusions_from_the_states_after_each_step():
    robot, humans = _walk_between(1.6)
    positions = np.concatenate([robot[:, None], humans], axis=1)
    trajectory = Trajectory(positions=positions, radii=np.full(4, 0.3), goal=3.0, goal_radius=0.3, dt=1.0,
                            social_force=np.zeros(len(robot) - 1), max_speed=1.0, walking_group=np.array([0, 0, -1]))
    assert episode_metrics(trajectory, success=True)["group_intrusions"] == 1
    start_inside = Trajectory(positions=positions[3:], radii=np.full(4, 0.3), goal=3.0, goal_radius=0.3, dt=1.0,
                              social_force=np.zeros(3), max_speed=1.0, walking_group=np.array([0, 0, -1]))
    assert episode_metrics(start_inside, success=True)["group_intrusions"] == 0  # the state after reset is not a step


def test_test_episodes_of_a_scenario_with_walking_groups_report_intrusions_and_others_zero():
    walking = HeldOutEpisodes({"scenario": "station_hall", "modalities": ["goal"],
                               "overrides": {"humans.groups.1.walk_together": True}}, [0, 1])
    rows = walking.run(lambda sim: np.array([1.0, 0.0]), privileged=True)
    assert all(isinstance(row["group_intrusions"], int) and row["group_intrusions"] >= 0 for row in rows)
    plain = HeldOutEpisodes({"scenario": "open_space", "modalities": ["goal"]}, [0]).run(lambda sim: np.zeros(2), privileged=True)
    assert plain[0]["group_intrusions"] == 0
