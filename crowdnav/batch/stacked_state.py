"""K worlds' episode states as one: :class:`StackedState`, the state of a bucket of the batched simulator.

A :class:`crowdnav.sim_state.SimState` is one world's (its robot's goal a ``complex``, its step
count an ``int``); the batched simulator keeps the worlds that have the same number of humans as
one :class:`StackedState`, the same fields in the same order, each with a leading world axis (K,).
Rows move between the two with :meth:`StackedState.stack`, :meth:`StackedState.row`,
:meth:`StackedState.set_row`, :meth:`StackedState.append` and :meth:`StackedState.take`. The
meaning, unit and dtype of each field are :class:`crowdnav.sim_state.SimState`'s: declared once
there; a test keeps the two lists of fields equal.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from crowdnav.batch.state import BoolArray, ComplexArray, FloatArray, IntArray
from crowdnav.sim_state import SimState


@dataclass(eq=False)
class StackedState:
    """:class:`crowdnav.sim_state.SimState` of K worlds with the same number of humans n, row k being world k."""

    positions: ComplexArray
    """(K, n+1) complex128, m: :attr:`SimState.positions <crowdnav.sim_state.SimState.positions>` of every world."""
    velocities: ComplexArray
    """(K, n+1) complex128, m/s: ``SimState.velocities`` of every world."""
    robot_goal: ComplexArray
    """(K,) complex128, m: ``SimState.robot_goal`` of every world."""
    robot_heading: FloatArray
    """(K,) float64, rad: ``SimState.robot_heading`` of every world."""
    step_count: IntArray
    """(K,) int64: ``SimState.step_count`` of every world."""
    human_group: IntArray
    """(K, n) int64: ``SimState.human_group`` of every world."""
    human_goals: ComplexArray
    """(K, n) complex128, m: ``SimState.human_goals`` of every world."""
    human_preferred_speed: FloatArray
    """(K, n) float64, m/s: ``SimState.human_preferred_speed`` of every world."""
    human_max_speed: FloatArray
    """(K, n) float64, m/s: ``SimState.human_max_speed`` of every world."""
    command_cap: FloatArray
    """(K, n) float64, m/s: ``SimState.command_cap`` of every world."""
    human_stopped: BoolArray
    """(K, n) bool: ``SimState.human_stopped`` of every world."""
    human_arrived: BoolArray
    """(K, n) bool: ``SimState.human_arrived`` of every world."""
    human_respawns: IntArray
    """(K, n) int64: ``SimState.human_respawns`` of every world."""
    human_stall_mark: FloatArray
    """(K, n) float64, m: ``SimState.human_stall_mark`` of every world."""
    human_stalls: IntArray
    """(K, n) int64: ``SimState.human_stalls`` of every world."""

    @classmethod
    def stack(cls, states: Sequence[SimState]) -> StackedState:
        """Worlds with the same number of humans as one state with a leading world axis, in the given order."""
        return cls(**{f.name: np.stack([np.asarray(getattr(state, f.name)) for state in states]) for f in fields(cls)})

    def row(self, k: int) -> SimState:
        """World ``k``: its arrays are views (writing them writes the stack), its scalars Python numbers."""
        out: dict[str, Any] = {name: value[k] for name, value in self._items()}
        return SimState(**{**out, "robot_goal": complex(out["robot_goal"]), "robot_heading": float(out["robot_heading"]),
                           "step_count": int(out["step_count"])})

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
