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

from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

from crowdnav.batch.scalar_math import cmul
from crowdnav.scenario.schema import LeogSensor
from crowdnav.sensors.base import Modality, RadiiConstants, register_modality
from crowdnav.sensors.frames import to_robot_frame, to_robot_frame_batch
from crowdnav.sensors.runs import expand_runs
from crowdnav.sensors.static_edges import oriented_edges

if TYPE_CHECKING:
    from crowdnav.batch.state import BatchState
    from crowdnav.simulator import Simulator
    from crowdnav.world import CompiledWorld

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
        n, res = self.cells, self.resolution
        self.row_x = (n / 2 - np.arange(n) - 0.5) * res
        """(H,) forward coordinate (m) of each row's cell centres."""
        self.column_y = (n / 2 - np.arange(n) - 0.5) * res
        """(W,) leftward coordinate (m) of each column's cell centres."""
        edges = oriented_edges(world.obstacles.polygons)
        self._edge_count = edges.count
        self._edge_start, self._edge_end = edges.start, edges.start + edges.vector
        obstacles = world.obstacles
        self._static_disc_center = obstacles.disc_center
        self._static_disc_radius = obstacles.disc_radius
        self._ones = self._minus_ones = np.zeros(0, dtype=np.intp)
        self._disc_constants = RadiiConstants(self._constants_for)
        """radii -> (2, n + C) disc radii in cells as [-r, +r], and (n + C,) their squares; humans first."""
        self._grid_origin = complex(n / 2 + 0.5, n / 2 + 0.5)
        self._batch_marks = np.zeros(0, dtype=np.int32)  # scratch of _running_counts_batch, grown on demand

    def make_space(self) -> spaces.Box:
        return spaces.Box(low=0, high=OCCUPIED, shape=(1, self.cells, self.cells), dtype=np.uint8)

    def observe(self, sim: Simulator) -> np.ndarray:
        n = self.cells
        occupied = self._running_counts(sim) > 0
        grid = occupied.view(np.uint8)  # True/False -> 1/0 without a copy
        np.negative(grid, out=grid)  # 1 -> 255 in uint8 arithmetic
        return grid.reshape(n, n + 1)[:, :n].reshape(1, n, n)

    def observe_batch(self, state: BatchState) -> np.ndarray:
        n, worlds = self.cells, state.worlds
        counts = self._running_counts_batch(state).reshape(worlds, n, n + 1)[:, :, :n]
        grid = np.empty((worlds, 1, n, n), dtype=np.uint8)
        np.greater(counts, 0, out=grid.view(np.bool_)[:, 0])
        np.negative(grid, out=grid)  # True/False -> 255/0, as observe
        return grid

    def coverage(self, sim: Simulator) -> np.ndarray:
        """(H, W) int: how many obstacles cover each cell centre (0 = free)."""
        n = self.cells
        return self._running_counts(sim).reshape(n, n + 1)[:, :n]

    @np.errstate(divide="ignore", invalid="ignore")  # slopes of edges parallel to the rows are never used
    def _running_counts(self, sim: Simulator) -> np.ndarray:
        """(H * (W + 1),) cover counts row after row; column W of each row is a spare (always 0)."""
        n, edges = self.cells, self._edge_count
        # Grid coordinates (v, u) = (n/2 + 0.5 - x / resolution, n/2 + 0.5 - y / resolution), as
        # one complex number v + iu, for [edge ends, edge starts, disc centres]. Row i's centre
        # line is v = i + 1, and the first column whose centre lies strictly right of (below) a
        # point at u is floor(u).
        scale = to_robot_frame(sim) * (-1.0 / self.resolution)
        z = np.concatenate((self._edge_end, self._edge_start, sim.positions[1:], self._static_disc_center))
        z *= scale
        z += self._grid_origin - complex(sim.positions[0]) * scale
        end, start, centre = z[:edges], z[edges : 2 * edges], z[2 * edges :]
        radius_span, radius2 = self._disc_constants(sim.radii)

        # Each edge and disc is paired with the run of rows whose centre line v = i + 1 falls in
        # its span [v0, v1): floor(v0) <= i < floor(v1). The half-open rule counts a polygon
        # vertex lying on a row line exactly once (both its edges see the same v).
        span = np.concatenate((np.sort(z.real[: 2 * edges].reshape(2, edges), axis=0), centre.real + radius_span), axis=1)
        np.maximum(span, 0.0, out=span)
        np.minimum(span, n, out=span)
        first, stop = span.astype(np.intp)  # floor: the values are >= 0
        count = stop - first
        row, ends = expand_runs(first, count)
        edge_pairs = int(ends[edges - 1]) if edges else 0

        # Per-primitive data reaches the pairs with one repeat each: the start (edges) or centre
        # (discs) shifted to v - 1, so that v - 1 - row is a pair's v offset from its row line;
        # du per row (edges) or r^2 (discs); and each edge's crossing sign. With the solid on the
        # left of every edge, an edge running backwards (towards -x, i.e. increasing v) has the
        # inside on its right: +1 for the cells right of its crossing, -1 for one running
        # forwards (an edge with constant v never crosses a row).
        delta = end - start
        anchor = (z[edges:] - 1.0).repeat(count)
        shape = np.concatenate((delta.imag / delta.real, radius2)).repeat(count)
        edge_sign = np.sign(delta.real).astype(np.intp).repeat(count[:edges])
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
        disc_row = row[edge_pairs:]

        u = np.concatenate((crossing, middle - half, middle + half))
        np.maximum(u, 0.0, out=u)
        np.minimum(u, n, out=u)
        flat = np.concatenate((row, disc_row))
        flat *= n + 1
        flat += u.astype(np.intp)
        chords = len(disc_row)
        sign = np.concatenate((edge_sign, self._ones[:chords], self._minus_ones[:chords]))
        marks = np.zeros(n * (n + 1), dtype=np.intp)
        np.add.at(marks, flat, sign)
        # Every row's marks sum to zero (each primitive enters and leaves it, column W included),
        # so one flat cumulative sum over the rows restarts at zero on each row.
        return marks.cumsum()

    def _constants_for(self, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        radius = np.concatenate((radii[1:], self._static_disc_radius)) / self.resolution
        # a disc spans at most 2 r / resolution + 1 rows: enough +1/-1 chord marks for all of them
        chords = int(np.ceil(2 * radius + 1).sum()) if len(radius) else 0
        if len(self._ones) < chords:
            self._ones = np.ones(chords, dtype=np.intp)
            self._minus_ones = -self._ones
        return np.stack((-radius, radius)), radius**2

    # ------------------------------------------------------------- K worlds at once

    @np.errstate(divide="ignore", invalid="ignore")  # as _running_counts
    def _running_counts_batch(self, state: BatchState) -> np.ndarray:
        """(K * H * (W + 1),) :meth:`_running_counts` of every world, one after the other, bit for bit.

        The same elementwise operations on (K, ...) arrays; the Python scalar complex math of the
        single code (the grid transform) is emulated with real arrays. The (primitive, row) pairs of
        all worlds form one flat list, all worlds' edges before all worlds' discs; world k's rows
        are rows k * H ... of one tall grid, so one scatter-add and one cumulative sum do them all.
        Returns a view of a scratch buffer, overwritten by the next call.
        """
        n, edges, worlds = self.cells, self._edge_count, state.worlds
        discs = state.n_humans + len(self._static_disc_radius)
        # scale = to_robot_frame * (-1 / resolution) and the shift grid_origin - robot * scale: Python complex math
        scale_re, scale_im = cmul(*to_robot_frame_batch(state), -1.0 / self.resolution, 0.0)
        robot = state.positions[:, 0]
        robot_re, robot_im = cmul(robot.real, robot.imag, scale_re, scale_im)
        scale, shift = np.empty(worlds, dtype=complex), np.empty(worlds, dtype=complex)
        scale.real, scale.imag = scale_re, scale_im
        shift.real, shift.imag = self._grid_origin.real - robot_re, self._grid_origin.imag - robot_im
        z = np.empty((worlds, 2 * edges + discs), dtype=complex)
        z[:, :edges], z[:, edges : 2 * edges] = self._edge_end, self._edge_start
        z[:, 2 * edges : 2 * edges + state.n_humans] = state.positions[:, 1:]
        z[:, 2 * edges + state.n_humans :] = self._static_disc_center
        z *= scale[:, None]  # numpy complex multiply, as the single code's array *= scalar (same bits)
        z += shift[:, None]
        end, start, centre = z[:, :edges], z[:, edges : 2 * edges], z[:, 2 * edges :]
        radius_span, radius2 = self._disc_constants(state.radii)

        # (2, primitive) spans, every world's edges then every world's discs
        edge_span = np.sort(z.real[:, : 2 * edges].reshape(worlds, 2, edges), axis=1)
        disc_span = centre.real[:, None, :] + radius_span
        span = np.concatenate((edge_span.transpose(1, 0, 2).reshape(2, -1), disc_span.transpose(1, 0, 2).reshape(2, -1)), axis=1)
        np.maximum(span, 0.0, out=span)
        np.minimum(span, n, out=span)
        first, stop = span.astype(np.intp)
        count = stop - first
        row, ends = expand_runs(first, count)
        edge_count = worlds * edges
        edge_pairs = int(ends[edge_count - 1]) if edge_count else 0
        world = np.concatenate((np.arange(worlds).repeat(edges), np.arange(worlds).repeat(discs))).repeat(count)

        delta = end - start
        anchor = np.concatenate(((start - 1.0).ravel(), (centre - 1.0).ravel())).repeat(count)
        shape = np.concatenate(((delta.imag / delta.real).ravel(), np.tile(radius2, worlds))).repeat(count)
        edge_sign = np.sign(delta.real).astype(np.int32).ravel().repeat(count[:edge_count])
        offset = row - anchor.real

        crossing = offset[:edge_pairs] * shape[:edge_pairs]
        crossing += anchor.imag[:edge_pairs]
        half = offset[edge_pairs:]
        half *= half
        np.subtract(shape[edge_pairs:], half, out=half)
        np.maximum(half, 0.0, out=half)
        np.sqrt(half, out=half)
        middle = anchor.imag[edge_pairs:]

        u = np.concatenate((crossing, middle - half, middle + half))
        np.maximum(u, 0.0, out=u)
        np.minimum(u, n, out=u)
        world *= n  # row of the tall grid
        world += row
        flat = np.concatenate((world, world[edge_pairs:]))
        flat *= n + 1
        flat += u.astype(np.intp)
        chords = len(row) - edge_pairs
        sign = np.concatenate((edge_sign, np.ones(chords, dtype=np.int32), np.full(chords, -1, dtype=np.int32)))
        # int32 (a count never exceeds the number of primitives) in a buffer kept between calls:
        # a fresh grid-sized array per call costs more in page faults than the marks themselves
        size = worlds * n * (n + 1)
        if len(self._batch_marks) < size:
            self._batch_marks = np.zeros(size, dtype=np.int32)
        marks = self._batch_marks[:size]
        marks.fill(0)
        np.add.at(marks, flat, sign)
        return np.add.accumulate(marks, out=marks)  # in place
