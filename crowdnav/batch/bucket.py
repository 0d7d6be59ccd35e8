"""A bucket: the worlds of a batch that have the same number of humans this episode, stacked row by row.

:class:`crowdnav.batch.simulator.BatchSimulator` keeps one per crowd size present (padding a crowd
would change the length of its force sums, and so their rounding: see :mod:`crowdnav.batch.simulator`).
A reset adds, replaces or removes a world's row here; the simulator's refresh fills the geometry.
"""

from __future__ import annotations

from typing import cast

import numpy as np

from crowdnav.batch.stacked_state import StackedState
from crowdnav.batch.state import BoolArray, ComplexArray, FloatArray
from crowdnav.sim.geometry import MEASURED, Measured
from crowdnav.sim.state import PairConstants, SimState

_GEOMETRY = MEASURED
"""What a refresh measures (:class:`crowdnav.sim.geometry.Measured`), one row per world in a bucket (created by the first refresh)."""
_ROBOT_ROW = frozenset({"polygon_offset", "polygon_distance", "disc_offset", "disc_distance"})
"""Those a bucket keeps for the robot only (its row: what the sensors read), (K, P) and (K, C)."""


class Bucket:
    """The worlds of a batch that have ``n`` humans this episode, stacked row by row.

    ``state``: their :class:`StackedState` (read as ``bucket.state.positions``: the bucket does not
    repeat its fields); the geometry arrays (``pair_offset``, ``gap``, ``repulsion``, ...) are
    created by the first refresh.
    """

    # the geometry (_GEOMETRY), one row per world: absent until the first refresh creates it
    pair_offset: ComplexArray
    pair_distance: FloatArray
    gap: FloatArray
    repulsion: ComplexArray
    humans_touch: BoolArray
    polygon_offset: ComplexArray
    polygon_distance: FloatArray
    disc_offset: ComplexArray
    disc_distance: FloatArray

    def __init__(self, n: int, constants: PairConstants, world: int, state: SimState):
        if constants.contact_all is None or constants.gain is None or constants.decay is None:
            raise ValueError(f"a bucket holds crowds measured by all pairs; {n} humans use the neighbour grid")
        self.n = n
        self.radii = constants.radii
        self.contact_all: FloatArray = constants.contact_all
        self.gain: FloatArray = constants.gain
        self.decay: FloatArray = constants.decay
        self.world = np.array([world], dtype=np.intp)
        """(K,) the batch index of each row's world."""
        self.state = StackedState.stack([state])

    def __len__(self) -> int:
        return len(self.world)

    def add(self, world: int, state: SimState) -> None:
        """Append ``world`` with its ``state`` after a reset."""
        self.world = np.append(self.world, world)
        self.state = self.state.append(state)
        for name in _GEOMETRY:  # a row for the newcomer, filled by the refresh that follows its reset
            stack = getattr(self, name, None)
            if stack is not None:
                setattr(self, name, np.concatenate([stack, np.zeros((1, *stack.shape[1:]), dtype=stack.dtype)]))

    def replace(self, row: int, state: SimState) -> None:
        """Overwrite ``row`` with its world's ``state`` after a reset (same crowd size)."""
        self.state.set_row(row, state)

    def store(self, rows: np.ndarray, measured: Measured) -> None:
        """Keep what a refresh of ``rows`` measured (the stacks are created by the first)."""
        for name, measured_value in zip(_GEOMETRY, measured, strict=True):
            value = cast(np.ndarray, measured_value)  # K worlds measured: every entry an array
            if name in _ROBOT_ROW:
                value = value[:, 0]
            stack = getattr(self, name, None)
            if stack is None:
                stack = np.zeros((len(self), *value.shape[1:]), dtype=value.dtype)
                setattr(self, name, stack)
            stack[rows] = value

    def remove(self, row: int) -> None:
        keep = np.arange(len(self)) != row
        self.world = self.world[keep]
        self.state = self.state.take(keep)
        for name in (g for g in _GEOMETRY if hasattr(self, g)):
            setattr(self, name, getattr(self, name)[keep])
