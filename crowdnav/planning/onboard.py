"""The predictive planner fed by the robot's own sensing (``baseline:onboard``): the ``plan`` modality's move, executed.

At every step :class:`OnboardPlanner` takes as its action exactly what the ``plan`` modality
(:class:`crowdnav.sensors.plan.PlanModality`) observes for that robot at that step: the move
:class:`crowdnav.planning.predictive.PredictivePlanner` makes from the humans the robot's tracker
reports (the ``humans`` modality with the scenario's ``sensors.humans`` settings: its k nearest
within range, never anyone else, nor the other robots; with a ``sensors.tracker`` profile the tracks
the env's tracker holds for that simulator, :func:`crowdnav.sensors.tracked.sensed_people`), its own pose, velocity and goal, and the
static map, the humans predicted at constant velocity. It reads nothing the robot does not have:
not privileged, unlike ``baseline:predictive`` (the same planner fed the true state of every
human). It is the level a learned agent has to beat; an agent observing ``plan`` can reach it by
outputting its observation.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from crowdnav.planning.oracle import PlannerUnavailable, check_plannable
from crowdnav.planning.predictive import PredictivePlanner
from crowdnav.sensors.plan import PlanModality
from crowdnav.sensors.tracked import sensed_people
from crowdnav.sim.robot_view import RobotView, RobotWorld

if TYPE_CHECKING:
    from crowdnav.scenario.schema import Scenario
    from crowdnav.worlds.compiled import CompiledWorld

WORLDS_KEPT = 512
"""Worlds one :class:`OnboardPlanner` keeps a ``plan`` modality for (the first seen freed first): a test set's envs,
one world each, played in lock-step (up to 500 episodes) reuse theirs."""


class OnboardPlanner:
    """The ``plan`` modality's move as the action: the predictive planner from the tracker, the robot's pose and the map.

    Called with what a scripted policy reads (``policy(sim) -> action``; several robots: that
    robot's :class:`crowdnav.sim.robot_view.RobotView`), it reads only the tracker's rows of that view
    (the humans, the other robots left out as the ``plan`` modality leaves them), the robot's pose,
    velocity and goal, and the map. Holonomic robots only: elsewhere, and for a world too large
    for the planner's maps, a one-line :class:`crowdnav.planning.PlannerUnavailable`. One
    :class:`crowdnav.planning.predictive.PredictivePlanner` serves every world (its maps are keyed
    by the scenario's content), so a test set of one scenario builds one map.
    """

    label = "onboard planner: tracker + map (scripted)"

    def __init__(self) -> None:
        self.planner = PredictivePlanner()
        self._worlds: dict[tuple[int, int], tuple[CompiledWorld, Scenario, PlanModality]] = {}
        """(id(world), id(robot's scenario)) -> (world, scenario, the plan modality of that robot in it)."""

    def __call__(self, sim: RobotWorld) -> np.ndarray:
        check_plannable(sim, "the onboard planner", needs_fixed_future=False)
        # the tracker's view: one robot's simulator as its env's tracker reports the people; several robots, the humans
        people = sim.without_robots() if isinstance(sim, RobotView) else sensed_people(sim)
        action: np.ndarray = self.modality(sim).observe(people)
        return action

    def modality(self, sim: RobotWorld) -> PlanModality:
        """The ``plan`` modality of ``sim``'s robot in its world, as the env builds it (robot k: the world with its own spec)."""
        key = (id(sim.world), id(sim.scenario))
        cached = self._worlds.get(key)
        if cached is None or cached[0] is not sim.world or cached[1] is not sim.scenario:  # (the tuple holds both: ids not reused)
            while len(self._worlds) >= WORLDS_KEPT:
                del self._worlds[next(iter(self._worlds))]
            world = sim.world if sim.scenario is sim.world.scenario else dataclasses.replace(sim.world, scenario=sim.scenario)
            try:
                plan = PlanModality(world)
            except ValueError as error:  # a world too large for the planner's maps
                raise PlannerUnavailable(f"the onboard planner: {str(error).splitlines()[0]}") from None
            plan.planner = self.planner  # the same planner and settings: one map per scenario, the same moves
            cached = self._worlds[key] = (sim.world, sim.scenario, plan)
        return cached[2]
