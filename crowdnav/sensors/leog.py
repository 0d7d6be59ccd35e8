"""``leog``: local egocentric occupancy grid, rasterized exactly row by row.

The grid is centred on the robot and turns with it: row 0 is the farthest ahead, column 0 the
farthest left, so forward is up when the grid is shown as an image. A cell is occupied when its
centre lies inside a human disc, a round obstacle or a static polygon (the robot itself is not
drawn).

Each grid row is a line of constant forward coordinate in the robot frame. Along that line a
disc covers one interval of columns, and a polygon's inside is where the signed count of its
edges crossed to the left (a winding number; edges are oriented so that it is +1 inside) is
positive. Both become +1/-1 marks at column boundaries, and one cumulative sum turns the marks
into per-cell counts. Every edge and disc is paired only with the run of rows it spans, so the
work grows with rows x nearby obstacles, not with cells x obstacles; the test is exact, with no
precomputed raster approximating the static world.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

from crowdnav.batch.scalar_math import cmul
from crowdnav.scenario.schema import LeogSensor
from crowdnav.sensors.base import Modality, RadiiConstants, register_modality
from crowdnav.sensors.runs import expand_runs
from crowdnav.sensors.static_edges import oriented_edges

if TYPE_CHECKING:
    from crowdnav.batch.state import BatchState
    from crowdnav.sim.robot_view import RobotWorld
    from crowdnav.worlds.compiled import CompiledWorld

OCCUPIED = 255
"""Value of an occupied cell (free cells are 0): uint8 0/255 lets SB3 treat the grid as an image."""


@register_modality
class LeogModality(Modality):
    """Occupancy grid, uint8 of shape (1, H, W): 255 where occupied, 0 where free (``grid > 0`` is the binary map).

    Cell (i, j) has its centre at ``x = (H/2 - i - 0.5) * resolution`` metres ahead of the robot
    and ``y = (W/2 - j - 0.5) * resolution`` metres to its left. Scale: the Box default, 255
    (normalised: 0/1); the agents pass the uint8 grid on unscaled (their CNN reads ``grid > 0``).
    """

    key = "leog"
    settings_type = LeogSensor

    def __init__(self, world: CompiledWorld, settings: LeogSensor | None = None):
        super().__init__(world, settings)
        self.resolution = float(self.settings.resolution)
        self.cells = round(self.settings.size / self.resolution)
        """Cells per side (H = W)."""
        edges = oriented_edges(world.obstacles.polygons)
        self._edge_count = edges.count
        self._edge_start, self._edge_end = edges.start, edges.start + edges.vector
        obstacles = world.obstacles
        self._static_disc_center = obstacles.disc_center
        self._static_disc_radius = obstacles.disc_radius
        self._ones = self._minus_ones = np.zeros(0, dtype=np.int32)
        """+1 and -1 chord marks, grown on demand."""
        self._disc_constants = RadiiConstants(self._constants_for)
        """radii -> (2, n + C) disc radii in cells as [-r, +r], and (n + C,) their squares; humans first."""
        self._grid_origin = complex(self.cells / 2 + 0.5, self.cells / 2 + 0.5)
        self._marks = np.zeros(0, dtype=np.int32)  # scratch of running_counts, grown on demand

    def make_space(self) -> spaces.Box:
        return spaces.Box(low=0, high=OCCUPIED, shape=(1, self.cells, self.cells), dtype=np.uint8)

    def observe(self, sim: RobotWorld) -> np.ndarray:
        n = self.cells
        occupied = self.running_counts(sim.positions, sim.robot_heading, sim.radii) > 0
        grid = occupied.view(np.uint8)  # True/False -> 1/0 without a copy
        np.negative(grid, out=grid)  # 1 -> 255 in uint8 arithmetic
        return grid.reshape(n, n + 1)[:, :n].reshape(1, n, n)

    def observe_batch(self, state: BatchState) -> np.ndarray:
        n, worlds = self.cells, state.worlds
        counts = self.running_counts(state.positions, state.robot_heading, state.radii).reshape(worlds, n, n + 1)[:, :, :n]
        grid = np.empty((worlds, 1, n, n), dtype=np.uint8)
        np.greater(counts, 0, out=grid.view(np.bool_)[:, 0])
        np.negative(grid, out=grid)  # True/False -> 255/0, as observe
        return grid

    @np.errstate(divide="ignore", invalid="ignore")  # slopes of edges parallel to the rows are never used
    def running_counts(self, positions: np.ndarray, heading: float | np.ndarray, radii: np.ndarray) -> np.ndarray:
        """The grid kernel: ``(W * H * (W + 1),)`` int32 cover counts, world after world and row after row.

        ``positions``: ``(*W, n+1)`` complex, robot first; ``heading``: ``W``-shaped; ``radii``:
        (n+1,), shared by the worlds. ``W`` is ``(K,)`` for K worlds (``observe_batch``) or ``()``
        for one (``observe``: no world axis, so one world pays no numpy overhead for it). Column W
        of each row is a spare (always 0). World k's counts depend on world k alone, bit for bit:
        its rows are rows k * H ... of one tall grid, and the (primitive, row) pairs of all worlds
        form one flat list, every world's edges before every world's discs, so one scatter-add and
        one cumulative sum do them all. Returns a view of a scratch buffer, overwritten by the next call.
        """
        batched, n, edges = positions.ndim == 2, self.cells, self._edge_count
        worlds = len(positions) if batched else 1
        discs = positions.shape[-1] - 1 + len(self._static_disc_radius)
        # Grid coordinates (v, u) = (n/2 + 0.5 - x / resolution, n/2 + 0.5 - y / resolution), as
        # one complex number v + iu, for [edge ends, edge starts, disc centres]. Row i's centre
        # line is v = i + 1, and the first column whose centre lies strictly right of (below) a
        # point at u is floor(u).
        scale, shift = self._grid_transform(positions, heading, batched)
        z = self._primitive_points(positions)
        z *= scale  # numpy's complex multiply: the same bits for a Python complex or a (K, 1) array of it
        z += shift
        end, start, centre = z[..., :edges], z[..., edges : 2 * edges], z[..., 2 * edges :]
        radius_span, radius2 = self._disc_constants(radii)

        # Each edge and disc is paired with the run of rows whose centre line v = i + 1 falls in
        # its span [v0, v1): floor(v0) <= i < floor(v1). The half-open rule counts a polygon
        # vertex lying on a row line exactly once (both its edges see the same v).
        if batched:  # (2, primitive): every world's edges, then every world's discs
            edge_span = np.sort(z.real[:, : 2 * edges].reshape(worlds, 2, edges), axis=1)
            disc_span = centre.real[:, None, :] + radius_span
            span = np.concatenate((edge_span.transpose(1, 0, 2).reshape(2, -1), disc_span.transpose(1, 0, 2).reshape(2, -1)), axis=1)
        else:
            span = np.concatenate((np.sort(z.real[: 2 * edges].reshape(2, edges), axis=0), centre.real + radius_span), axis=1)
        np.maximum(span, 0.0, out=span)
        np.minimum(span, n, out=span)
        first, stop = span.astype(np.intp)  # floor: the values are >= 0
        count = stop - first
        row, ends = expand_runs(first, count)
        edge_count = worlds * edges
        edge_pairs = int(ends[edge_count - 1]) if edge_count else 0

        # Per-primitive data reaches the pairs with one repeat each: the start (edges) or centre
        # (discs) shifted to v - 1, so that v - 1 - row is a pair's v offset from its row line;
        # du per row (edges) or r^2 (discs); and each edge's crossing sign. With the solid on the
        # left of every edge, an edge running backwards (towards -x, i.e. increasing v) has the
        # inside on its right: +1 for the cells right of its crossing, -1 for one running
        # forwards (an edge with constant v never crosses a row).
        delta = end - start
        if batched:
            anchor = np.concatenate(((start - 1.0).ravel(), (centre - 1.0).ravel())).repeat(count)
            shape = np.concatenate(((delta.imag / delta.real).ravel(), np.tile(radius2, worlds))).repeat(count)
        else:
            anchor = (z[edges:] - 1.0).repeat(count)
            shape = np.concatenate((delta.imag / delta.real, radius2)).repeat(count)
        edge_sign = np.sign(delta.real).astype(np.int32).ravel().repeat(count[:edge_count])
        offset = row - anchor.real  # from the primitive's anchor to the row line, in rows

        # Edges: the crossing's u on each row; it counts for the cells right of it.
        crossing = offset[:edge_pairs] * shape[:edge_pairs]
        crossing += anchor.imag[:edge_pairs]
        # Discs: a chord adds +1 from its left end (smaller u) and -1 from its right end.
        half = offset[edge_pairs:]
        half *= half
        np.subtract(shape[edge_pairs:], half, out=half)
        np.maximum(half, 0.0, out=half)  # guards rounding at the disc's top and bottom rows
        np.sqrt(half, out=half)
        middle = anchor.imag[edge_pairs:]

        u = np.concatenate((crossing, middle - half, middle + half))
        np.maximum(u, 0.0, out=u)
        np.minimum(u, n, out=u)
        if batched:  # row of the tall grid
            row += np.concatenate((np.arange(0, worlds * n, n).repeat(edges), np.arange(0, worlds * n, n).repeat(discs))).repeat(count)
        flat = np.concatenate((row, row[edge_pairs:]))
        flat *= n + 1
        flat += u.astype(np.intp)
        chords = len(row) - edge_pairs
        if len(self._ones) < chords:
            self._ones = np.ones(chords, dtype=np.int32)
            self._minus_ones = -self._ones
        sign = np.concatenate((edge_sign, self._ones[:chords], self._minus_ones[:chords]))
        # int32 (a count never exceeds the number of primitives) in a buffer kept between calls:
        # a fresh grid-sized array per call costs more in page faults than the marks themselves
        size = worlds * n * (n + 1)
        if len(self._marks) < size:
            self._marks = np.zeros(size, dtype=np.int32)
        marks = self._marks[:size]
        marks.fill(0)
        np.add.at(marks, flat, sign)
        # Every row's marks sum to zero (each primitive enters and leaves it, column W included),
        # so one flat cumulative sum over the rows restarts at zero on each row.
        return np.add.accumulate(marks, out=marks)  # in place

    def _grid_transform(self, positions: np.ndarray, heading: float | np.ndarray, batched: bool) -> tuple[complex | np.ndarray, complex | np.ndarray]:
        """``scale = to_robot_frame * (-1 / resolution)`` and ``shift = grid_origin - robot * scale``, per world.

        One world: Python complex math; K worlds: (K, 1) complex arrays of the same bits, the
        scalar math emulated with real arrays (:mod:`crowdnav.batch.scalar_math`).
        """
        if not batched:
            scale = complex(math.cos(heading), -math.sin(heading)) * (-1.0 / self.resolution)
            return scale, self._grid_origin - complex(positions[0]) * scale
        scale_re, scale_im = cmul(np.cos(heading), -np.sin(heading), -1.0 / self.resolution, 0.0)
        robot = positions[:, 0]
        robot_re, robot_im = cmul(robot.real, robot.imag, scale_re, scale_im)
        scales, shifts = np.empty((len(positions), 1), dtype=complex), np.empty((len(positions), 1), dtype=complex)
        scales.real[:, 0], scales.imag[:, 0] = scale_re, scale_im
        shifts.real[:, 0], shifts.imag[:, 0] = self._grid_origin.real - robot_re, self._grid_origin.imag - robot_im
        return scales, shifts

    def _primitive_points(self, positions: np.ndarray) -> np.ndarray:
        """``(*W, 2E + n + C)`` complex, world frame: [edge ends, edge starts, humans, round obstacles] per world."""
        if positions.ndim == 1:
            return np.concatenate((self._edge_end, self._edge_start, positions[1:], self._static_disc_center))
        edges, n = self._edge_count, positions.shape[1] - 1
        z = np.empty((len(positions), 2 * edges + n + len(self._static_disc_radius)), dtype=complex)
        z[:, :edges], z[:, edges : 2 * edges] = self._edge_end, self._edge_start
        z[:, 2 * edges : 2 * edges + n] = positions[:, 1:]
        z[:, 2 * edges + n :] = self._static_disc_center
        return z

    def _constants_for(self, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        radius = np.concatenate((radii[1:], self._static_disc_radius)) / self.resolution
        return np.stack((-radius, radius)), radius**2
