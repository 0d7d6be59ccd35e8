"""What each human agent observes in the multi-agent env: everything a social-force walker needs.

All humans' observations are computed together as new (n, ...) arrays from the simulator's
cached geometry every step, then handed out per agent as row views (one dict per human).
Everything is in the world frame (humans have no heading), metres and m/s, float32.

Keys (N = the scenario's maximum crowd size, O = static obstacles: polygons, then discs):

====================  ========  ===========================================================
key                   shape     meaning
====================  ========  ===========================================================
``position``          (2,)      own centre (x, y)
``velocity``          (2,)      own velocity, |v| <= max_speed
``goal``              (2,)      own goal (x, y)
``preferred_speed``   (1,)      walking speed the goal force aims for (m/s)
``max_speed``         (1,)      speed cap; the action is the velocity command / max_speed
``radius``            (1,)      own body radius
``humans_offset``     (N-1, 2)  other humans' centres minus own centre, padding zero
``humans_velocity``   (N-1, 2)  other humans' velocities minus own velocity, padding zero
``humans_radius``     (N-1,)    other humans' radii, padding zero
``humans_mask``       (N-1,)    1.0 where the slot holds an active human, 0.0 for padding
``obstacles_offset``  (O, 2)    nearest point of each static obstacle minus own centre
``robot_offset``      (2,)      robot centre minus own centre (only with ``see_robot``; several
                                robots: the nearest one still in the world, by surface distance)
``robot_velocity``    (2,)      robot velocity minus own velocity (only with ``see_robot``)
``robot_radius``      (1,)      robot body radius (only with ``see_robot``)
``active``            (1,)      1.0 for an active human, 0.0 for an inactive one (only with
                                the env's ``fixed_agents``; first in the flat vector)
====================  ========  ===========================================================

Slot k of human i holds human k if k < i and human k+1 otherwise (index order, itself skipped).
With ``fixed_agents`` (:meth:`HumanObservations.fixed`) every possible human has a row: an
inactive one's (absent this episode, or gone through ``human_exit``) is all zeros.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from crowdnav.scenario.schema import Scenario
from crowdnav.sim.simulator import Simulator
from crowdnav.worlds.obstacles import StaticObstacles

_ROUNDING = 1.0 + 1e-6
"""Bounds are the physical limits widened by this factor so float32 rounding stays inside them."""


def _xy(z: np.ndarray) -> np.ndarray:
    """Complex array (...) -> float32 array (..., 2) of (x, y)."""
    return np.ascontiguousarray(z).view(np.float64).reshape(*z.shape, 2).astype(np.float32)


def _box(low: float, high: float, shape: tuple[int, ...]) -> spaces.Box:
    return spaces.Box(np.float32(low), np.float32(high), shape=shape, dtype=np.float32)


class HumanObservations:
    """Observation spaces and vectorized observations of the ``human_<i>`` agents."""

    def __init__(self, scenario: Scenario, obstacles: StaticObstacles, *, active_flag: bool = False):
        humans = scenario.humans
        self.active_flag = active_flag
        self.max_humans = humans.max_count
        self.see_robot = humans.see_robot
        self._slots = max(self.max_humans - 1, 0)
        self._disc_radius = obstacles.disc_radius
        self._static_count = obstacles.polygon_count + obstacles.disc_count
        self._preferred_max = humans.max_preferred_speed * _ROUNDING
        self._speed_max = humans.max_preferred_speed * humans.social_force.max_speed_factor * _ROUNDING
        robots = scenario.robot_specs  # several robots: a human sees the nearest one
        self._radius_max = max(humans.radius, *(robot.radius for robot in robots)) * _ROUNDING
        self._robot_speed_max = max(robot.max_speed for robot in robots) * _ROUNDING
        self._others = np.zeros((0, 0), dtype=np.intp)
        self._constants: dict[str, np.ndarray] = {}
        self._shapes = {key: box.shape for key, box in self._boxes().items()}

    def space(self) -> spaces.Dict:
        """A new Dict space for one human (each agent gets its own object, seeded separately)."""
        fields: dict[str, spaces.Space[Any]] = dict(self._boxes())
        return spaces.Dict(fields)

    def _boxes(self) -> dict[str, spaces.Box]:
        """The space's fields, new objects each call."""
        inf, k, o = np.inf, self._slots, self._static_count
        speed = self._speed_max
        fields = {
            "position": _box(-inf, inf, (2,)),
            "velocity": _box(-speed, speed, (2,)),
            "goal": _box(-inf, inf, (2,)),
            "preferred_speed": _box(0.0, self._preferred_max, (1,)),
            "max_speed": _box(0.0, speed, (1,)),
            "radius": _box(0.0, self._radius_max, (1,)),
            "humans_offset": _box(-inf, inf, (k, 2)),
            "humans_velocity": _box(-2 * speed, 2 * speed, (k, 2)),
            "humans_radius": _box(0.0, self._radius_max, (k,)),
            "humans_mask": _box(0.0, 1.0, (k,)),
            "obstacles_offset": _box(-inf, inf, (o, 2)),
        }
        if self.see_robot:
            relative = self._robot_speed_max + speed
            fields["robot_offset"] = _box(-inf, inf, (2,))
            fields["robot_velocity"] = _box(-relative, relative, (2,))
            fields["robot_radius"] = _box(0.0, self._radius_max, (1,))
        if self.active_flag:
            fields["active"] = _box(0.0, 1.0, (1,))
        return fields

    def reset(self, sim: Simulator) -> None:
        """Per-episode index tables and constant fields (the crowd size is fixed within an episode)."""
        n, k = sim.n_humans, self._slots
        used = max(n - 1, 0)  # slots holding a real neighbour (an empty crowd has none)
        slot = np.arange(used)
        # Row i lists the other humans in index order: slot s holds human s, or s+1 from i on.
        self._others = slot[None, :] + (slot[None, :] >= np.arange(n)[:, None])
        radii = sim.radii[1:]
        humans_radius = np.zeros((n, k), dtype=np.float32)
        humans_radius[:, :used] = radii[self._others]
        mask = np.zeros((n, k), dtype=np.float32)
        mask[:, :used] = 1.0
        self._constants = {
            "preferred_speed": sim.human_preferred_speed[:, None].astype(np.float32),
            "max_speed": sim.human_max_speed[:, None].astype(np.float32),
            "radius": radii[:, None].astype(np.float32),
            "humans_radius": humans_radius,
            "humans_mask": mask,
        }
        if self.see_robot and sim.team is None:
            self._constants["robot_radius"] = np.full((n, 1), sim.radii[0], dtype=np.float32)

    def batch(self, sim: Simulator) -> dict[str, np.ndarray]:
        """All active humans' observations as new (n, ...) arrays, row i for ``human_<i>``."""
        n, k = sim.n_humans, self._slots
        own_velocity = sim.velocities[1:]
        rows = np.arange(n)[:, None]
        others = self._others
        humans_offset = np.zeros((n, k, 2), dtype=np.float32)
        humans_offset[:, : n - 1] = _xy(sim.pair_offset[1:, 1:][rows, others])
        humans_velocity = np.zeros((n, k, 2), dtype=np.float32)
        humans_velocity[:, : n - 1] = _xy(own_velocity[others] - own_velocity[:, None])
        out = {
            "position": _xy(sim.positions[1:]),
            "velocity": _xy(own_velocity),
            "goal": _xy(sim.human_goals),
            "humans_offset": humans_offset,
            "humans_velocity": humans_velocity,
            "obstacles_offset": _xy(self._static_offset(sim)),
        }
        for key, constant in self._constants.items():
            out[key] = constant.copy()
        if self.see_robot and sim.team is None:
            out["robot_offset"] = _xy(sim.pair_offset[1:, 0])
            out["robot_velocity"] = _xy(sim.velocities[0] - own_velocity)
        elif self.see_robot:
            offset, velocity, radius = _nearest_robot(sim)
            out["robot_offset"], out["robot_velocity"] = _xy(offset), _xy(velocity - own_velocity)
            out["robot_radius"] = radius[:, None].astype(np.float32)
        return out

    def fixed(self, sim: Simulator, active: np.ndarray) -> dict[str, np.ndarray]:
        """Every possible human's observation as new (N, ...) arrays, row i for ``human_<i>``.

        ``active``: simulator indices of the active humans; every other row is all zeros, its
        ``active`` entry included (the values sit inside the space: each bound spans 0).
        """
        out = {key: np.zeros((self.max_humans, *shape), dtype=np.float32) for key, shape in self._shapes.items()}
        if len(active):
            for key, values in self.batch(sim).items():  # a loop over keys, not humans
                out[key][active] = values[active]
            out["active"][active] = 1.0
        return out

    def _static_offset(self, sim: Simulator) -> np.ndarray:
        """(n, P+C) complex: from each human to the nearest point of each polygon, then disc surface."""
        if not self._static_count:
            return np.zeros((sim.n_humans, 0), dtype=complex)
        polygons = sim.polygon_offset[1:]
        if not len(self._disc_radius):
            return polygons
        # disc_offset points at the centre; the surface is disc_radius closer along the same ray.
        to_center, center_distance = sim.disc_offset[1:], sim.disc_distance[1:]
        discs = to_center * (1.0 - self._disc_radius / center_distance)
        return np.concatenate([polygons, discs], axis=1)


def _nearest_robot(sim: Simulator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Several robots: each human's nearest active robot by surface distance: (n,) offsets, velocities and radii."""
    team = sim.team
    assert team is not None  # several robots
    robots = sim.robot_positions
    velocities = np.concatenate([sim.velocities[:1], team.state.velocities])
    offset = robots[None, :] - sim.positions[1:, None]  # (n, R) from each human to each robot
    gap = np.where(team.state.active, np.abs(offset) - team.all_radii, np.inf)
    nearest = gap.argmin(axis=1) if len(gap) else np.zeros(0, dtype=int)
    rows = np.arange(len(offset))
    return offset[rows, nearest], velocities[nearest], team.all_radii[nearest]
