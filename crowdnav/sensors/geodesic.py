"""``geodesic``: how far the goal is around walls and furniture, on a small grid centred on the robot.

The robot's map of the room, its pose and its goal give the shortest-path distance to the goal
around the static world (:class:`crowdnav.planning.static_map.GeodesicField`, the distance the
predictive planner steers by: an 8-connected wavefront over the cells where the robot's centre
may stand, computed once per goal). This modality reads it at a ``size`` x ``size`` grid of
points around the robot's centre, in the robot frame, so an agent can tell where a move brings it
closer to the goal *by a path that exists*, not only as the crow flies (the SARL-style agent reads
it in its lookahead: docs/agents.md#agents-that-read-the-room). Humans are not in it.

A grid point where the robot's centre may not stand (closer to a wall than its radius) reads the
least, over the grid's standing points, of their distance plus the straight way from them: a move
of a few centimetres toward a wall then reads the goal a few centimetres farther, not suddenly out
of reach (else a robot in a 0.8 m gap would see every move off the exact centre line as hopeless),
and no reading cuts through a wall beyond the grid.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

from crowdnav.planning.predictive import PlannerSettings
from crowdnav.planning.static_map import MapCache, grid_shape
from crowdnav.scenario.schema import GeodesicSensor
from crowdnav.sensors.base import Modality, register_modality
from crowdnav.sensors.frames import to_robot_frame, to_robot_frame_batch

if TYPE_CHECKING:
    from crowdnav.batch.state import BatchState
    from crowdnav.sim.robot_view import RobotWorld
    from crowdnav.worlds.compiled import CompiledWorld

UNREACHABLE_FACTOR = 4.0
"""Grids with no standing point connected to the goal read this many world diagonals (the Box's bound)."""


@register_modality
class GeodesicModality(Modality):
    """Geodesic distance (m) to the goal at a grid of points around the robot: float32 ``(size, size)``.

    Entry ``[i, j]`` is the distance at the robot's centre plus ``((i - c) * spacing, (j - c) *
    spacing)`` in the robot frame (x along the heading, y to the left; ``c = size // 2``, so the centre
    entry is the robot's own position). The distance is the predictive planner's
    (:class:`~crowdnav.planning.predictive.PlannerSettings`: its static margin and grid spacing): from a
    point, the best of the four surrounding grid cells plus the straight step to it. A point where the
    robot's centre may not stand reads the least, over the grid's points that have a distance, of that
    distance plus the straight line between the two points; a grid without any (cut off from the goal)
    reads ``4 x`` the world's diagonal, the Box's bound. Scale (:meth:`scale`): one diagonal; offsets 0.
    """

    key = "geodesic"
    sees_robots = False  # the map's static shapes only
    settings_type = GeodesicSensor

    def __init__(self, world: CompiledWorld, settings: GeodesicSensor | None = None):
        super().__init__(world, settings)
        size, spacing = int(self.settings.size), float(self.settings.spacing)
        self.size = size
        planner = PlannerSettings()
        box = world.scenario.world
        grid_shape((float(box.min[0]), float(box.min[1]), float(box.max[0]), float(box.max[1])), planner.map_spacing,
                   "modality 'geodesic': the goal-distance grid")  # a world too large: one line now, not at the first reset
        self.maps = MapCache(planner.static_margin, planner.map_spacing)
        span = (np.arange(size) - size // 2) * spacing
        self.offset_x, self.offset_y = np.meshgrid(span, span, indexing="ij")  # (size, size), robot frame
        flat = (self.offset_x + 1j * self.offset_y).ravel()
        self._between = np.abs(flat[:, None] - flat[None, :])  # (size^2, size^2) straight lines between grid points
        self.diagonal = float(world.scenario.world_diagonal)
        self.bound = UNREACHABLE_FACTOR * self.diagonal

    def make_space(self) -> spaces.Box:
        return spaces.Box(0.0, self.bound, shape=(self.size, self.size), dtype=np.float32)

    def scale(self) -> tuple[np.ndarray, np.ndarray]:
        shape = (self.size, self.size)
        return np.zeros(shape, dtype=np.float32), np.full(shape, self.diagonal, dtype=np.float32)

    def observe(self, sim: RobotWorld) -> np.ndarray:
        rotation, robot = to_robot_frame(sim), complex(sim.positions[0])
        goal = np.array([sim.robot_goal], dtype=complex)
        one: np.ndarray = self._read(np.array([robot]), np.array([rotation.real]), np.array([rotation.imag]), goal)[0]
        return one

    def observe_batch(self, state: BatchState) -> np.ndarray:
        cos, minus_sin = to_robot_frame_batch(state)
        return self._read(state.positions[:, 0], cos, minus_sin, state.robot_goal)

    def _read(self, robot: np.ndarray, cos: np.ndarray, minus_sin: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """(K, size, size) float32 of K worlds: robot centres (K,), the robot frame's rotation (K,), goals (K,)."""
        c, s = cos[:, None, None], -minus_sin[:, None, None]  # robot frame -> world: rotate by +heading
        x = robot.real[:, None, None] + (self.offset_x * c - self.offset_y * s)
        y = robot.imag[:, None, None] + (self.offset_x * s + self.offset_y * c)
        owner = np.broadcast_to(np.arange(len(robot))[:, None, None], x.shape)
        distance = self.maps.cost(self.world, goals, x + 1j * y, owner).reshape(len(robot), -1)
        off = ~np.isfinite(distance)
        if off.any():  # points off the standing cells: the least standing point's distance plus the straight way from it
            reach = np.min(distance[:, None, :] + self._between[None], axis=2)
            distance = np.where(off, reach, distance)
        distance = distance.reshape(x.shape)
        return np.minimum(np.where(np.isfinite(distance), distance, self.bound), self.bound).astype(np.float32)
