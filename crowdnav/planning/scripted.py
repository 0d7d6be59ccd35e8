"""Scripted robot policies that read the simulator's state directly (baselines, demos, videos).

Each policy is a callable ``policy(sim) -> action`` (:data:`ScriptedPolicy`; ``sim`` a simulator or
one robot's :class:`crowdnav.sim.robot_view.RobotView`, :class:`crowdnav.sim.robot_view.RobotWorld`) returning the robot's normalized action
(2 values in [-1, 1]) for the scenario's kinematics. All but one are privileged (they see the
true state, not the observation), which is what a baseline for a video or a sanity check needs;
``onboard`` (:class:`crowdnav.planning.onboard.OnboardPlanner`) reads only what the robot's own
sensing gives (its tracker's rows, its pose and the map: it executes the ``plan`` modality's move).
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Callable
from typing import TypeAlias

import numpy as np

from crowdnav.planning.onboard import OnboardPlanner
from crowdnav.planning.oracle import OraclePlanner
from crowdnav.planning.predictive import PredictivePlanner
from crowdnav.sim import forces as sf
from crowdnav.sim.orca_solver import OrcaSolver, SolverCache, obstacle_rings, pyrvo_module, toward_goal
from crowdnav.sim.robot_view import RobotWorld
from crowdnav.worlds.compiled import CompiledWorld

ScriptedPolicy: TypeAlias = Callable[[RobotWorld], np.ndarray]
"""``policy(sim) -> action``: float32 (2,) in [-1, 1]."""


def velocity_to_action(sim: RobotWorld, velocity: complex) -> np.ndarray:
    """The normalized action that moves the robot at ``velocity`` (world frame, m/s), as close as its kinematics allow."""
    robot = sim.scenario.robot
    local = velocity * cmath.exp(-1j * sim.robot_heading) / robot.max_speed  # robot frame, in max-speed units
    if robot.kinematics == "holonomic":
        if abs(local) > 1.0:
            local /= abs(local)
        return np.array([local.real, local.imag], dtype=np.float32)
    # unicycle: turn towards the direction (as fast as one step allows), drive along the heading
    bearing = cmath.phase(local) if abs(local) > 1e-9 else 0.0
    assert robot.max_angular_speed is not None  # the schema requires it of a unicycle
    turn = bearing / (robot.max_angular_speed * sim.dt)
    forward = abs(local) * max(0.0, math.cos(bearing))
    return np.clip(np.array([forward, turn], dtype=np.float32), -1.0, 1.0)


class StraightToGoal:
    """Head straight for the goal at full speed, slowing so as not to overshoot it."""

    def __call__(self, sim: RobotWorld) -> np.ndarray:
        to_goal = sim.robot_goal - sim.robot_position
        speed = min(sim.scenario.robot.max_speed, abs(to_goal) / sim.dt)
        direction = to_goal / abs(to_goal) if abs(to_goal) > 1e-12 else 0j
        return velocity_to_action(sim, direction * speed)


class RandomPolicy:
    """Uniformly random actions from its own seeded generator."""

    def __init__(self, seed: int | None = None) -> None:
        self.rng = np.random.default_rng(seed)

    def __call__(self, sim: RobotWorld) -> np.ndarray:
        return self.rng.uniform(-1.0, 1.0, size=2).astype(np.float32)


class SocialForceRobot:
    """The humans' social-force model applied to the robot: goal attraction plus repulsion.

    Repulsion from humans is the simulator's ``robot_social_force``; repulsion from static
    obstacles uses the scenario's obstacle parameters with the robot's radius. With several
    robots (called with :meth:`crowdnav.Simulator.robot_view`), the other robots repel it as a
    robot repels the humans (``robot_strength``, ``robot_range``): without that, two of them
    driving at each other would meet head on.
    """

    def __call__(self, sim: RobotWorld) -> np.ndarray:
        params = sim.scenario.humans.social_force
        robot = sim.scenario.robot
        to_goal = np.array([sim.robot_goal - sim.robot_position])
        force = complex(sf.goal_force(to_goal, params.goal_weight, params.goal_saturation_distance)[0])
        force += sim.robot_social_force
        if sim.obstacles.polygon_count + sim.obstacles.disc_count:
            offsets = np.concatenate([sim.polygon_offset[0], sim.disc_offset[0] if sim.obstacles.disc_count else []])
            distances = np.concatenate([sim.polygon_distance[0], sim.disc_distance[0] if sim.obstacles.disc_count else []])
            assert sim.obstacles.surface_radius is not None  # build_obstacles sets it for every world
            contact = robot.radius + sim.obstacles.surface_radius
            gain = sf.repulsion_gain(params.obstacle_strength, contact, params.obstacle_range)
            force += complex(sf.repulsion(offsets[None, :], distances[None, :], gain[None, :], -1.0 / params.obstacle_range)[0])
        others = sim.other_robot_discs
        offsets = sim.positions[others] - sim.positions[0]
        if len(offsets):
            gain = sf.repulsion_gain(params.robot_strength, robot.radius + sim.radii[others], params.robot_range)
            force += complex(sf.repulsion(offsets[None, :], np.abs(offsets)[None, :], gain[None, :], -1.0 / params.robot_range)[0])
        velocity = force * robot.max_speed
        if abs(velocity) > robot.max_speed:
            velocity *= robot.max_speed / abs(velocity)
        return velocity_to_action(sim, velocity)


WORLDS_KEPT = 8
"""Worlds one :class:`OrcaRobot` keeps solvers for (the first seen freed first)."""


class OrcaRobot:
    """ORCA for the robot: the velocity nearest to full speed at the goal that stays collision-free.

    Privileged like :class:`SocialForceRobot`: ORCA (:mod:`crowdnav.sim.orca_solver`, the scenario's
    ``humans.orca`` parameters) sees every human's true position and velocity, each assumed to
    keep it (its preferred velocity), and the static obstacles. As in ORCA everywhere, the robot
    takes only half of the avoidance of each human, the other half being the human's: against
    humans that do not see it (``humans.see_robot: false``) it can still be hit. Needs the
    optional package pyrvo (``pip install -e ".[orca]"`` in crowdnav's clone).
    """

    def __init__(self) -> None:
        pyrvo_module("the ORCA robot (baseline:orca)")
        self._worlds: dict[int, tuple[CompiledWorld, list[list[tuple[float, float]]], SolverCache]] = {}
        """id(world) -> (world, its obstacles as RVO2 rings, the solvers of its last few agent counts): one policy may drive many envs."""

    def __call__(self, sim: RobotWorld) -> np.ndarray:
        cached = self._worlds.get(id(sim.world))
        if cached is None or cached[0] is not sim.world:  # (the tuple holds the world, so its id is not reused while cached)
            while len(self._worlds) >= WORLDS_KEPT:  # the oldest world's solvers freed: one policy over many worlds stays bounded
                del self._worlds[next(iter(self._worlds))]
            cached = self._worlds[id(sim.world)] = (sim.world, obstacle_rings(sim.obstacles), SolverCache())
        _, rings, solvers = cached
        robot, count = sim.scenario.robot, sim.n_humans + 1
        solver = solvers.get(count, lambda size: OrcaSolver(rings, sim.scenario.humans.orca, sim.dt, size, "the ORCA robot"))
        if solver.episode is not sim.human_max_speed:  # a new array at every reset: another episode (or env) than last time
            solver.configure(sim.radii, np.concatenate([[robot.max_speed], sim.human_max_speed]))
            solver.episode = sim.human_max_speed
        preferred = sim.velocities.copy()  # the humans keep their velocity; the robot heads for its goal
        preferred[0] = toward_goal(np.array([sim.robot_goal - sim.robot_position]), robot.max_speed, sim.dt)[0]
        velocity = complex(solver.velocities(sim.positions, sim.velocities, preferred)[0])
        return velocity_to_action(sim, velocity)


SCRIPTED_POLICIES: dict[str, Callable[..., ScriptedPolicy]] = {
    "social-force": SocialForceRobot, "straight": StraightToGoal, "random": RandomPolicy, "orca": OrcaRobot,
    "oracle": OraclePlanner, "predictive": PredictivePlanner, "onboard": OnboardPlanner,
}
"""Names accepted by ``crowdnav render --policy`` -> the policy's class (``random`` takes a seed, the others nothing)."""
