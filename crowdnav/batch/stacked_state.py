"""K worlds' episode states as one: :class:`StackedState`, the state of a bucket of the batched simulator.

A :class:`crowdnav.sim.state.SimState` is one world's (its robot's goal a ``complex``, its step
count an ``int``); the batched simulator keeps the worlds that have the same number of humans as
one :class:`StackedState`, the same fields in the same order, each with a leading world axis (K,).
Rows move between the two with :meth:`StackedState.stack`, :meth:`StackedState.row`,
:meth:`StackedState.set_row`, :meth:`StackedState.append` and :meth:`StackedState.take`. The
meaning, unit and dtype of each field are declared once, in :class:`crowdnav.sim.state.StateFields`,
the base of both (this module adds no field).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from crowdnav.batch.state import ComplexArray, FloatArray, IntArray
from crowdnav.sim.state import ONE_WORLD_SCALARS, SimState, StateFields


@dataclass(eq=False)
class StackedState(StateFields[ComplexArray, FloatArray, IntArray]):
    """K worlds with the same number of humans n, row k being world k.

    Every field of :class:`crowdnav.sim.state.StateFields` with a leading world axis (K,) (the
    robot's goal, heading and step count: (K,) complex128, float64 and int64 arrays).
    """

    @classmethod
    def stack(cls, states: Sequence[SimState]) -> StackedState:
        """Worlds with the same number of humans as one state with a leading world axis, in the given order."""
        return cls(**{f.name: np.stack([np.asarray(getattr(state, f.name)) for state in states]) for f in fields(cls)})

    def row(self, k: int) -> SimState:
        """World ``k``: its arrays are views (writing them writes the stack), its scalars Python numbers."""
        out: dict[str, Any] = {name: value[k] for name, value in self._items()}
        return SimState(**{**out, **{name: convert(out[name]) for name, convert in ONE_WORLD_SCALARS.items()}})

    def set_row(self, k: int, state: SimState) -> None:
        """Overwrite world ``k`` with one world's ``state`` (same number of humans)."""
        for name, value in self._items():
            value[k] = getattr(state, name)

    def append(self, state: SimState) -> StackedState:
        """The worlds with one world's ``state`` added as the last row (new arrays)."""
        return StackedState(**{name: np.concatenate([value, np.asarray(getattr(state, name))[None]]) for name, value in self._items()})

    def take(self, rows: np.ndarray) -> StackedState:
        """The worlds ``rows`` (indices or a bool mask), as new arrays."""
        return StackedState(**{name: value[rows] for name, value in self._items()})

    def _items(self) -> list[tuple[str, np.ndarray]]:
        return [(f.name, getattr(self, f.name)) for f in fields(self)]
