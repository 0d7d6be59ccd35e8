"""The geometry a simulator measures from its state once per step, and what it decides from it.

:class:`SimGeometry` is the mixin of :class:`crowdnav.Simulator` that turns the positions into
what the sensors, the reward and the step read: every agent's offset and distance to every other
agent and obstacle, the surface gaps, the fused social-force repulsion (:meth:`SimGeometry.refresh`),
and from those the contacts: pushing overlapping humans apart, the robot's collision and its
leaving the world. It is not state (:mod:`crowdnav.sim_state`): it is recomputed from the
positions and never written by anyone else. Stepping, reset and the episode's draws stay in
:mod:`crowdnav.simulator`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from crowdnav import social_force as sf
from crowdnav.contacts import deepest_contact, outside, push_humans_apart, push_out_of_obstacles, touching
from crowdnav.events import Collision
from crowdnav.obstacles import nearest_on_edges
from crowdnav.sim_state import SELF_DISTANCE, SimState

if TYPE_CHECKING:
    from crowdnav.crowd_grid import CrowdGrid, GridGeometry
    from crowdnav.obstacles import StaticObstacles
    from crowdnav.robots import Team


class SimGeometry:
    """Measures the geometry of :attr:`_state` (:meth:`refresh`) and the contacts read from it; see the module docstring.

    The owner (:class:`crowdnav.Simulator`) sets the state, the obstacles, the team and the
    pair constants of its crowd size before the first :meth:`refresh`.
    """

    _state: SimState
    obstacles: StaticObstacles
    team: Team | None
    bounds: tuple[float, float, float, float] | None
    _static_count: int
    _gain: np.ndarray
    """(n+1, n+1+S): :attr:`crowdnav.sim_state.PairConstants.gain` (all pairs; empty on the grid)."""
    _decay: np.ndarray
    """(n+1, n+1+S): :attr:`crowdnav.sim_state.PairConstants.decay` (all pairs; empty on the grid)."""
    _contact_all: np.ndarray
    """(n+1, n+1+S): :attr:`crowdnav.sim_state.PairConstants.contact_all` (all pairs; empty on the grid)."""
    _grid: CrowdGrid | None
    # what refresh() measures, read by the sensors, the reward and the step
    _geometry: GridGeometry
    _pair_offset: np.ndarray | None
    _pair_distance: np.ndarray | None
    _gap: np.ndarray
    _robot_gap: np.ndarray
    _humans_touch: bool
    _repulsion: np.ndarray
    robot_offset: np.ndarray
    robot_distance: np.ndarray
    polygon_offset: np.ndarray
    polygon_distance: np.ndarray
    disc_offset: np.ndarray
    disc_distance: np.ndarray

    @property
    def n_humans(self) -> int:
        """Active humans this episode."""
        return len(self._state.positions) - 1

    @property
    def robot_social_force(self) -> complex:
        """Social repulsion the humans exert on the robot (dimensionless force, world frame).

        Row 0 of the fused repulsion: the robot's own column and its obstacle columns have zero gain.
        """
        return complex(self._repulsion[0])

    def refresh(self) -> None:
        """Geometry at the current positions, computed once per step and read by sensors.

        Sets ``robot_offset`` / ``robot_distance`` ((n+1,): from the robot to every agent, centre
        distance, its own a huge number), ``pair_offset`` / ``pair_distance`` ((n+1, n+1): from
        agent i to agent j; for crowds of ``grid_from`` humans or more they are built only when
        read), ``polygon_offset`` / ``polygon_distance``
        ((n+1, P): to the nearest point of each static polygon) and, with round obstacles,
        ``disc_offset`` / ``disc_distance`` ((n+1, C): to each disc's centre, centre distance).
        Also the repulsion on every agent from humans (and the robot if seen) and obstacles.
        Call it after editing ``positions`` by hand (tests, scripted set-ups).
        """
        z = self._state.positions
        if self._grid is not None:
            self._refresh_grid(z, self._grid)
            return
        offset = z[None, :] - z[:, None]  # row i, column j: from agent i to agent j
        distance = np.abs(offset)
        distance.flat[:: len(z) + 1] = SELF_DISTANCE
        self._pair_offset, self._pair_distance = offset, distance
        self.robot_offset, self.robot_distance = offset[0], distance[0]
        static_offset, static_distance = self._measure_obstacles(z)
        if static_offset is not None:
            offset = np.concatenate([offset, static_offset], axis=1)
            distance = np.concatenate([distance, static_distance], axis=1)
        self._gap = distance - self._contact_all  # surface gaps: agents then obstacles, (n+1, n+1+P+C)
        self._robot_gap = self._gap[0]
        self._humans_touch = len(z) > 1 and bool(self._gap[1:].min() < 0.0)
        self._repulsion = sf.repulsion(offset, distance, self._gain, self._decay)
        if self.team is not None:
            self.team.refresh(z, self._repulsion)

    def _measure_obstacles(self, z: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Every agent's offset and distance to each static obstacle (polygons, then disc centres; None without any).

        Also sets the per-kind views the sensors read: ``polygon_*`` and ``disc_*``.
        """
        if not self._static_count:
            empty = np.zeros((len(z), 0))
            self.polygon_offset = self.disc_offset = empty.astype(complex)
            self.polygon_distance = self.disc_distance = empty
            return None, None
        surface = self.obstacles.surface
        assert surface is not None  # obstacles have their edge table
        static_offset, static_distance = nearest_on_edges(z, surface)
        count = self.obstacles.polygon_count
        self.polygon_offset, self.polygon_distance = static_offset[:, :count], static_distance[:, :count]
        self.disc_offset, self.disc_distance = static_offset[:, count:], static_distance[:, count:]
        return static_offset, static_distance

    def _refresh_grid(self, z: np.ndarray, grid: CrowdGrid) -> None:
        """:meth:`refresh` for a large crowd: the robot against everyone, humans against neighbours."""
        geometry = grid.refresh(z, *self._measure_obstacles(z))
        self._geometry = geometry
        self._pair_offset = self._pair_distance = None  # built from positions only if someone asks
        self.robot_offset, self.robot_distance = geometry.robot_offset, geometry.robot_distance
        self._robot_gap, self._humans_touch, self._repulsion = geometry.robot_gap, geometry.humans_touch, geometry.repulsion
        if self.team is not None:
            self._repulsion = self._repulsion.copy()  # the grid's own array: the team adds to a copy
            self.team.refresh(z, self._repulsion)

    @property
    def pair_offset(self) -> np.ndarray:
        """(n+1, n+1) complex: from agent i to agent j (all pairs; built on demand for large crowds)."""
        if self._pair_offset is None:
            return self._dense_pairs()[0]
        return self._pair_offset

    @property
    def pair_distance(self) -> np.ndarray:
        """(n+1, n+1): centre distances, the diagonal a huge number (built on demand for large crowds)."""
        if self._pair_distance is None:
            return self._dense_pairs()[1]
        return self._pair_distance

    def _dense_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        z = self._state.positions
        offset = z[None, :] - z[:, None]
        distance = np.abs(offset)
        distance.flat[:: len(z) + 1] = SELF_DISTANCE
        self._pair_offset, self._pair_distance = offset, distance
        return offset, distance

    def _resolve_human_overlaps(self) -> None:
        """Push humans apart (half the overlap each), then out of walls and furniture.

        Obstacles go last, from the positions after the pair push, because a neighbour's push
        can move a human into furniture; a second obstacle pass settles corners where the first
        pass out of one obstacle lands in another. Repulsion keeps all of this rare; it is what
        holds humans out of walls and furniture (penetration under 1 cm, docs/simulator.md).
        """
        n, positions = self.n_humans, self._state.positions
        if self._grid is not None:
            positions += self._grid.push_apart(self._geometry)
            contact = self._grid.static_contact[1:]
        else:  # the batch's kernels, on this one world (views with a world axis of one)
            pair_offset, pair_distance = self._pair_offset, self._pair_distance
            assert pair_offset is not None and pair_distance is not None  # all pairs: refresh() measured them
            push_humans_apart(positions[None], pair_offset[None, 1:, 1:], pair_distance[None, 1:, 1:], self._gap[None, 1:, 1 : n + 1])
            contact = self._contact_all[1:, n + 1 :]
        if self._static_count:
            push_out_of_obstacles(positions[None], self.obstacles.surface, contact)

    def robot_collision(self) -> Collision | None:
        """The robot's deepest contact in the current state (touching counts), or None."""
        gaps = self._robot_gap
        if not len(gaps) or not touching(gaps):
            return None  # the common case, decided with one reduction
        return deepest_contact(gaps, self.n_humans, self.obstacles.labels + self.obstacles.disc_labels)

    def robot_left_world(self) -> bool:
        """Whether the robot's centre is outside the world rectangle (always False with boundary walls).

        Four scalar comparisons: the robot is one point, whatever the crowd size.
        """
        if self.bounds is None:
            return False
        robot = complex(self._state.positions[0])
        left: bool = outside(robot.real, robot.imag, self.bounds)  # Python floats: a bool
        return left
