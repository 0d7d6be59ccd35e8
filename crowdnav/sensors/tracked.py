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
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from crowdnav.scenario.tracker import PERFECT
from crowdnav.sensors.tracker import TrackedColumns
from crowdnav.sim.geometry import pair_tables
from crowdnav.sim.robot_view import reads_the_rest

if TYPE_CHECKING:
    from crowdnav.batch.state import BatchState
    from crowdnav.sim.robot_view import RobotWorld

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
        return cast("RobotWorld", TrackedView(sim, reader(sim.n_humans)))
    profile = sim.scenario.sensors.tracker.profile
    if profile != PERFECT:
        raise ValueError(f"sensors.tracker is {profile!r}: the people tracker's state lives in the env; call this with the "
                         "simulator of a crowdnav env (env.simulator, or CrowdNavVectorEnv.simulator(i))")
    return sim


def tracked_state(state: BatchState, columns: TrackedColumns) -> BatchState:
    """K stacked worlds with the tracker's people (``columns`` of those worlds, in their order) in place of the true ones."""
    return dataclasses.replace(state, positions=columns.positions, velocities=columns.velocities, robot_offset=columns.offset,
                               robot_distance=columns.distance)


@reads_the_rest("_sim")  # every other name: the simulator's (the robot's pose, goal and map, the people's radii and speeds)
class TrackedView:
    """One world (``sim``, a simulator) with the tracker's people (``columns``, 1-row arrays) in place of the true ones.

    It has the names a :class:`crowdnav.sim.robot_view.RobotWorld` has: ``positions``, ``velocities``,
    ``robot_offset``, ``robot_distance`` (and ``pair_*``, built from them) hold the tracks; the rest is
    the simulator's (:func:`crowdnav.sim.robot_view.reads_the_rest`).
    """

    positions: np.ndarray
    velocities: np.ndarray
    robot_offset: np.ndarray
    robot_distance: np.ndarray

    def __init__(self, sim: RobotWorld, columns: TrackedColumns):
        self._sim = sim
        self.positions, self.velocities, self.robot_offset, self.robot_distance = (np.array(values[0]) for values in columns)

    @property
    def pair_offset(self) -> np.ndarray:
        """(n+1, n+1) complex between the robot and the tracks (NaN for people not reported)."""
        return pair_tables(self.positions)[0]

    @property
    def pair_distance(self) -> np.ndarray:
        return pair_tables(self.positions)[1]
