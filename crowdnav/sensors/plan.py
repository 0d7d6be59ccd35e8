"""``plan``: the predictive planner's next move, computed from what the robot itself senses.

The move :class:`crowdnav.planning.predictive.PredictivePlanner` would make now, given the
humans the robot's tracker reports (the ``humans`` modality with the scenario's sensor settings:
its k nearest within range, never anyone else; ``reads_tracker``: with a ``sensors.tracker`` profile
the env hands it the tracks), the robot's pose in the map (localisation), its
own velocity (odometry) and its goal; the humans are predicted at constant velocity. It is the
base of a residual agent (env option ``residual``: the executed action is this plan plus the
policy's action; docs/agents.md#agents-that-anticipate-the-crowd) and a hint any policy may read.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

from crowdnav.planning.predictive import CrowdEstimate, PredictivePlanner, moves_to_actions
from crowdnav.sensors.base import Modality, register_modality
from crowdnav.sensors.humans import HumansModality

if TYPE_CHECKING:
    from crowdnav.batch.state import BatchState
    from crowdnav.sim.robot_view import RobotWorld
    from crowdnav.worlds.compiled import CompiledWorld


@register_modality
class PlanModality(Modality):
    """The planner's next move as a holonomic action: ``(vx, vy)`` in the robot frame over ``max_speed``, float32 in [-1, 1].

    Holonomic robots only (a ValueError names the kinematics otherwise). The planner's parameters
    are :class:`crowdnav.planning.predictive.PlannerSettings`' defaults. Scale: 1.
    """

    key = "plan"
    sees_robots = False  # it plans around the people its tracker reports
    reads_tracker = True

    def __init__(self, world: CompiledWorld, settings: None = None):
        super().__init__(world, settings)
        robot = world.scenario.robot
        if robot.kinematics != "holonomic":
            raise ValueError(f"modality 'plan' plans lattice moves for a holonomic robot; this robot is {robot.kinematics}")
        self.planner = PredictivePlanner()
        self.planner.check(world, float(world.scenario.time_step))  # a world too large for the planner's maps: one line now
        self.tracker = HumansModality(world, world.scenario.sensors.humans)
        self.dt, self.max_speed = float(world.scenario.time_step), float(robot.max_speed)

    def make_space(self) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)

    def observe(self, sim: RobotWorld) -> np.ndarray:
        rows = self.tracker.observe(sim)[None]
        actions = self._actions(np.array([sim.robot_position]), np.array([sim.robot_heading]), np.array([complex(sim.velocities[0])]),
                                np.array([sim.robot_goal]), rows)
        one: np.ndarray = actions[0]
        return one

    def observe_batch(self, state: BatchState) -> np.ndarray:
        rows = self.tracker.observe_batch(state)
        return self._actions(state.positions[:, 0], state.robot_heading, state.velocities[:, 0], state.robot_goal, rows)

    def _actions(self, robot: np.ndarray, heading: np.ndarray, velocity: np.ndarray, goal: np.ndarray, rows: np.ndarray) -> np.ndarray:
        crowd = CrowdEstimate.from_tracker(robot, heading, velocity, goal, rows)
        move = self.planner.plan(self.world, self.dt, crowd)
        return moves_to_actions(move, heading, self.max_speed * self.dt)
