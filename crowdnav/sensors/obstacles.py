"""``obstacles``: the nearest point of each of the nearest walls and pieces of furniture, from the map and the pose.

What a robot with a map of its room and a localisation knows of the static world around it: for
each of the ``count`` nearest static shapes (wall, boundary wall, floor outline, piece of
furniture; with ``world_edge``, in a world without boundary walls, each side of the world
rectangle, whose crossing ends the episode) the point of its surface nearest to the robot's
centre, in the robot frame. An agent
reads it as a set of entities beside the humans (the SARL-style agent's second attention pool,
docs/agents.md), and, because the offset to the nearest point is also the surface's normal there,
it can predict its clearance after a short move (the supporting half-plane, exact along a flat
wall).

Everything comes from what the simulator caches after a reset/step (``polygon_offset``,
``polygon_distance``, ``disc_offset``, ``disc_distance`` of the robot's row): one sort over the
shapes, no Python loop. Humans and other robots never appear (the ``humans`` modality reports
people).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

from crowdnav.batch.scalar_math import cmul
from crowdnav.scenario.schema import ObstaclesSensor
from crowdnav.sensors.base import Modality, register_modality
from crowdnav.sensors.frames import to_robot_frame, to_robot_frame_batch

if TYPE_CHECKING:
    from crowdnav.batch.state import BatchState
    from crowdnav.sim.robot_view import RobotWorld
    from crowdnav.worlds.compiled import CompiledWorld

COLUMNS = ("x", "y", "present")
"""The three entries of a row (one static shape), in order."""


@register_modality
class ObstaclesModality(Modality):
    """The ``count`` nearest static shapes, nearest first: float32 ``(count, 3)``, one row per shape.

    Row ``i`` describes the i-th nearest wall or piece of furniture by surface distance (ties by
    shape index: polygons in the scenario's order, then round furniture, then with ``world_edge`` in a
    world without boundary walls the world rectangle's sides: bottom, top, left, right): ``(x, y, present)``, with
    ``(x, y)`` its surface point nearest to the robot's centre, relative to that centre and rotated
    into the robot frame (x along the heading, y to the left), in m, and ``present`` 1.0. Rows of
    absent shapes (fewer than ``count`` shapes, or a surface farther than ``max_range``) are all
    zeros. Should the robot's centre be inside a polygon (only after a collision has ended the
    episode) the row is the offset to its outline, as ``closest_obstacle``'s.

    Bounds: positions +-``max_range``; flag [0, 1]. Scale (:meth:`scale`): ``max_range`` for
    positions, 1 for the flag; offsets 0.
    """

    key = "obstacles"
    sees_robots = False  # the map's static shapes only: robots and humans are reported by other modalities
    settings_type = ObstaclesSensor

    def __init__(self, world: CompiledWorld, settings: ObstaclesSensor | None = None):
        super().__init__(world, settings)
        self.count = int(self.settings.count)
        self.max_range = float(self.settings.max_range)
        self._disc_radius = np.asarray(world.obstacles.disc_radius, dtype=np.float64)
        box = world.scenario.world
        self._edge: tuple[float, float, float, float] | None = None
        """With ``world_edge`` and no boundary walls: the rectangle ``(x0, y0, x1, y1)`` whose sides are four more shapes."""
        if self.settings.world_edge and not box.boundary_walls:
            self._edge = (float(box.min[0]), float(box.min[1]), float(box.max[0]), float(box.max[1]))
        self._shapes = world.obstacles.polygon_count + world.obstacles.disc_count + (4 if self._edge else 0)

    def make_space(self) -> spaces.Box:
        r = self.max_range
        high = np.tile(np.array([r, r, 1.0], dtype=np.float32), (self.count, 1))
        low = np.tile(np.array([-r, -r, 0.0], dtype=np.float32), (self.count, 1))
        return spaces.Box(low=low, high=high, dtype=np.float32)

    def scale(self) -> tuple[np.ndarray, np.ndarray]:
        r = self.max_range
        return np.zeros((self.count, 3), dtype=np.float32), np.tile(np.array([r, r, 1.0], dtype=np.float32), (self.count, 1))

    def observe(self, sim: RobotWorld) -> np.ndarray:
        rotation = to_robot_frame(sim)
        return self.nearest(sim.polygon_offset[0], sim.disc_offset[0], rotation.real, rotation.imag,
                            np.asarray(sim.positions[0]))

    def observe_batch(self, state: BatchState) -> np.ndarray:
        cos, minus_sin = to_robot_frame_batch(state)
        return self.nearest(state.polygon_offset, state.disc_offset, cos[:, None], minus_sin[:, None],
                            state.positions[:, 0])

    def nearest(self, polygon_offset: np.ndarray, disc_offset: np.ndarray, rotation_re: float | np.ndarray,
                rotation_im: float | np.ndarray, robot: np.ndarray | None = None) -> np.ndarray:
        """The kernel: ``(*W, count, 3)`` float32 rows of the nearest shapes of every world.

        ``polygon_offset`` (*W, P) and ``disc_offset`` (*W, D): the simulator's cached offsets from the
        robot's centre to each polygon's nearest point and each round obstacle's centre; the rotation
        into the robot frame: Python floats for one world (``W = ()``), (K, 1) arrays for K worlds; ``robot``
        (*W,) complex: the robot's centre (read only with ``world_edge`` in a world without boundary walls). Only a
        sort along the shape axis and elementwise real operations, so world k's rows depend on world k
        alone, bit for bit.
        """
        out = np.zeros((*polygon_offset.shape[:-1], self.count, 3), dtype=np.float32)
        if not self._shapes or not out.size:
            return out
        centre = np.hypot(disc_offset.real, disc_offset.imag)
        # a disc's nearest surface point: along the line to its centre, one radius short of it
        with np.errstate(divide="ignore", invalid="ignore"):
            shrink = np.where(centre > 0.0, 1.0 - self._disc_radius / centre, 0.0)
        disc_re, disc_im = cmul(disc_offset.real, disc_offset.imag, shrink, 0.0)
        parts_re, parts_im = [polygon_offset.real, disc_re], [polygon_offset.imag, disc_im]
        if self._edge is not None:
            edge_re, edge_im = self._edge_offsets(robot)
            parts_re.append(edge_re)
            parts_im.append(edge_im)
        re, im = np.concatenate(parts_re, axis=-1), np.concatenate(parts_im, axis=-1)
        surface = np.hypot(re, im)
        order = np.argsort(surface, axis=-1, kind="stable")[..., : self.count]
        re, im, surface = (np.take_along_axis(values, order, axis=-1) for values in (re, im, surface))
        x, y = cmul(re, im, rotation_re, rotation_im)
        r = self.max_range
        rows = np.stack((np.clip(x, -r, r), np.clip(y, -r, r), np.ones_like(x)), axis=-1)
        present = surface <= r
        out[..., : order.shape[-1], :] = np.where(present[..., None], rows, 0.0)
        return out

    def _edge_offsets(self, robot: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """``(re, im)`` (*W, 4): from the robot's centre to the nearest point of each side of the world rectangle.

        Bottom, top, left, right. The nearest point of a side is the robot's coordinate along it clipped to the
        side, so it is exact outside the rectangle too (after an ``out_of_bounds`` has ended the episode).
        """
        assert self._edge is not None and robot is not None, "only with world_edge, given the robot's centre"
        x0, y0, x1, y1 = self._edge
        x, y = robot.real, robot.imag
        along_x, along_y = np.clip(x, x0, x1) - x, np.clip(y, y0, y1) - y
        re = np.stack((along_x, along_x, x0 - x, x1 - x), axis=-1)
        im = np.stack((y0 - y, y1 - y, along_y, along_y), axis=-1)
        return re, im
