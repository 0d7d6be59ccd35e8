"""``leog``: local egocentric occupancy grid, rasterized exactly row by row.

The grid is centred on the robot and turns with it: row 0 is the farthest ahead, column 0 the
farthest left, so forward is up when the grid is shown as an image. A cell is occupied when its
centre lies inside a human disc, a round obstacle or a static polygon (the robot itself is not
drawn).

Each grid row is a line of constant forward coordinate in the robot frame. Along that line a
disc covers one interval of columns, and a polygon's inside is where the signed count of edge
crossings to the left (a winding number; edges are oriented so it is +1 inside) is positive.
Both become +1/-1 marks at column boundaries; one cumulative sum along the rows turns the marks
into per-cell counts. The work is proportional to rows x (edges + discs), not to cells x
obstacles, and the test is exact, with no precomputed raster to approximate the static world.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

from crowdnav.scenario.schema import LeogSensor
from crowdnav.sensors.base import Modality, register_modality
from crowdnav.sensors.frames import to_robot_frame
from crowdnav.sensors.static_edges import oriented_edges

if TYPE_CHECKING:
    from crowdnav.simulator import Simulator
    from crowdnav.world import CompiledWorld

OCCUPIED = 255
"""Value of an occupied cell (free cells are 0): uint8 0/255 lets SB3 treat the grid as an image."""


@register_modality
class LeogModality(Modality):
    """Occupancy grid, uint8 of shape (1, H, W): 255 where occupied, 0 where free (``grid > 0`` is the binary map).

    Cell (i, j) has its centre at ``x = (H/2 - i - 0.5) * resolution`` metres ahead of the robot
    and ``y = (W/2 - j - 0.5) * resolution`` metres to its left.
    """

    key = "leog"
    settings_type = LeogSensor

    def __init__(self, world: CompiledWorld, settings: LeogSensor | None = None):
        super().__init__(world, settings)
        self.resolution = float(self.settings.resolution)
        self.cells = round(self.settings.size / self.resolution)
        """Cells per side (H = W)."""
        n, res = self.cells, self.resolution
        self.row_x = (n / 2 - np.arange(n) - 0.5) * res
        """(H,) forward coordinate (m) of each row's cell centres."""
        self.column_y = (n / 2 - np.arange(n) - 0.5) * res
        """(W,) leftward coordinate (m) of each column's cell centres."""
        self._reach = math.hypot(n * res / 2, n * res / 2)  # centre to grid corner
        edges = oriented_edges(world.obstacles.polygons)
        self._edge_start, self._edge_vector = edges.start, edges.vector
        self._has_static_discs = world.obstacles.disc_count > 0
        self._static_disc_radius = world.obstacles.disc_radius

    def make_space(self) -> spaces.Box:
        return spaces.Box(low=0, high=OCCUPIED, shape=(1, self.cells, self.cells), dtype=np.uint8)

    def observe(self, sim: Simulator) -> np.ndarray:
        occupied = self.coverage(sim) > 0
        grid = occupied.view(np.uint8)  # True/False -> 1/0 without a copy
        grid *= OCCUPIED
        return grid.reshape(1, self.cells, self.cells)

    def coverage(self, sim: Simulator) -> np.ndarray:
        """(H, W) float: how many obstacles cover each cell centre (0 = free)."""
        n = self.cells
        rotate = to_robot_frame(sim)
        flat_edges, edge_sign = self._polygon_marks(sim, rotate)
        flat_low, flat_high = self._disc_marks(sim, rotate)
        index = np.concatenate((flat_edges, flat_low, flat_high))
        weight = np.concatenate((edge_sign, np.ones(len(flat_low)), -np.ones(len(flat_high))))
        marks = np.bincount(index, weight, minlength=n * (n + 1)).reshape(n, n + 1)
        return np.cumsum(marks, axis=1)[:, :n]

    def _column(self, y: np.ndarray) -> np.ndarray:
        """Fractional column index whose centre lies at leftward coordinate ``y`` (column j sits at j)."""
        return self.cells / 2 - 0.5 - y / self.resolution

    def _clipped(self, column: np.ndarray) -> np.ndarray:
        return np.clip(column, 0, self.cells).astype(np.intp)

    def _polygon_marks(self, sim: Simulator, rotate: complex) -> tuple[np.ndarray, np.ndarray]:
        """Flat mark indices and signs of every (row, edge) crossing."""
        start = (self._edge_start - complex(sim.positions[0])) * rotate
        end = start + self._edge_vector * rotate
        start_x, end_x = start.real, end.real
        # Half-open rule: an edge crosses row x when exactly one end lies beyond x, so a vertex
        # on the row line is counted once.
        crosses = (start_x > self.row_x[:, None]) != (end_x > self.row_x[:, None])
        row, edge = np.nonzero(crosses)
        sx, sy, ex, ey = start_x[edge], start.imag[edge], end_x[edge], end.imag[edge]
        y = sy + (self.row_x[row] - sx) * (ey - sy) / (ex - sx)  # ex != sx on crossing edges
        # Going backwards (ex < sx) with the solid on the left means the cells to the right are inside.
        sign = np.where(ex < sx, 1.0, -1.0)
        # the crossing counts for the cells right of it: from the first column whose centre is below y
        return row * (self.cells + 1) + self._clipped(np.floor(self._column(y)) + 1.0), sign

    def _disc_marks(self, sim: Simulator, rotate: complex) -> tuple[np.ndarray, np.ndarray]:
        """Flat indices of each (row, disc) chord's first covered column and of the column after its last."""
        offset, distance, radius = sim.pair_offset[0, 1:], sim.pair_distance[0, 1:], sim.radii[1:]
        if self._has_static_discs:
            offset = np.concatenate((offset, sim.disc_offset[0]))
            distance = np.concatenate((distance, sim.disc_distance[0]))
            radius = np.concatenate((radius, self._static_disc_radius))
        near = np.flatnonzero(distance - radius <= self._reach)
        centre, radius = offset[near] * rotate, radius[near]
        half2 = radius**2 - (self.row_x[:, None] - centre.real) ** 2  # squared half chord per (row, disc)
        row, disc = np.nonzero(half2 >= 0.0)
        half = np.sqrt(half2[row, disc])
        cy = centre.imag[disc]
        base = row * (self.cells + 1)
        # covered: the columns whose centre y satisfies cy - half <= y <= cy + half
        low = base + self._clipped(np.ceil(self._column(cy + half)))
        high = base + self._clipped(np.floor(self._column(cy - half)) + 1.0)
        return low, high
