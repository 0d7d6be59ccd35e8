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

from crowdnav.scenario.schema import ClosestObstacleSensor
from crowdnav.sensors.base import Modality, register_modality
from crowdnav.sensors.frames import encode_vector, to_robot_frame, vector_space

if TYPE_CHECKING:
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
