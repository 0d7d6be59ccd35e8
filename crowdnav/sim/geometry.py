"""The geometry a simulator measures from its state once per step, and what it decides from it.

:class:`Geometry` is a part of :class:`crowdnav.Simulator` (:attr:`crowdnav.Simulator.geometry`),
not a base class: it turns the positions into what the sensors, the reward and the step read:
every agent's offset and distance to every other agent and obstacle, the surface gaps, the fused
social-force repulsion (:meth:`Geometry.measure`), and from those the contacts: pushing
overlapping humans apart, the robot's collision and its leaving the world. It is not state
(:mod:`crowdnav.sim.state`): it is recomputed from the positions and never written by anyone
else. Stepping, reset and the episode's draws stay in :mod:`crowdnav.sim.simulator`, which reads the
measured arrays as its own attributes (``sim.robot_offset``, ...).
"""

from __future__ import annotations

import copy
from typing import TYPE_CHECKING

import numpy as np

from crowdnav.sim import forces as sf
from crowdnav.sim.contacts import deepest_contact, outside, push_humans_apart, push_out_of_obstacles, touching
from crowdnav.sim.events import Collision
from crowdnav.sim.state import SELF_DISTANCE, PairConstants
from crowdnav.worlds.obstacles import nearest_on_edges

if TYPE_CHECKING:
    from crowdnav.sim.crowd_grid import CrowdGrid, GridGeometry
    from crowdnav.sim.robots import Team
    from crowdnav.worlds.obstacles import StaticObstacles

_NO_TABLE = np.zeros((0, 0))
"""The all-pairs tables of a crowd on the neighbour grid, which has none (and never reads them)."""


