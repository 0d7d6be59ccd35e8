"""What a batch of worlds looks like to the sensors: K worlds of one scenario, one crowd size, stacked.

:class:`BatchState` holds the same quantities a :class:`crowdnav.Simulator` exposes after a
reset or step, with a leading world axis. The batched simulator (:mod:`crowdnav.batch.simulator`)
builds one per crowd size present in the batch; :meth:`BatchState.stack` builds one from single
simulators (tests, and modalities without a batched ``observe_batch``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeAlias

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from crowdnav.sim.simulator import Simulator

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
    def stack(cls, sims: Sequence[Simulator]) -> BatchState:
        """The state of single simulators with the same crowd size, stacked in the given order."""
        sizes = {sim.n_humans for sim in sims}
        if len(sizes) != 1:
            raise ValueError(f"BatchState.stack needs simulators with one crowd size, got sizes {sorted(sizes)}")
        return cls(
            positions=np.stack([sim.positions for sim in sims]),
            velocities=np.stack([sim.velocities for sim in sims]),
            robot_heading=np.array([sim.robot_heading for sim in sims], dtype=float),
            robot_goal=np.array([sim.robot_goal for sim in sims], dtype=complex),
            radii=np.asarray(sims[0].radii, dtype=float),
            robot_offset=np.stack([sim.robot_offset for sim in sims]),
            robot_distance=np.stack([sim.robot_distance for sim in sims]),
            polygon_offset=np.stack([sim.polygon_offset[0] for sim in sims]),
            polygon_distance=np.stack([sim.polygon_distance[0] for sim in sims]),
            disc_offset=np.stack([sim.disc_offset[0] for sim in sims]),
            disc_distance=np.stack([sim.disc_distance[0] for sim in sims]),
        )
