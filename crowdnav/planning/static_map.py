"""The room's map as a planner reads it: where the robot's centre may be, and how far the goal is around furniture.

Both come from the compiled world's exact geometry (:attr:`crowdnav.world.CompiledWorld.obstacles`,
the nearest-point kernel the simulator's collision check uses), so a cell the map calls free is
one where the simulator reports no contact with walls or furniture. The distance to the goal is
geodesic (around obstacles) on a grid, computed once per goal by a vectorized wavefront.
"""

from __future__ import annotations

import math

import numpy as np

from crowdnav.obstacles import nearest_on_edges
from crowdnav.world import CompiledWorld

POINT_CHUNK = 4096
"""Points per nearest-point query: bounds the (points x obstacles x edges) temporary to a few MB."""


class StaticMap:
    """Where a robot of radius ``radius`` may stand in ``world``, with ``margin`` metres to spare."""

    def __init__(self, world: CompiledWorld, radius: float, margin: float = 0.0):
        self.world, self.radius, self.margin = world, float(radius), float(margin)
        obstacles = world.obstacles
        self._surface = obstacles.surface if obstacles.polygon_count + obstacles.disc_count else None
        self._surface_radius = obstacles.surface_radius
        box = world.scenario.world
        self.bounds = (float(box.min[0]), float(box.min[1]), float(box.max[0]), float(box.max[1]))

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

    def free(self, points: np.ndarray) -> np.ndarray:
        """Whether a robot centred at each point is inside the world and clear of walls and furniture by ``margin``."""
        x0, y0, x1, y1 = self.bounds
        points = np.asarray(points, dtype=complex)
        inside = (points.real >= x0) & (points.real <= x1) & (points.imag >= y0) & (points.imag <= y1)
        return inside & (self.clearance(points) > self.margin)

    def geodesic(self, goal: complex, spacing: float) -> GeodesicField:
        """The distance (m) to ``goal`` around obstacles, on a ``spacing`` grid over the world."""
        return GeodesicField(self, complex(goal), spacing)


class GeodesicField:
    """Shortest-path distance to one goal over a map's free cells (8-connected grid, computed at construction)."""

    def __init__(self, static_map: StaticMap, goal: complex, spacing: float):
        self.world = static_map.world
        x0, y0, x1, y1 = static_map.bounds
        self.origin, self.spacing = complex(x0, y0), float(spacing)
        w, h = int(math.ceil((x1 - x0) / spacing)) + 1, int(math.ceil((y1 - y0) / spacing)) + 1
        ii, jj = np.meshgrid(np.arange(w), np.arange(h), indexing="ij")
        self.cells = self.origin + (ii + 1j * jj) * spacing
        free = static_map.free(self.cells)
        gi = min(max(int(round((goal.real - x0) / spacing)), 0), w - 1)
        gj = min(max(int(round((goal.imag - y0) / spacing)), 0), h - 1)
        distance = np.full((w, h), np.inf)
        distance[gi, gj] = abs(self.cells[gi, gj] - goal)
        free[gi, gj] = True  # the goal's own cell seeds the wave even when it sits in the margin
        self.distance = _relax(distance, free, spacing)

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """Distance (m) to the goal from each point: the best of its four surrounding cells plus the straight step to it."""
        rel = (np.asarray(points, dtype=complex) - self.origin) / self.spacing
        w, h = self.distance.shape
        i0 = np.clip(np.floor(rel.real).astype(np.int64), 0, w - 2)
        j0 = np.clip(np.floor(rel.imag).astype(np.int64), 0, h - 2)
        best = np.full(rel.shape, np.inf)
        for di in (0, 1):
            for dj in (0, 1):
                i, j = i0 + di, j0 + dj
                best = np.minimum(best, self.distance[i, j] + np.abs(self.cells[i, j] - points))
        return best


_NEIGHBOURS = [(di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj]


def _relax(distance: np.ndarray, free: np.ndarray, spacing: float) -> np.ndarray:
    """Bellman-Ford on the 8-connected grid of ``free`` cells, whole-array updates until nothing changes."""
    w, h = distance.shape
    while True:
        before = distance.copy()
        for di, dj in _NEIGHBOURS:
            step = spacing * math.hypot(di, dj)
            dst = (slice(max(0, di), w + min(0, di)), slice(max(0, dj), h + min(0, dj)))
            src = (slice(max(0, -di), w + min(0, -di)), slice(max(0, -dj), h + min(0, -dj)))
            np.minimum(distance[dst], np.where(free[dst], distance[src] + step, np.inf), out=distance[dst])
        if np.array_equal(before, distance):
            return distance
