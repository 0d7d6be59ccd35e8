"""What a batch of worlds looks like to the sensors: K worlds of one scenario, one crowd size, stacked.

:class:`BatchState` holds the same quantities a :class:`crowdnav.Simulator` exposes after a
reset or step, with a leading world axis: each field is one of :class:`crowdnav.sim.robot_view.RobotWorld`'s
names. The batched simulator (:mod:`crowdnav.batch.simulator`) builds one per crowd size present in the
batch; :meth:`BatchState.stack` builds one from single simulators (tests, and modalities without a batched
``observe_batch``) and :meth:`BatchState.rows` takes some worlds of one, both from the fields as declared
(not listed again).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeAlias, get_args, get_type_hints

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from crowdnav.sim.robot_view import RobotWorld

ComplexArray: TypeAlias = npt.NDArray[np.complex128]
"""Points and vectors in the plane, ``x + y j``."""
FloatArray: TypeAlias = npt.NDArray[np.float64]
"""Distances, headings, radii."""
IntArray: TypeAlias = npt.NDArray[np.int64]
"""Counts and indices (steps, groups, respawns)."""
BoolArray: TypeAlias = npt.NDArray[np.bool_]
"""Masks (stopped, arrived)."""


@dataclass
class BatchState:
    """K worlds with the same number of humans n; agent 0 is the robot, as in the simulator."""

    positions: ComplexArray
    """(K, n+1) complex: robot then humans, metres, world frame."""
    velocities: ComplexArray
    """(K, n+1) complex: velocities over the last step, m/s."""
    robot_heading: FloatArray
    """(K,) float: the robot's heading, radians."""
    robot_goal: ComplexArray
    """(K,) complex: the robot's goal."""
    radii: FloatArray
    """(n+1,) float: body radii, shared by the K worlds (robot first)."""
    robot_offset: ComplexArray
    """(K, n+1) complex: from the robot to every agent's centre (column 0: the robot itself, 0)."""
    robot_distance: FloatArray
    """(K, n+1) float: centre distances from the robot (column 0: a huge number)."""
    polygon_offset: ComplexArray
    """(K, P) complex: from the robot's centre to the nearest point of each static polygon."""
    polygon_distance: FloatArray
    """(K, P) float: its length."""
    disc_offset: ComplexArray
    """(K, C) complex: from the robot's centre to each round obstacle's centre."""
    disc_distance: FloatArray
    """(K, C) float: its length (centre distance)."""

    @property
    def worlds(self) -> int:
        return len(self.positions)

    @property
    def n_humans(self) -> int:
        humans: int = self.positions.shape[1] - 1
        return humans

    @classmethod
    def stack(cls, worlds: Sequence[RobotWorld]) -> BatchState:
        """The state of single worlds (simulators, views of one robot) with the same crowd size, stacked in the given order:
        each field read from every world by its name, as its declared dtype (:data:`SHARED_BY_WORLDS` from the first world,
        :data:`ROBOT_ROW` row 0)."""
        sizes = {world.n_humans for world in worlds}
        if len(sizes) != 1:
            raise ValueError(f"BatchState.stack needs simulators with one crowd size, got sizes {sorted(sizes)}")
        return cls(**{name: np.asarray(getattr(worlds[0], name), dtype) if name in SHARED_BY_WORLDS
                      else np.array([getattr(world, name)[0] if name in ROBOT_ROW else getattr(world, name) for world in worlds], dtype)
                      for name, dtype in dtypes(cls).items()})

    def rows(self, rows: np.ndarray | None, **given: np.ndarray) -> BatchState:
        """Worlds ``rows`` of this batch (None: all), but the fields ``given`` (those worlds' already); the fields without a
        world axis kept."""
        for name in dtypes(type(self)):
            if name not in given:
                value = getattr(self, name)
                given[name] = value if rows is None or name in SHARED_BY_WORLDS else value[rows]
        return type(self)(**given)


SHARED_BY_WORLDS = frozenset({"radii"})
"""The fields without a world axis: the same for every world of a batch."""
ROBOT_ROW = frozenset({"polygon_offset", "polygon_distance", "disc_offset", "disc_distance"})
"""The obstacle tables: a simulator's have a row per agent, a view's one; a batch keeps the robot's (row 0)."""


def dtypes(kind: type[BatchState]) -> dict[str, Any]:
    """Every field of ``kind`` (:class:`BatchState` or a subclass) and its declared dtype (``np.complex128``, ...), in order."""
    known = _DTYPES.get(kind)
    if known is None:
        known = _DTYPES[kind] = {name: get_args(get_args(hint)[1])[0] for name, hint in get_type_hints(kind).items()}
    return known


_DTYPES: dict[type, dict[str, Any]] = {}
