"""The room's map as a planner reads it: where the robot's centre may be, and how far the goal is around furniture.

Both come from the compiled world's exact geometry (:attr:`crowdnav.worlds.compiled.CompiledWorld.obstacles`,
the nearest-point kernel the simulator's collision check uses), so a cell the map calls free is
one where the simulator reports no contact with walls or furniture. The distance to the goal is
geodesic (around obstacles) on a grid, computed once per goal by a vectorized wavefront.
"""

from __future__ import annotations

import math

import numpy as np

from crowdnav.errors import CrowdNavError
from crowdnav.worlds.compiled import CompiledWorld
from crowdnav.worlds.obstacles import nearest_on_edges

RASTER = 0.05
"""Spacing (m) of the clearance raster the per-step planners read (:meth:`StaticMap.free` with ``exact=False``)."""
POINT_CHUNK = 4096
"""Points per nearest-point query: bounds the (points x obstacles x edges) temporary to a few MB."""
MAX_MAP_CELLS = 1_000_000
"""Most cells of a planner's grid over the world (the clearance raster, the goal-distance grid): a 50 m x 50 m world at
``RASTER``; a bigger world (or a finer ``map_spacing``) is refused in one line before anything is allocated."""


class MapTooLarge(CrowdNavError, ValueError):
    """A planner's grid over the world would exceed :data:`MAX_MAP_CELLS` (one line: the world, the spacing, the limit)."""


def grid_shape(bounds: tuple[float, float, float, float], spacing: float, what: str) -> tuple[int, int]:
    """``(W, H)`` of a ``spacing`` grid over ``bounds``, or a one-line :class:`MapTooLarge` over ``MAX_MAP_CELLS``."""
    x0, y0, x1, y1 = bounds
    cells = ((x1 - x0) / spacing + 2) * ((y1 - y0) / spacing + 2)  # float first: a tiny spacing overflows to inf, not an int
    if not cells <= MAX_MAP_CELLS:
        raise MapTooLarge(f"{what}: a {x1 - x0:g} m x {y1 - y0:g} m world on a {spacing:g} m grid is {cells:,.0f} cells, "
                          f"over the planners' limit of {MAX_MAP_CELLS:,} (a smaller world or a coarser grid)")
    return int(math.ceil((x1 - x0) / spacing)) + 1, int(math.ceil((y1 - y0) / spacing)) + 1


