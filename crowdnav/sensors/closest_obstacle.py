"""``closest_obstacle``: the nearest point of any obstacle, from the geometry the simulator caches.

The simulator already measured, after the last reset/step, the robot's offset to every human
centre (``robot_offset``), to the nearest point of every static polygon
(``polygon_offset`` row 0) and to every round obstacle's centre (``disc_offset`` row 0), so
this modality only picks the smallest of three short rows.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

from crowdnav.batch.scalar_math import cmul
from crowdnav.scenario.schema import ClosestObstacleSensor
from crowdnav.sensors.base import Modality, RadiiConstants, register_modality
from crowdnav.sensors.frames import encode_vector, encode_vectors, to_robot_frame, to_robot_frame_batch, vector_space

if TYPE_CHECKING:
    from crowdnav.batch.state import BatchState
    from crowdnav.sim.robot_view import RobotWorld
    from crowdnav.worlds.compiled import CompiledWorld


@register_modality
class ClosestObstacleModality(Modality):
    """Nearest point of any obstacle outline (human disc, static polygon or disc), robot frame.

    Polar ``(distance, sin, cos)`` or cartesian ``(x, y)``; the distance is measured from the
    robot's centre and clipped to ``max_range``. With nothing within range the reading is
    distance ``max_range`` at bearing 0: polar ``(max_range, 0, 1)``, cartesian ``(max_range, 0)``.

    While the robot's centre is outside every obstacle (always the case before a collision
    ends the episode) the point is shapely's nearest point of the obstacles; should the centre
    be inside one, the reading is the nearest point of that obstacle's outline.

    Scale (:meth:`~crowdnav.sensors.Modality.scale`): the Box default, ``max_range`` for distances and
    coordinates, 1 for sin/cos; "nothing in range" then reads ``(1, 0, 1)`` (cartesian ``(1, 0)``).
    """

    key = "closest_obstacle"
    settings_type = ClosestObstacleSensor

    def __init__(self, world: CompiledWorld, settings: ClosestObstacleSensor | None = None):
        super().__init__(world, settings)
        self.frame = self.settings.frame
        self.max_range = float(self.settings.max_range)
        obstacles = world.obstacles
        self._has_polygons = obstacles.polygon_count > 0
        self._has_discs = obstacles.disc_count > 0
        self._disc_radius = obstacles.disc_radius
        self._columns = RadiiConstants(self._column_constants)
        """radii -> per column of :meth:`nearest`: the radius (0 for polygons) and whether it is a disc."""

    def make_space(self) -> spaces.Box:
        return vector_space(self.frame, self.max_range)

    def observe(self, sim: RobotWorld) -> np.ndarray:
        offset = self.nearest_offset(sim)
        if offset is None or abs(offset) >= self.max_range:
            offset = complex(self.max_range, 0.0)
        else:
            offset *= to_robot_frame(sim)
        return encode_vector(offset, self.frame, self.max_range)

    def nearest_offset(self, sim: RobotWorld) -> complex | None:
        """World-frame vector from the robot's centre to the nearest obstacle point (None: no obstacle)."""
        if not self._has_polygons and not self._has_discs and not sim.n_humans:
            return None
        column, nearest = self.nearest(sim.robot_distance, sim.robot_offset, sim.polygon_distance[0], sim.polygon_offset[0],
                                       sim.disc_distance[0], sim.disc_offset[0], sim.radii)
        radius, is_disc = self._columns(sim.radii)
        offset = complex(nearest)
        if is_disc[column]:
            # from the robot to the centre, minus one radius along that line
            centre_distance = abs(offset)
            offset = offset * (1.0 - radius[column] / centre_distance) if centre_distance > 0.0 else complex(radius[column], 0.0)
        return offset

    @np.errstate(invalid="ignore")  # rotating the no-obstacle fill (inf) may give NaN; it is replaced
    def observe_batch(self, state: BatchState) -> np.ndarray:
        re, im = self.nearest_offset_batch(state)
        # abs(offset) >= max_range (or no obstacle: inf) reads max_range at bearing 0
        far = ~(np.hypot(re, im) < self.max_range)
        re, im = cmul(re, im, *to_robot_frame_batch(state))
        re, im = np.where(far, self.max_range, re), np.where(far, 0.0, im)
        return encode_vectors(re, im, self.frame, self.max_range)

    def nearest_offset_batch(self, state: BatchState) -> tuple[np.ndarray, np.ndarray]:
        """(K,) real and imaginary parts of :meth:`nearest_offset` per world (inf where there is no obstacle)."""
        if not self._has_polygons and not self._has_discs and not state.n_humans:
            return np.full(state.worlds, np.inf), np.full(state.worlds, np.inf)
        column, offset = self.nearest(state.robot_distance, state.robot_offset, state.polygon_distance, state.polygon_offset,
                                      state.disc_distance, state.disc_offset, state.radii)
        radius, is_disc = self._columns(state.radii)
        radius, is_disc = radius[column], is_disc[column]
        re, im = offset.real, offset.imag
        # discs: offset * (1 - r / |offset|), a Python complex times a float; complex(r, 0) at the centre
        centre_distance = np.hypot(re, im)
        with np.errstate(divide="ignore", invalid="ignore"):
            shrunk_re, shrunk_im = cmul(re, im, 1.0 - radius / centre_distance, 0.0)
        at_centre = is_disc & ~(centre_distance > 0.0)
        re = np.where(is_disc, np.where(at_centre, radius, shrunk_re), re)
        im = np.where(is_disc, np.where(at_centre, 0.0, shrunk_im), im)
        return re, im

    def nearest(
        self,
        robot_distance: np.ndarray,
        robot_offset: np.ndarray,
        polygon_distance: np.ndarray,
        polygon_offset: np.ndarray,
        disc_distance: np.ndarray,
        disc_offset: np.ndarray,
        radii: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The kernel: the nearest obstacle's column and the world-frame offset to its centre (discs) or point (polygons).

        Arrays of the simulator's cached geometry, ``(*W, columns)``: ``W = (K,)`` for K worlds or
        ``()`` for one (no world axis: no numpy overhead for it). Columns are [humans | static
        polygons | round obstacles] (see :meth:`_columns`); the nearest is the smallest surface
        distance (polygons: to their nearest point; discs: ``|centre distance - radius|``, so a
        disc containing the robot's centre measures to its outline), the first column on a tie.
        Needs at least one column.
        """
        surface = np.concatenate((np.abs(robot_distance[..., 1:] - radii[1:]), polygon_distance, np.abs(disc_distance - self._disc_radius)), axis=-1)
        offsets = np.concatenate((robot_offset[..., 1:], polygon_offset, disc_offset), axis=-1)
        column = surface.argmin(axis=-1)
        if surface.ndim == 1:
            return column, offsets[column]
        return column, offsets[np.arange(len(offsets)), column]

    def _column_constants(self, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        polygons = np.zeros(self.world.obstacles.polygon_count)
        radius = np.concatenate((radii[1:], polygons, self._disc_radius))
        return radius, np.concatenate((np.ones(len(radii) - 1, dtype=bool), polygons.astype(bool), np.ones(len(self._disc_radius), dtype=bool)))