class Geometry:
    """Measures one world's geometry (:meth:`measure`) and the contacts read from it; see the module docstring.

    ``obstacles``: the world's static obstacles; ``bounds``: open space's ``(x0, y0, x1, y1)``
    rectangle the robot's centre must stay in (None: boundary walls). :meth:`use` sets the pair
    constants of the crowd size before the first :meth:`measure`.
    """

    gain: np.ndarray
    """(n+1, n+1+S): :attr:`crowdnav.sim.state.PairConstants.gain` (all pairs; empty on the grid)."""
    decay: np.ndarray
    """(n+1, n+1+S): :attr:`crowdnav.sim.state.PairConstants.decay` (all pairs; empty on the grid)."""
    contact_all: np.ndarray
    """(n+1, n+1+S): :attr:`crowdnav.sim.state.PairConstants.contact_all` (all pairs; empty on the grid)."""
    grid: CrowdGrid | None
    """The neighbour-grid constants of a large crowd (None: all pairs)."""
    # what measure() sets, read by the sensors, the reward and the step
    grid_geometry: GridGeometry
    gap: np.ndarray
    """(n+1, n+1+S) m: surface gaps, agents then obstacles (all pairs only)."""
    robot_gap: np.ndarray
    """The robot's row of the gaps (grid: the robot's own)."""
    humans_touch: bool
    """Whether a human touches someone or something."""
    repulsion: np.ndarray
    """(n+1,) complex: the social-force repulsion on every agent (row 0: the humans' on the robot)."""
    robot_offset: np.ndarray
    robot_distance: np.ndarray
    polygon_offset: np.ndarray
    polygon_distance: np.ndarray
    disc_offset: np.ndarray
    disc_distance: np.ndarray

    def __init__(self, obstacles: StaticObstacles, bounds: tuple[float, float, float, float] | None):
        self.obstacles, self.bounds = obstacles, bounds
        self.static_count = obstacles.polygon_count + obstacles.disc_count
        self._pair_offset: np.ndarray | None = None
        self._pair_distance: np.ndarray | None = None

    def use(self, constants: PairConstants) -> None:
        """Measure crowds of ``constants``' size from now on."""
        self.grid = constants.grid
        if constants.gain is None or constants.decay is None or constants.contact_all is None:
            self.gain = self.decay = self.contact_all = _NO_TABLE  # a grid crowd: measure() reads the grid's instead
        else:
            self.gain, self.decay, self.contact_all = constants.gain, constants.decay, constants.contact_all

    def copy(self) -> Geometry:
        """An independent copy (what it measures next is its own; the constants stay shared, never written)."""
        return copy.copy(self)

    def measure(self, z: np.ndarray, team: Team | None) -> None:
        """Geometry at positions ``z`` ((n+1,) complex, robot first): what :meth:`crowdnav.Simulator.refresh` documents.

        ``team``: a ``robots:`` scenario's other robots (they measure theirs and push the humans), or None.
        """
        if self.grid is not None:
            self._measure_grid(z, self.grid, team)
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
        self.gap = distance - self.contact_all  # surface gaps: agents then obstacles, (n+1, n+1+P+C)
        self.robot_gap = self.gap[0]
        self.humans_touch = len(z) > 1 and bool(self.gap[1:].min() < 0.0)
        self.repulsion = sf.repulsion(offset, distance, self.gain, self.decay)
        if team is not None:
            team.refresh(z, self.repulsion)

    def _measure_obstacles(self, z: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Every agent's offset and distance to each static obstacle (polygons, then disc centres; None without any).

        Also sets the per-kind views the sensors read: ``polygon_*`` and ``disc_*``.
        """
        if not self.static_count:
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

    def _measure_grid(self, z: np.ndarray, grid: CrowdGrid, team: Team | None) -> None:
        """:meth:`measure` for a large crowd: the robot against everyone, humans against neighbours."""
        geometry = grid.refresh(z, *self._measure_obstacles(z))
        self.grid_geometry = geometry
        self._pair_offset = self._pair_distance = None  # built from positions only if someone asks
        self.robot_offset, self.robot_distance = geometry.robot_offset, geometry.robot_distance
        self.robot_gap, self.humans_touch, self.repulsion = geometry.robot_gap, geometry.humans_touch, geometry.repulsion
        if team is not None:
            self.repulsion = self.repulsion.copy()  # the grid's own array: the team adds to a copy
            team.refresh(z, self.repulsion)

    def pairs(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n+1, n+1) offsets from agent i to agent j and their centre distances (the diagonal a huge number).

        All pairs: the measured tables; a large crowd: built from positions ``z`` when first read.
        """
        if self._pair_offset is None or self._pair_distance is None:
            offset = z[None, :] - z[:, None]
            distance = np.abs(offset)
            distance.flat[:: len(z) + 1] = SELF_DISTANCE
            self._pair_offset, self._pair_distance = offset, distance
        return self._pair_offset, self._pair_distance

    def push_humans_apart(self, positions: np.ndarray) -> None:
        """Push humans apart (half the overlap each), then out of walls and furniture (``positions`` in place).

        Obstacles go last, from the positions after the pair push, because a neighbour's push
        can move a human into furniture; a second obstacle pass settles corners where the first
        pass out of one obstacle lands in another. Repulsion keeps all of this rare; it is what
        holds humans out of walls and furniture (penetration under 1 cm, docs/simulator.md).
        """
        n = len(positions) - 1
        if self.grid is not None:
            positions += self.grid.push_apart(self.grid_geometry)
            contact = self.grid.static_contact[1:]
        else:  # the batch's kernels, on this one world (views with a world axis of one)
            pair_offset, pair_distance = self._pair_offset, self._pair_distance
            assert pair_offset is not None and pair_distance is not None  # all pairs: measure() measured them
            push_humans_apart(positions[None], pair_offset[None, 1:, 1:], pair_distance[None, 1:, 1:], self.gap[None, 1:, 1 : n + 1])
            contact = self.contact_all[1:, n + 1 :]
        if self.static_count:
            push_out_of_obstacles(positions[None], self.obstacles.surface, contact)

    def robot_collision(self, n_humans: int) -> Collision | None:
        """The robot's deepest contact as last measured (touching counts), or None."""
        gaps = self.robot_gap
        if not len(gaps) or not touching(gaps):
            return None  # the common case, decided with one reduction
        return deepest_contact(gaps, n_humans, self.obstacles.labels + self.obstacles.disc_labels)

    def robot_left_world(self, robot: complex) -> bool:
        """Whether the robot's centre ``robot`` is outside the world rectangle (always False with boundary walls).

        Four scalar comparisons: the robot is one point, whatever the crowd size.
        """
        if self.bounds is None:
            return False
        left: bool = outside(robot.real, robot.imag, self.bounds)  # Python floats: a bool
        return left
