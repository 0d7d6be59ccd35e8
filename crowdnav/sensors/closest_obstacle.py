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
from crowdnav.sensors.base import Modality, register_modality
from crowdnav.sensors.frames import encode_vector, encode_vectors, to_robot_frame, to_robot_frame_batch, vector_space

if TYPE_CHECKING:
    from crowdnav.batch.state import BatchState
    from crowdnav.simulator import Simulator
    from crowdnav.world import CompiledWorld


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

    def make_space(self) -> spaces.Box:
        return vector_space(self.frame, self.max_range)

    def observe(self, sim: Simulator) -> np.ndarray:
        offset = self.nearest_offset(sim)
        if offset is None or abs(offset) >= self.max_range:
            offset = complex(self.max_range, 0.0)
        else:
            offset *= to_robot_frame(sim)
        return encode_vector(offset, self.frame, self.max_range)

    def nearest_offset(self, sim: Simulator) -> complex | None:
        """World-frame vector from the robot's centre to the nearest obstacle point (None: no obstacle)."""
        best_distance, best = np.inf, None
        if sim.n_humans:
            surface = np.abs(sim.robot_distance[1:] - sim.radii[1:])
            j = int(surface.argmin())
            if surface[j] < best_distance:
                best_distance, best = surface[j], ("disc", sim.robot_offset[j + 1], sim.radii[j + 1])
        if self._has_polygons:
            distances = sim.polygon_distance[0]
            k = int(distances.argmin())
            if distances[k] < best_distance:
                best_distance, best = distances[k], ("point", sim.polygon_offset[0, k], 0.0)
        if self._has_discs:
            surface = np.abs(sim.disc_distance[0] - self._disc_radius)
            k = int(surface.argmin())
            if surface[k] < best_distance:
                best_distance, best = surface[k], ("disc", sim.disc_offset[0, k], self._disc_radius[k])
        if best is None:
            return None
        kind, offset, radius = best
        offset = complex(offset)
        if kind == "disc":
            centre_distance = abs(offset)
            # from the robot to the centre, minus one radius along that line
            offset = offset * (1.0 - radius / centre_distance) if centre_distance > 0.0 else complex(radius, 0.0)
        return offset

    @np.errstate(invalid="ignore")  # rotating the no-obstacle fill (inf) may give NaN; it is replaced
    def observe_batch(self, state: BatchState) -> np.ndarray:
        re, im = self.nearest_offset_batch(state)
        # abs(offset) >= max_range (or no obstacle: inf) reads max_range at bearing 0
        far = ~(np.hypot(re, im) < self.max_range)
        re, im = cmul(re, im, *to_robot_frame_batch(state))
        re, im = np.where(far, self.max_range, re), np.where(far, 0.0, im)
        return encode_vectors(re, im, self.frame, self.max_range)

    @np.errstate(invalid="ignore")  # the no-obstacle fill (inf) makes NaN products, replaced in observe_batch
    def nearest_offset_batch(self, state: BatchState) -> tuple[np.ndarray, np.ndarray]:
        """(K,) real and imaginary parts of :meth:`nearest_offset` per world (inf where there is no obstacle)."""
        worlds = np.arange(state.worlds)
        best_distance = np.full(state.worlds, np.inf)
        offset = np.full(state.worlds, np.inf + 0j)
        radius = np.zeros(state.worlds)
        is_disc = np.zeros(state.worlds, dtype=bool)
        # (kind is a disc, surface distances, offsets, radii per column) in the order nearest_offset
        # tries them; strict '<' keeps the earlier kind on a tie, as there
        candidates = []
        if state.n_humans:
            candidates.append((True, np.abs(state.robot_distance[:, 1:] - state.radii[1:]), state.robot_offset[:, 1:], state.radii[1:]))
        if self._has_polygons:
            candidates.append((False, state.polygon_distance, state.polygon_offset, None))
        if self._has_discs:
            candidates.append((True, np.abs(state.disc_distance - self._disc_radius), state.disc_offset, self._disc_radius))
        for disc, distances, offsets, radii in candidates:  # at most three kinds, not a loop over obstacles
            column = distances.argmin(axis=1)
            better = distances[worlds, column] < best_distance
            best_distance = np.where(better, distances[worlds, column], best_distance)
            offset = np.where(better, offsets[worlds, column], offset)
            radius = np.where(better, radii[column] if disc else 0.0, radius)
            is_disc = np.where(better, disc, is_disc)
        re, im = offset.real, offset.imag
        # discs: offset * (1 - r / |offset|), a Python complex times a float; complex(r, 0) at the centre
        centre_distance = np.hypot(re, im)
        with np.errstate(divide="ignore"):
            shrunk_re, shrunk_im = cmul(re, im, 1.0 - radius / centre_distance, 0.0)
        at_centre = is_disc & ~(centre_distance > 0.0)
        re = np.where(is_disc, np.where(at_centre, radius, shrunk_re), re)
        im = np.where(is_disc, np.where(at_centre, 0.0, shrunk_im), im)
        return re, im
