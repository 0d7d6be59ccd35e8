"""``goal``: where the robot's goal is, seen from the robot."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

from crowdnav.batch.scalar_math import F, cmul
from crowdnav.scenario.schema import GoalSensor
from crowdnav.sensors.base import Modality, register_modality
from crowdnav.sensors.frames import encode_vector, encode_vectors, to_robot_frame, to_robot_frame_batch, vector_space

if TYPE_CHECKING:
    from crowdnav.batch.state import BatchState
    from crowdnav.sim.robot_view import RobotWorld
    from crowdnav.worlds.compiled import CompiledWorld

GOAL_RANGE_FACTOR = 2.0
"""Goal distances are clipped to this many world diagonals (reached only far outside an open world)."""


@register_modality
class GoalModality(Modality):
    """Relative goal in the robot frame: polar ``(distance, sin, cos)`` or cartesian ``(x, y)``.

    The distance (cartesian: the vector's length) is clipped to ``2 x`` the world's diagonal, so
    the observation stays in its space even after the robot leaves an open world. Its scale
    (:meth:`scale`) is one diagonal, the largest distance inside the world.
    """

    key = "goal"
    settings_type = GoalSensor

    def __init__(self, world: CompiledWorld, settings: GoalSensor | None = None):
        super().__init__(world, settings)
        self.diagonal = float(world.scenario.world_diagonal)
        self.bound = GOAL_RANGE_FACTOR * self.diagonal
        self.frame = self.settings.frame

    def make_space(self) -> spaces.Box:
        return vector_space(self.frame, self.bound)

    def scale(self) -> tuple[np.ndarray, np.ndarray]:
        """Metres scaled by the world's diagonal (not the 2x clip bound): polar ``(d, 1, 1)``, cartesian ``(d, d)``."""
        shape = self.space().shape
        scale = np.array((self.diagonal, 1.0, 1.0) if self.frame == "polar" else (self.diagonal, self.diagonal), dtype=np.float32)
        return np.zeros(shape, dtype=np.float32), scale

    def observe(self, sim: RobotWorld) -> np.ndarray:
        rotation, robot = to_robot_frame(sim), complex(sim.positions[0])
        re, im = goal_in_robot_frame(sim.robot_goal.real, sim.robot_goal.imag, robot.real, robot.imag, rotation.real, rotation.imag)
        return encode_vector(complex(re, im), self.frame, self.bound)

    def observe_batch(self, state: BatchState) -> np.ndarray:
        robot = state.positions[:, 0]
        relative = goal_in_robot_frame(state.robot_goal.real, state.robot_goal.imag, robot.real, robot.imag, *to_robot_frame_batch(state))
        return encode_vectors(*relative, self.frame, self.bound)


def goal_in_robot_frame(goal_re: F, goal_im: F, robot_re: F, robot_im: F, rotation_re: F, rotation_im: F) -> tuple[F, F]:
    """The kernel: ``(goal - robot) * to_robot_frame`` as (re, im), for Python floats (one world) or (K,) arrays.

    Python's complex product, written as separately rounded real operations, so both give the same bits.
    """
    return cmul(goal_re - robot_re, goal_im - robot_im, rotation_re, rotation_im)
