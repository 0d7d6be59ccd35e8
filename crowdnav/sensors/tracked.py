"""The world as the robot's people tracker reports it, for everything that reads the tracker.

The ``humans`` and ``plan`` modalities (``Modality.reads_tracker``), the shield and ``baseline:onboard``
read the people around the robot through the names a simulator has (``robot_offset``,
``robot_distance``, ``velocities``, ...). With a tracker profile the env hands them, instead of the
simulator, a view whose people are the tracker's reported tracks (:class:`TrackedView` for one world,
:func:`tracked_state` for K stacked worlds): a reported person at its estimated centre with its estimated
velocity, anyone else at an infinite distance (absent). The robot's own pose, velocity and goal and the
map stay the simulator's (localisation and odometry are exact).

A scripted policy is called with the simulator itself; :func:`sensed_people` finds the tracker the env
attached to that simulator (:func:`attach`), so ``baseline:onboard`` sees the same tracks as the env's
own observation at that step.
"""

from __future__ import annotations

import dataclasses
import weakref
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from crowdnav.scenario.tracker import PERFECT
from crowdnav.sensors.tracker import TrackedColumns
from crowdnav.sim.state import SELF_DISTANCE

if TYPE_CHECKING:
    from crowdnav.batch.state import BatchState
    from crowdnav.scenario.schema import Scenario
    from crowdnav.sim.robot_view import RobotWorld
    from crowdnav.worlds.compiled import CompiledWorld
    from crowdnav.worlds.obstacles import StaticObstacles

Reader = Callable[[int], TrackedColumns]
"""``reader(n)``: a world's columns (1-row arrays) for its first n people."""

_READERS: weakref.WeakKeyDictionary[Any, Reader] = weakref.WeakKeyDictionary()


def attach(sim: Any, reader: Reader) -> None:
    """Make ``reader`` the tracker of the robot in ``sim`` (a simulator an env steps, or a snapshot of one)."""
    _READERS[sim] = reader


def sensed_people(sim: RobotWorld) -> RobotWorld:
    """``sim`` as its robot's tracker reports the people: ``sim`` itself for the ``perfect`` profile.

    A ValueError (one line) for a tracker profile and a simulator no env attached a tracker to: its
    tracks exist only where an env steps them.
    """
    reader = _READERS.get(sim)
    if reader is not None:
        return TrackedView(sim, reader(sim.n_humans))
    profile = sim.scenario.sensors.tracker.profile
    if profile != PERFECT:
        raise ValueError(f"sensors.tracker is {profile!r}: the people tracker's state lives in the env; call this with the "
                         "simulator of a crowdnav env (env.simulator, or CrowdNavVectorEnv.simulator(i))")
    return sim


def tracked_state(state: BatchState, columns: TrackedColumns) -> BatchState:
    """K stacked worlds with the tracker's people (``columns`` of those worlds, in their order) in place of the true ones."""
    return dataclasses.replace(state, positions=columns.positions, velocities=columns.velocities, robot_offset=columns.offset,
                               robot_distance=columns.distance)


class TrackedView:
    """One world (``sim``, a simulator) with the tracker's people (``columns``, 1-row arrays) in place of the true ones.

    It has the names a :class:`crowdnav.sim.robot_view.RobotWorld` has: ``positions``, ``velocities``,
    ``robot_offset``, ``robot_distance`` (and ``pair_*``, built from them) hold the tracks; the rest is
    the simulator's.
    """

    def __init__(self, sim: RobotWorld, columns: TrackedColumns):
        self._sim = sim
        self.positions, self.velocities, self.robot_offset, self.robot_distance = (np.array(values[0]) for values in columns)

    @property
    def world(self) -> CompiledWorld:
        return self._sim.world

    @property
    def scenario(self) -> Scenario:
        return self._sim.scenario

    @property
    def obstacles(self) -> StaticObstacles:
        return self._sim.obstacles

    @property
    def dt(self) -> float:
        return self._sim.dt

    @property
    def n_humans(self) -> int:
        return self._sim.n_humans

    @property
    def robot_position(self) -> complex:
        return self._sim.robot_position

    @property
    def robot_goal(self) -> complex:
        return self._sim.robot_goal

    @property
    def robot_goal_distance(self) -> float:
        return self._sim.robot_goal_distance

    @property
    def robot_heading(self) -> float:
        return self._sim.robot_heading

    @property
    def robot_social_force(self) -> complex:
        return self._sim.robot_social_force

    @property
    def other_robot_discs(self) -> slice:
        return self._sim.other_robot_discs

    @property
    def radii(self) -> np.ndarray:
        return self._sim.radii

    @property
    def human_max_speed(self) -> np.ndarray:
        return self._sim.human_max_speed

    @property
    def polygon_offset(self) -> np.ndarray:
        return self._sim.polygon_offset

    @property
    def polygon_distance(self) -> np.ndarray:
        return self._sim.polygon_distance

    @property
    def disc_offset(self) -> np.ndarray:
        return self._sim.disc_offset

    @property
    def disc_distance(self) -> np.ndarray:
        return self._sim.disc_distance

    @property
    def pair_offset(self) -> np.ndarray:
        """(n+1, n+1) complex between the robot and the tracks (NaN for people not reported)."""
        offset: np.ndarray = self.positions[None, :] - self.positions[:, None]
        return offset

    @property
    def pair_distance(self) -> np.ndarray:
        distance: np.ndarray = np.abs(self.pair_offset)
        distance.flat[:: len(self.positions) + 1] = SELF_DISTANCE
        return distance
