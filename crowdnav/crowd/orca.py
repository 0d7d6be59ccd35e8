"""The ORCA crowd model (``model: orca``): optimal reciprocal collision avoidance through pyrvo (:mod:`crowdnav.sim.orca_solver`).

Every human is an ORCA agent (so ORCA humans also avoid social-force and standing ones), and so
is each robot when the humans see it (``humans.see_robot``), at its current velocity; the
commands of every human come back, and the crowd uses those of its ORCA groups. A pyrvo solver
holds one world's agents, so a batch steps its worlds one by one, each with its own instance.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, cast

import numpy as np

from crowdnav.crowd.base import CrowdModel, CrowdView
from crowdnav.sim.orca_solver import OrcaSolver, SolverCache, obstacle_rings, pyrvo_module, toward_goal
from crowdnav.worlds.compiled import CompiledWorld


class OrcaModel(CrowdModel):
    """One world's ORCA humans: the solver of this episode's agent count (kept per count by a :class:`SolverCache`)."""

    name = "orca"

    def __init__(self, world: CompiledWorld):
        super().__init__(world)
        pyrvo_module("orca")  # fail at load, not at the first step
        self._rings = obstacle_rings(world.obstacles)
        self._params = world.scenario.humans.orca
        self._see_robot = world.scenario.humans.see_robot
        self._solvers = SolverCache()
        """The solvers of the last few episodes' agent counts."""

    def start_episode(self, view: CrowdView, rng: np.random.Generator) -> None:
        """Pick (or build) the solver for this episode's agents and set their radii and max speeds."""
        self._configure(view)

    def resume(self, view: CrowdView, state: Mapping[str, Any]) -> None:
        """The solver of the loaded episode's agents, set for them (RVO2 keeps nothing else between steps that a step does not set)."""
        self._configure(view)

    def _configure(self, view: CrowdView) -> None:
        robots = view.robot_count
        n = len(view.human_max_speed)
        count = n + self._see_robot * robots
        self._solver = solver = self._solvers.get(count, lambda size: OrcaSolver(self._rings, self._params, self.dt, size, "orca"))
        if self._see_robot:
            solver.configure(view.agent_radii, np.concatenate([view.robot_max_speeds, view.human_max_speed]))
        else:
            solver.configure(view.agent_radii[robots:], view.human_max_speed)

    def commands(self, view: CrowdView) -> np.ndarray:
        return self._velocities(view.robot_count, view.agent_positions, view.agent_velocities, view.human_goals, view.human_preferred_speed)

    def commands_batch(self, view: CrowdView, worlds: Sequence[CrowdModel]) -> np.ndarray:
        """World by world (a pyrvo solver holds one world's agents), each world's own solver on its row."""
        robots, positions, velocities = view.robot_count, view.agent_positions, view.agent_velocities
        goals, speeds = view.human_goals, view.human_preferred_speed
        return np.stack([cast(OrcaModel, model)._velocities(robots, positions[k], velocities[k], goals[k], speeds[k])
                         for k, model in enumerate(worlds)])

    def _velocities(self, robots: int, positions: np.ndarray, velocities: np.ndarray, goals: np.ndarray, speeds: np.ndarray) -> np.ndarray:
        """(n,) ORCA velocities of one world's humans (agents: the robots first)."""
        preferred = toward_goal(goals - positions[robots:], speeds, self.dt)
        if self._see_robot:  # the robots keep their course, as far as ORCA's humans can tell
            return self._solver.velocities(positions, velocities, np.concatenate([velocities[:robots], preferred]))[robots:]
        return self._solver.velocities(positions[robots:], velocities[robots:], preferred)
