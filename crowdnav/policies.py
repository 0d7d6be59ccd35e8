"""Scripted robot policies that read the simulator's state directly (baselines, demos, videos).

Each policy is a callable ``policy(sim) -> action`` returning the robot's normalized action
(2 values in [-1, 1]) for the scenario's kinematics. They are privileged (they see the true
state, not the observation), which is what a baseline for a video or a sanity check needs.
"""

from __future__ import annotations

import cmath
import math
from typing import Protocol

import numpy as np

from crowdnav import social_force as sf
from crowdnav.simulator import Simulator


class RobotPolicy(Protocol):
    """Anything that maps the simulator's current state to a robot action."""

    def __call__(self, sim: Simulator) -> np.ndarray: ...


def velocity_to_action(sim: Simulator, velocity: complex) -> np.ndarray:
    """The normalized action that moves the robot at ``velocity`` (world frame, m/s), as close as its kinematics allow."""
    robot = sim.scenario.robot
    local = velocity * cmath.exp(-1j * sim.robot_heading) / robot.max_speed  # robot frame, in max-speed units
    if robot.kinematics == "holonomic":
        if abs(local) > 1.0:
            local /= abs(local)
        return np.array([local.real, local.imag], dtype=np.float32)
    # unicycle: turn towards the direction (as fast as one step allows), drive along the heading
    bearing = cmath.phase(local) if abs(local) > 1e-9 else 0.0
    turn = bearing / (robot.max_angular_speed * sim.dt)
    forward = abs(local) * max(0.0, math.cos(bearing))
    return np.clip(np.array([forward, turn], dtype=np.float32), -1.0, 1.0)


class StraightToGoal:
    """Head straight for the goal at full speed, slowing so as not to overshoot it."""

    def __call__(self, sim: Simulator) -> np.ndarray:
        to_goal = sim.robot_goal - sim.robot_position
        speed = min(sim.scenario.robot.max_speed, abs(to_goal) / sim.dt)
        direction = to_goal / abs(to_goal) if abs(to_goal) > 1e-12 else 0j
        return velocity_to_action(sim, direction * speed)


class RandomPolicy:
    """Uniformly random actions from its own seeded generator."""

    def __init__(self, seed: int | None = None):
        self.rng = np.random.default_rng(seed)

    def __call__(self, sim: Simulator) -> np.ndarray:
        return self.rng.uniform(-1.0, 1.0, size=2).astype(np.float32)


class SocialForceRobot:
    """The humans' social-force model applied to the robot: goal attraction plus repulsion.

    Repulsion from humans is the simulator's ``robot_social_force``; repulsion from static
    obstacles uses the scenario's obstacle parameters with the robot's radius.
    """

    def __call__(self, sim: Simulator) -> np.ndarray:
        params = sim.scenario.humans.social_force
        robot = sim.scenario.robot
        to_goal = np.array([sim.robot_goal - sim.robot_position])
        force = complex(sf.goal_force(to_goal, params.goal_weight, params.goal_saturation_distance)[0])
        force += sim.robot_social_force
        if sim.obstacles.polygon_count + sim.obstacles.disc_count:
            offsets = np.concatenate([sim.polygon_offset[0], sim.disc_offset[0] if sim.obstacles.disc_count else []])
            distances = np.concatenate([sim.polygon_distance[0], sim.disc_distance[0] if sim.obstacles.disc_count else []])
            contact = robot.radius + sim.obstacles.surface_radius
            gain = sf.repulsion_gain(params.obstacle_strength, contact, params.obstacle_range)
            force += complex(sf.repulsion(offsets[None, :], distances[None, :], gain[None, :], -1.0 / params.obstacle_range)[0])
        velocity = force * robot.max_speed
        if abs(velocity) > robot.max_speed:
            velocity *= robot.max_speed / abs(velocity)
        return velocity_to_action(sim, velocity)


SCRIPTED_POLICIES = {"social-force": SocialForceRobot, "straight": StraightToGoal, "random": RandomPolicy}
"""Names accepted by ``crowdnav render --policy``."""