class StaticMap:
    """Where a robot of radius ``radius`` may stand in ``world``, with ``margin`` metres to spare."""

    def __init__(self, world: CompiledWorld, radius: float, margin: float = 0.0):
        self.world, self.radius, self.margin = world, float(radius), float(margin)
        obstacles = world.obstacles
        self._surface = obstacles.surface if obstacles.polygon_count + obstacles.disc_count else None
        self._surface_radius = obstacles.surface_radius
        box = world.scenario.world
        self.bounds = (float(box.min[0]), float(box.min[1]), float(box.max[0]), float(box.max[1]))
        self._raster: np.ndarray | None = None

    def clearance(self, points: np.ndarray) -> np.ndarray:
        """Surface gap (m) from a robot centred at each point to the nearest wall or furniture (inf without any)."""
        flat = np.asarray(points, dtype=complex).ravel()
        gap = np.full(flat.shape, np.inf)
        if self._surface is not None and len(flat):
            assert self._surface_radius is not None  # build_obstacles sets both
            for lo in range(0, len(flat), POINT_CHUNK):
                _, distance = nearest_on_edges(flat[lo:lo + POINT_CHUNK], self._surface)
                gap[lo:lo + POINT_CHUNK] = (distance - self._surface_radius).min(1) - self.radius
        return gap.reshape(np.shape(points))

    def free(self, points: np.ndarray, exact: bool = True) -> np.ndarray:
        """Whether a robot centred at each point is inside the world and clear of walls and furniture by ``margin``.

        ``exact=False`` reads a raster of clearances (``RASTER`` m, built on first use) instead of
        the exact kernel: the clearance at the nearest raster point minus the distance to it, a lower
        bound (the clearance is 1-Lipschitz), so it never calls a touching point free and is at most
        ``RASTER / sqrt(2)`` m stricter than exact. The per-step planners use it; the oracle does not.
        """
        x0, y0, x1, y1 = self.bounds
        points = np.asarray(points, dtype=complex)
        inside = (points.real >= x0) & (points.real <= x1) & (points.imag >= y0) & (points.imag <= y1)
        if exact:
            return inside & (self.clearance(points) > self.margin)
        if self._raster is None:
            w, h = grid_shape(self.bounds, RASTER, "the planners' clearance raster")
            ii, jj = np.meshgrid(np.arange(w), np.arange(h), indexing="ij")
            self._raster = self.clearance(complex(x0, y0) + (ii + 1j * jj) * RASTER)
        w, h = self._raster.shape
        i = np.clip(np.rint((points.real - x0) / RASTER).astype(np.int64), 0, w - 1)
        j = np.clip(np.rint((points.imag - y0) / RASTER).astype(np.int64), 0, h - 1)
        nearest = complex(x0, y0) + (i + 1j * j) * RASTER
        free: np.ndarray = inside & (self._raster[i, j] - np.abs(points - nearest) > self.margin)
        return free

    def geodesic(self, goal: complex, spacing: float) -> GeodesicField:
        """The distance (m) to ``goal`` around obstacles, on a ``spacing`` grid over the world."""
        return GeodesicField(GoalGrid(self, spacing), complex(goal))


class MapCache:
    """A planner's maps and goal distances, shared by every world of the same scenario (100 test envs load 100 worlds).

    Keyed by the scenario's content, so a planner driving many envs of one scenario builds one
    map; at most ``MAX_MAPS`` maps and ``MAX_FIELDS`` goal distances are kept (oldest dropped).
    """

    MAX_MAPS, MAX_FIELDS, MAX_WORLDS = 8, 512, 4096

    def __init__(self, margin: float, spacing: float = 0.1):
        self.margin, self.spacing = float(margin), float(spacing)
        self._keys: dict[int, tuple[CompiledWorld, str]] = {}
        self._maps: dict[str, StaticMap] = {}
        self._fields: dict[tuple[str, complex], GeodesicField] = {}
        self._grids: dict[str, GoalGrid] = {}

    def key(self, world: CompiledWorld) -> str:
        """The content key of ``world``'s scenario (computed once per world object)."""
        found = self._keys.get(id(world))
        if found is None or found[0] is not world:
            _bounded(self._keys, self.MAX_WORLDS)
            found = self._keys[id(world)] = (world, world.scenario.model_dump_json())
        return found[1]

    def map(self, world: CompiledWorld) -> StaticMap:
        """The map of ``world`` for its robot."""
        key = self.key(world)
        if key not in self._maps:
            _bounded(self._maps, self.MAX_MAPS)
            self._maps[key] = StaticMap(world, world.scenario.robot.radius, self.margin)
        return self._maps[key]

    def field(self, world: CompiledWorld, goal: complex) -> GeodesicField:
        """The geodesic distance to ``goal`` in ``world``."""
        key = (self.key(world), complex(goal))
        if key not in self._fields:
            _bounded(self._fields, self.MAX_FIELDS)
            grid = self._grids.get(key[0])
            if grid is None:
                _bounded(self._grids, self.MAX_MAPS)
                grid = self._grids[key[0]] = GoalGrid(self.map(world), self.spacing)
            self._fields[key] = GeodesicField(grid, complex(goal))
        return self._fields[key]

    def cost(self, world: CompiledWorld, goals: np.ndarray, points: np.ndarray, owner: np.ndarray) -> np.ndarray:
        """Geodesic distance from each point (P,) to the goal of its world ``owner`` (P,), ``goals`` (K,): one lookup."""
        fields = [self.field(world, goal) for goal in np.asarray(goals).tolist()]
        return fields[0].grid.lookup(np.stack([f.distance for f in fields]), points, owner)


