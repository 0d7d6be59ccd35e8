"""``humans.routing: geodesic``: walking humans steer along the room's shortest path to their goal, not straight at it.

The goal force's desired direction becomes the steepest descent of the geodesic distance to the
goal around walls and furniture (the planners' wavefront, :mod:`crowdnav.planning.static_map`, on
the cells where a human's centre may stand), so humans turn corners and walk around benches
instead of pressing against them. A human that sees its goal (the straight segment to it stays
clear of obstacles by its radius) keeps the straight goal force exactly; routing changes only the
humans whose straight line is blocked.

One :class:`Router` serves every simulator of a compiled world (the batched simulator's worlds
share it). Per goal *cell* of a ``SPACING`` grid it keeps the distance to that cell, the descent
direction and whether the cell sees the goal, in a pool of slots (least recently used dropped,
``POOL_BYTES`` at most unless one step needs more goals at once). A field depends only on its goal
cell, so what the pool holds never changes a command: the same seed gives the same episode
whatever ran before, and world k of a batch equals the single simulator bit for bit.
"""

from __future__ import annotations

import math

import numpy as np

from crowdnav.planning.static_map import GeodesicField, GoalGrid, StaticMap
from crowdnav.worlds.compiled import CompiledWorld

SPACING = 0.1
"""Grid spacing (m) of the humans' goal distances (the planners' ``map_spacing``): passages down to ~2 radii + 0.1 m are found."""
POOL_BYTES = 64 * 2**20
"""The pool's size: this many bytes of fields (a 12 m x 12 m room: ~180 goal cells; a 50 m x 50 m world: ~7)."""
KEEP_OFF = 0.2
"""Routes keep this far (m, surface gap) from walls and furniture where the room allows: people do not brush corners, and two
groups meeting at an inner corner have room to pass (a passage narrower than 2 radii + this is routed through its band)."""
BAND_COST = 3.0
"""A step in the band beside obstacles (closer than ``KEEP_OFF``) costs this many times its length: the band leads back out
to the routes, it never shortens one."""
MAX_ROUTERS = 8
"""Routers kept for the most recently used compiled worlds (each holds its pool)."""

_ROUTERS: dict[int, tuple[CompiledWorld, Router]] = {}


def router_for(world: CompiledWorld) -> Router:
    """The router of ``world`` (one per compiled world object, built on first use; the oldest of ``MAX_ROUTERS`` dropped)."""
    found = _ROUTERS.get(id(world))
    if found is None or found[0] is not world:
        while len(_ROUTERS) >= MAX_ROUTERS:
            _ROUTERS.pop(next(iter(_ROUTERS)))
        found = _ROUTERS[id(world)] = (world, Router(world))
    return found[1]


