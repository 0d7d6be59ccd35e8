"""Recorded people who react to the robot (``humans.replay.react_within``): one social-force step toward their recorded future.

A reacting person (:class:`crowdnav.crowd.replay.ReplayModel`) is no longer put at its recorded
position: each step it takes the social force's velocity command, the kernels of
:mod:`crowdnav.sim.forces` with the scenario's ``humans.social_force`` parameters, where

- the goal is its own recorded position ``react_lookahead`` seconds ahead (its last recorded
  position near the end of its track), updated every step;
- it is repelled by every robot (``robot_strength``, ``robot_range``, whatever ``see_robot``
  says: reacting to the robot is the point), every other human present (``human_strength``,
  ``human_range``) and the static obstacles (``obstacle_strength``, ``obstacle_range``);
- its preferred and max speed are those the simulator drew for its place (the group's
  ``preferred_speed`` range), and it relaxes from its current velocity over ``relaxation_time``.

The arithmetic is over the reacting people at once (arrays (m, agents) and (m, obstacles)); a
world of the batched simulator computes exactly what a single simulator does (same arrays, same
operations), so batched replay equals single replay bit for bit.
"""

from __future__ import annotations

import numpy as np

from crowdnav.crowd.base import CrowdView
from crowdnav.sim import forces as sf
from crowdnav.worlds.compiled import CompiledWorld
from crowdnav.worlds.obstacles import nearest_on_edges


class Reaction:
    """The social-force step of reacting recorded people in one world (constants read once from the compiled world)."""

    def __init__(self, world: CompiledWorld):
        force = world.scenario.humans.social_force
        self.force = force
        self.dt = world.scenario.time_step
        self.relax = min(1.0, self.dt / force.relaxation_time)
        self.surface = world.obstacles.surface
        radius = world.obstacles.surface_radius
        self.surface_radius = np.zeros(0) if radius is None else radius

    def velocities(self, view: CrowdView, who: np.ndarray, targets: np.ndarray, moving: np.ndarray) -> np.ndarray:
        """(m,) complex: the velocity command of humans ``who`` (indices among the humans) toward ``targets`` (m,), from their
        current velocities ``moving`` (m,), in the state ``view`` shows."""
        force, robots = self.force, view.robot_count
        agents = view.agent_positions
        mine = robots + who
        here = agents[mine]
        offset = agents[None, :] - here[:, None]  # (m, R+n): from each reacting person to every agent
        distance = np.abs(offset)
        radii = view.agent_radii
        is_robot = np.arange(len(agents)) < robots
        strength = np.where(is_robot, force.robot_strength, force.human_strength)
        reach = np.where(is_robot, force.robot_range, force.human_range)
        gain = sf.repulsion_gain(np.broadcast_to(strength, offset.shape), radii[mine][:, None] + radii[None, :], reach)
        # itself, and agents that are nowhere (a robot that left): no force
        void = ~np.isfinite(distance)
        void[np.arange(len(who)), mine] = True
        if void.any():
            gain = np.where(void, 0.0, gain)
            offset = np.where(void, 0.0, offset)
            distance = np.where(void, 1.0, distance)
        total = sf.goal_force(targets - here, force.goal_weight, force.goal_saturation_distance)
        total += sf.repulsion(offset, distance, gain, -1.0 / reach)
        if self.surface is not None and self.surface.start.shape[0]:
            to_wall, gap = nearest_on_edges(here, self.surface)  # (m, S): centre to the nearest point of each obstacle
            wall_gain = sf.repulsion_gain(force.obstacle_strength, radii[mine][:, None] + self.surface_radius[None, :],
                                          force.obstacle_range)
            total += sf.repulsion(to_wall, np.maximum(gap, 1e-9), wall_gain, -1.0 / force.obstacle_range)
        command: np.ndarray = sf.velocity_command(total, moving, view.human_preferred_speed[who], view.human_max_speed[who],
                                                  self.relax)
        return command