def _bounded(cache: dict, size: int) -> None:  # type: ignore[type-arg]
    """Drop the oldest entries of ``cache`` so one more fits in ``size``."""
    while len(cache) >= size:
        cache.pop(next(iter(cache)))


class GoalGrid:
    """The grid goal distances live on: cells over the world and where the robot's centre may be (built once per map)."""

    def __init__(self, static_map: StaticMap, spacing: float):
        x0, y0 = static_map.bounds[:2]
        self.origin, self.spacing = complex(x0, y0), float(spacing)
        w, h = grid_shape(static_map.bounds, spacing, "the goal-distance grid (map_spacing)")
        ii, jj = np.meshgrid(np.arange(w), np.arange(h), indexing="ij")
        self.cells = self.origin + (ii + 1j * jj) * spacing
        self.free = static_map.free(self.cells)
        blocked = np.where(self.free, 0.0, np.inf)
        # per neighbour: (where it lands, where it comes from, the cost of entering each landing cell)
        self.steps = []
        for di, dj in _NEIGHBOURS:
            dst = (slice(max(0, di), w + min(0, di)), slice(max(0, dj), h + min(0, dj)))
            src = (slice(max(0, -di), w + min(0, -di)), slice(max(0, -dj), h + min(0, -dj)))
            self.steps.append((dst, src, blocked[dst] + spacing * math.hypot(di, dj)))

    def index(self, point: complex) -> tuple[int, int]:
        """The cell nearest ``point`` (clipped to the grid)."""
        w, h = self.free.shape
        rel = (point - self.origin) / self.spacing
        return min(max(int(round(rel.real)), 0), w - 1), min(max(int(round(rel.imag)), 0), h - 1)

    def lookup(self, distance: np.ndarray, points: np.ndarray, world: np.ndarray) -> np.ndarray:
        """Distances (K, W, H) read at ``points`` of worlds ``world`` (same shape): the best of the four surrounding
        cells plus the straight step to it."""
        points = np.asarray(points, dtype=complex)
        rel = (points - self.origin) / self.spacing
        w, h = self.free.shape
        i0 = np.clip(np.floor(rel.real).astype(np.int64), 0, w - 2)
        j0 = np.clip(np.floor(rel.imag).astype(np.int64), 0, h - 2)
        best = np.full(rel.shape, np.inf)
        for di in (0, 1):
            for dj in (0, 1):
                i, j = i0 + di, j0 + dj
                best = np.minimum(best, distance[world, i, j] + np.abs(self.cells[i, j] - points))
        return best


class GeodesicField:
    """Shortest-path distance to one goal over a grid's free cells (8-connected, computed at construction)."""

    def __init__(self, grid: GoalGrid, goal: complex):
        self.grid = grid
        gi, gj = grid.index(goal)
        distance = np.full(grid.free.shape, np.inf)
        distance[gi, gj] = abs(grid.cells[gi, gj] - goal)  # the goal's own cell seeds the wave even when it sits in the margin
        self.distance = _relax(distance, grid)

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """Distance (m) to the goal from each point."""
        points = np.asarray(points, dtype=complex)
        return self.grid.lookup(self.distance[None], points, np.zeros(points.shape, dtype=np.int64))


_NEIGHBOURS = [(di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj]


def _relax(distance: np.ndarray, grid: GoalGrid) -> np.ndarray:
    """Bellman-Ford on the 8-connected grid of free cells, whole-array updates until nothing changes."""
    while True:
        before = distance.copy()
        for dst, src, enter in grid.steps:
            np.minimum(distance[dst], distance[src] + enter, out=distance[dst])
        if np.array_equal(before, distance):
            return distance
