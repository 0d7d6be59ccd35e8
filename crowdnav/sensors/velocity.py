"""``velocity``: the robot's own velocity, as odometry would report it."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

from crowdnav.batch.scalar_math import cmul
from crowdnav.sensors.base import Modality, register_modality
from crowdnav.sensors.frames import encode_vector, encode_vectors, to_robot_frame, to_robot_frame_batch, vector_space

if TYPE_CHECKING:
    from crowdnav.batch.state import BatchState
    from crowdnav.sim.robot_view import RobotWorld
    from crowdnav.worlds.compiled import CompiledWorld


@register_modality
class VelocityModality(Modality):
    """Velocity over the last step in the robot frame, ``(vx, vy)`` in m/s, float32.

    Bounded by the robot's ``max_speed`` (the vector is scaled down if longer, which the
    kinematics never produce). Zero right after reset. Scale: the Box default, ``max_speed``.
    """

    key = "velocity"

    def __init__(self, world: CompiledWorld, settings: None = None):
        super().__init__(world, settings)
        self.bound = float(world.scenario.robot.max_speed)

    def make_space(self) -> spaces.Box:
        return vector_space("cartesian", self.bound)

    def observe(self, sim: RobotWorld) -> np.ndarray:
        rotation, robot = to_robot_frame(sim), complex(sim.velocities[0])
        return encode_vector(complex(*cmul(robot.real, robot.imag, rotation.real, rotation.imag)), "cartesian", self.bound)

    def observe_batch(self, state: BatchState) -> np.ndarray:
        robot = state.velocities[:, 0]
        return encode_vectors(*cmul(robot.real, robot.imag, *to_robot_frame_batch(state)), "cartesian", self.bound)
