"""``humans``: the k nearest humans as a robot's tracker would report them.

The standard observation of CrowdNav-style learned agents: for each of the k nearest humans its
centre and its velocity relative to the robot, in the robot frame, its radius and a presence
flag. The closest point alone (``closest_obstacle``) tells a policy where the crowd is, not
where it is going; this modality gives the crowd's motion.

Everything comes from what the simulator caches after a reset/step (``robot_offset``,
``robot_distance``, ``velocities``, ``radii``): one sort over the human axis, no Python loop.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

from crowdnav.batch.scalar_math import cmul
from crowdnav.scenario.schema import HumansSensor
from crowdnav.sensors.base import Modality, register_modality
from crowdnav.sensors.frames import to_robot_frame, to_robot_frame_batch

if TYPE_CHECKING:
    from crowdnav.batch.state import BatchState
    from crowdnav.sim.robot_view import RobotWorld
    from crowdnav.worlds.compiled import CompiledWorld

COLUMNS = ("x", "y", "vx", "vy", "radius", "present")
"""The six entries of a row (one human), in order."""


@register_modality
class HumansModality(Modality):
    """The ``count`` nearest humans, nearest first: float32 ``(count, 6)``, one row per human.

    Row ``i`` describes the i-th nearest human by surface distance (centre distance minus its
    radius, ascending; ties by human index): ``(x, y, vx, vy, radius, present)``, where ``(x, y)``
    is its centre relative to the robot's centre and ``(vx, vy)`` its velocity minus the robot's
    velocity, both rotated into the robot frame (x along the heading, y to the left), in m and
    m/s; ``radius`` its body radius (m) and ``present`` 1.0. Rows of absent humans (fewer than
    ``count`` humans, or a surface farther than ``max_range``) are all zeros.

    Bounds (clipped per entry): positions +-(``max_range`` + the humans' radius), velocities +-(the
    humans' speed cap, ``max_preferred_speed * max_speed_factor``, plus the robot's
    ``max_speed``), radius [0, humans' radius], flag [0, 1].

    Scale (:meth:`scale`): ``max_range`` for positions, the velocity bound for velocities, 1 for
    the radius and the flag; offsets 0.
    """

    key = "humans"
    sees_robots = False  # a tracker of people: the range sensors see the other robots
    reads_tracker = True
    settings_type = HumansSensor

    def __init__(self, world: CompiledWorld, settings: HumansSensor | None = None):
        super().__init__(world, settings)
        self.count = int(self.settings.count)
        self.max_range = float(self.settings.max_range)
        scenario = world.scenario
        humans = scenario.humans
        self.radius = float(humans.radius)
        self.position_bound = self.max_range + self.radius
        self.human_max_speed = float(humans.max_preferred_speed * humans.social_force.max_speed_factor)
        self.speed_bound = self.human_max_speed + float(scenario.robot.max_speed)

    def make_space(self) -> spaces.Box:
        p, v = self.position_bound, self.speed_bound
        high = np.tile(np.array([p, p, v, v, self.radius, 1.0], dtype=np.float32), (self.count, 1))
        low = np.tile(np.array([-p, -p, -v, -v, 0.0, 0.0], dtype=np.float32), (self.count, 1))
        return spaces.Box(low=low, high=high, dtype=np.float32)

    def scale(self) -> tuple[np.ndarray, np.ndarray]:
        r, v = self.max_range, self.speed_bound
        scale = np.tile(np.array([r, r, v, v, 1.0, 1.0], dtype=np.float32), (self.count, 1))
        return np.zeros((self.count, 6), dtype=np.float32), scale

    def observe(self, sim: RobotWorld) -> np.ndarray:
        rotation = to_robot_frame(sim)
        return self.nearest(sim.robot_distance, sim.robot_offset, sim.velocities, sim.radii, rotation.real, rotation.imag)

    def observe_batch(self, state: BatchState) -> np.ndarray:
        cos, minus_sin = to_robot_frame_batch(state)
        return self.nearest(state.robot_distance, state.robot_offset, state.velocities, state.radii, cos[:, None], minus_sin[:, None])

    def nearest(
        self,
        robot_distance: np.ndarray,
        robot_offset: np.ndarray,
        velocities: np.ndarray,
        radii: np.ndarray,
        rotation_re: float | np.ndarray,
        rotation_im: float | np.ndarray,
    ) -> np.ndarray:
        """The kernel: ``(*W, count, 6)`` float32 rows of the nearest humans of every world.

        ``robot_distance`` / ``robot_offset`` / ``velocities``: ``(*W, n+1)``, the simulator's cached
        geometry and velocities (robot first); ``radii``: (n+1,), shared by the worlds; the robot
        frame's rotation ``to_robot_frame``: Python floats for one world (``W = ()``, no world
        axis: no numpy overhead for it) or (K, 1) arrays for K worlds. Only a sort along the human
        axis and elementwise real operations, so world k's rows depend on world k alone, bit for bit.
        """
        batched = robot_distance.ndim == 2
        out = np.zeros((*robot_distance.shape[:-1], self.count, 6), dtype=np.float32)
        if robot_distance.shape[-1] == 1 or not out.size:  # no humans (or no worlds)
            return out
        surface = robot_distance[..., 1:] - radii[1:]
        order = np.argsort(surface, axis=-1, kind="stable")[..., : self.count]
        robot_velocity: complex | np.ndarray  # (K, 1) for K worlds, a Python complex for one
        if batched:
            def gather(values: np.ndarray) -> np.ndarray:
                return np.take_along_axis(values, order, axis=-1)

            robot_velocity = velocities[:, :1]
        else:
            def gather(values: np.ndarray) -> np.ndarray:
                return values[order]

            robot_velocity = complex(velocities[0])
        out[..., : order.shape[-1], :] = self._rows(
            gather(surface), gather(robot_offset[..., 1:]), gather(velocities[..., 1:]), radii[1:][order],
            robot_velocity.real, robot_velocity.imag, rotation_re, rotation_im,
        )
        return out

    def _rows(
        self,
        surface: np.ndarray,
        offset: np.ndarray,
        velocity: np.ndarray,
        radius: np.ndarray,
        robot_vx: float | np.ndarray,
        robot_vy: float | np.ndarray,
        rotation_re: float | np.ndarray,
        rotation_im: float | np.ndarray,
    ) -> np.ndarray:
        """(..., m, 6) float32 rows of the m nearest humans, given sorted (..., m) arrays.

        Only elementwise real operations, so Python-float rotation and robot velocity (one world)
        and (K, 1) arrays of them (K worlds) give the same bits.
        """
        p, v = self.position_bound, self.speed_bound
        x, y = cmul(offset.real, offset.imag, rotation_re, rotation_im)
        vx, vy = cmul(velocity.real - robot_vx, velocity.imag - robot_vy, rotation_re, rotation_im)
        rows = np.stack(
            (
                np.clip(x, -p, p),
                np.clip(y, -p, p),
                np.clip(vx, -v, v),
                np.clip(vy, -v, v),
                np.minimum(radius, self.radius),
                np.ones_like(x),
            ),
            axis=-1,
        )
        present = surface <= self.max_range
        return np.where(present[..., None], rows, 0.0).astype(np.float32)
