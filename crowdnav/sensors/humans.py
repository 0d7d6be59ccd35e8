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
    from crowdnav.simulator import Simulator
    from crowdnav.world import CompiledWorld

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

    def observe(self, sim: Simulator) -> np.ndarray:
        out = np.zeros((self.count, 6), dtype=np.float32)
        if sim.n_humans:
            surface = sim.robot_distance[1:] - sim.radii[1:]
            order = np.argsort(surface, kind="stable")[: self.count]
            rotation = to_robot_frame(sim)
            robot_velocity = complex(sim.velocities[0])
            out[: len(order)] = self._rows(
                surface[order], sim.robot_offset[1:][order], sim.velocities[1:][order], sim.radii[1:][order],
                robot_velocity.real, robot_velocity.imag, rotation.real, rotation.imag,
            )
        return out

    def observe_batch(self, state: BatchState) -> np.ndarray:
        out = np.zeros((state.worlds, self.count, 6), dtype=np.float32)
        if state.n_humans and state.worlds:
            surface = state.robot_distance[:, 1:] - state.radii[1:]
            order = np.argsort(surface, axis=1, kind="stable")[:, : self.count]
            cos, minus_sin = to_robot_frame_batch(state)
            robot_velocity = state.velocities[:, :1]
            out[:, : order.shape[1]] = self._rows(
                np.take_along_axis(surface, order, axis=1),
                np.take_along_axis(state.robot_offset[:, 1:], order, axis=1),
                np.take_along_axis(state.velocities[:, 1:], order, axis=1),
                state.radii[1:][order],
                robot_velocity.real, robot_velocity.imag, cos[:, None], minus_sin[:, None],
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

        Only elementwise real operations, so the single path (Python-float rotation and robot
        velocity) and the batched one ((K, 1) arrays of them) give the same bits.
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