class Router:
    """Routed goal vectors for the humans of one compiled world (built lazily: the map on the first call)."""

    def __init__(self, world: CompiledWorld):
        self.world = world
        self._grid: GoalGrid | None = None

    def _setup(self) -> GoalGrid:
        humans = self.world.scenario.humans
        grid = self._grid = GoalGrid(StaticMap(self.world, humans.radius, KEEP_OFF), SPACING)
        w, h = grid.free.shape
        # cells a centre can reach at all (not inside an obstacle): a human pushed against a bench stands in this band
        body = StaticMap(self.world, 0.0).free(grid.cells)
        band = np.where(body, 0.0, np.inf)
        self._band_steps = [(dst, src, band[dst] + BAND_COST * spacing) for (dst, src, _), spacing in
                            zip(grid.steps, (SPACING * math.hypot(di, dj) for di, dj in _NEIGHBOURS), strict=True)]
        self._slot_of = np.full(w * h, -1, dtype=np.int64)  # goal cell -> pool slot
        self._cell_of = np.zeros(0, dtype=np.int64)  # slot -> goal cell
        self._used = np.zeros(0, dtype=np.int64)  # slot -> last call that read it
        self._calls = 0
        self._capacity = max(1, POOL_BYTES // (w * h * (8 + 16 + 1)))
        self._distance = np.zeros((0, w, h))
        self._direction = np.zeros((0, w, h), dtype=complex)
        self._visible = np.zeros((0, w, h), dtype=bool)
        return grid

    @property
    def fields(self) -> int:
        """Goal cells whose fields the pool holds now."""
        return int((self._slot_of >= 0).sum()) if self._grid is not None else 0

    def to_goal(self, humans: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """The goal force's ``to_goal`` (any shape, complex m): ``goals - humans`` where a human sees its goal, else the descent
        direction times the geodesic distance (at least the straight one); straight too where the map gives no way."""
        grid = self._grid or self._setup()
        straight: np.ndarray = goals - humans
        w, h = grid.free.shape
        slot = self._slots(_cell(goals, grid, w, h))
        i, j = _index(humans, grid, w, h)
        distance = self._distance[slot, i, j]
        direction = self._direction[slot, i, j]
        keep = self._visible[slot, i, j] | ~np.isfinite(distance) | (direction == 0)
        routed: np.ndarray = np.where(keep, straight, direction * np.maximum(np.where(keep, 0.0, distance), np.abs(straight)))
        return routed

    def _slots(self, cells: np.ndarray) -> np.ndarray:
        """The pool slot of each goal cell, computing the fields of cells not in the pool (one per new goal cell)."""
        self._calls += 1
        slot: np.ndarray = self._slot_of[cells]
        self._used[slot[slot >= 0]] = self._calls  # before any new field takes a slot: this call's goals stay
        if (slot < 0).any():
            for cell in np.unique(cells[slot < 0]).tolist():  # per new goal cell: a wavefront
                self._add(int(cell))
            slot = self._slot_of[cells]
        return slot

    def _add(self, cell: int) -> None:
        """Compute goal cell ``cell``'s field into a free slot, the least recently used one, or a new one."""
        free = np.flatnonzero(self._cell_of < 0)
        if len(free):
            slot = int(free[0])
        elif len(self._cell_of) < self._capacity or self._used.min() >= self._calls:  # full of this call's goals: grow
            slot = len(self._cell_of)
            self._grow()
        else:
            slot = int(np.argmin(self._used))
            self._slot_of[self._cell_of[slot]] = -1
        distance, direction, visible = self._field(cell)
        self._distance[slot], self._direction[slot], self._visible[slot] = distance, direction, visible
        self._cell_of[slot], self._slot_of[cell], self._used[slot] = cell, slot, self._calls

    def _grow(self) -> None:
        more = max(1, min(len(self._cell_of), self._capacity - len(self._cell_of)))
        self._cell_of = np.concatenate([self._cell_of, np.full(more, -1, dtype=np.int64)])
        self._used = np.concatenate([self._used, np.zeros(more, dtype=np.int64)])
        self._distance = np.concatenate([self._distance, np.zeros((more, *self._distance.shape[1:]))])
        self._direction = np.concatenate([self._direction, np.zeros((more, *self._direction.shape[1:]), dtype=complex)])
        self._visible = np.concatenate([self._visible, np.zeros((more, *self._visible.shape[1:]), dtype=bool)])

    def _field(self, cell: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Goal cell ``cell``: (distance (W, H) m, descent direction (W, H) unit complex or 0, whether each cell sees it)."""
        grid = self._grid
        assert grid is not None
        w, h = grid.free.shape
        goal = complex(grid.cells[cell // h, cell % h])
        free = GeodesicField(grid, goal).distance
        # the band next to obstacles continues the free cells' distances (they keep theirs: no path hugs a bench)
        distance = np.where(grid.free, free, np.inf)
        distance.flat[cell] = free.flat[cell]
        banded = _relax(distance.copy(), self._band_steps)
        distance = np.where(grid.free, distance, banded)
        return distance, _descent(distance), _sees(grid, goal)


_NEIGHBOURS = [(di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj]  # the order of GoalGrid.steps


def _relax(distance: np.ndarray, steps: list[tuple[tuple[slice, slice], tuple[slice, slice], np.ndarray]]) -> np.ndarray:
    """Bellman-Ford over ``steps`` (where a move lands, where it starts, its cost), whole-array updates until nothing changes."""
    while True:
        before = distance.copy()
        for dst, src, enter in steps:
            np.minimum(distance[dst], distance[src] + enter, out=distance[dst])
        if np.array_equal(before, distance):
            return distance


def _descent(distance: np.ndarray) -> np.ndarray:
    """(W, H) complex: minus the distance's gradient, normalised (central differences, one-sided beside a blocked cell; 0: none)."""
    gradient = []
    for axis in (0, 1):
        padded = np.moveaxis(np.pad(distance, [(1, 1) if a == axis else (0, 0) for a in (0, 1)], constant_values=np.inf), axis, 0)
        with np.errstate(invalid="ignore"):  # inf - inf beside blocked cells: no difference that way
            ahead, behind = padded[2:] - padded[1:-1], padded[1:-1] - padded[:-2]
        ahead, behind = np.where(np.isfinite(ahead), ahead, np.nan), np.where(np.isfinite(behind), behind, np.nan)
        both = np.where(np.isnan(ahead), behind, np.where(np.isnan(behind), ahead, (ahead + behind) / 2))
        gradient.append(np.moveaxis(np.nan_to_num(both, nan=0.0), 0, axis))
    descent = -(gradient[0] + 1j * gradient[1])
    length = np.abs(descent)
    unit: np.ndarray = np.where(length > 0, descent / np.where(length > 0, length, 1.0), 0.0)
    return unit


def _sees(grid: GoalGrid, goal: complex) -> np.ndarray:
    """(W, H) bool: the straight segment from each cell to ``goal`` stays on free cells (sampled at most a cell apart; the
    goal's own cell may be in the band beside an obstacle)."""
    cells = grid.cells
    span = np.abs(goal - cells)
    samples = max(1, int(math.ceil(float(span.max()) / grid.spacing)))
    w, h = grid.free.shape
    sees: np.ndarray = grid.free.copy()
    for k in range(1, samples):  # per sample along the segments: all cells at once
        i, j = _index(cells + (goal - cells) * (k / samples), grid, w, h)
        sees &= grid.free[i, j] | (span * (1 - k / samples) < grid.spacing)
    return sees


def _index(points: np.ndarray, grid: GoalGrid, w: int, h: int) -> tuple[np.ndarray, np.ndarray]:
    """The grid cell nearest each point (clipped to the grid)."""
    rel = (points - grid.origin) / grid.spacing
    return (np.clip(np.rint(rel.real), 0, w - 1).astype(np.int64), np.clip(np.rint(rel.imag), 0, h - 1).astype(np.int64))


def _cell(points: np.ndarray, grid: GoalGrid, w: int, h: int) -> np.ndarray:
    """The flat index of the cell nearest each point."""
    i, j = _index(points, grid, w, h)
    flat: np.ndarray = i * h + j
    return flat
