"""The geometry a simulator measures from its state once per step, and what it decides from it.

:class:`Geometry` is a part of :class:`crowdnav.Simulator` (:attr:`crowdnav.Simulator.geometry`),
not a base class: it turns the positions into what the sensors, the reward and the step read:
every agent's offset and distance to every other agent and obstacle, the surface gaps, the fused
social-force repulsion (:meth:`Geometry.measure`), and from those the contacts: pushing
overlapping humans apart, the robot's collision and its leaving the world. It is not state
(:mod:`crowdnav.sim.state`): it is recomputed from the positions and never written by anyone
else. Stepping, reset and the episode's draws stay in :mod:`crowdnav.sim.simulator`, which reads the
measured arrays as its own attributes (``sim.robot_offset``, ...).

What an all-pairs refresh measures is one kernel for both simulators, :func:`measure` (positions
with an optional leading world axis: :class:`Geometry` calls it on its one world, the batched
simulator on a chunk of K worlds), and :class:`Measured` declares what it returns.
"""

from __future__ import annotations

import copy
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from crowdnav.sim import forces as sf
from crowdnav.sim.contacts import deepest_contact, outside, push_out_of_obstacles, resolve_overlaps, touching
from crowdnav.sim.events import Collision
from crowdnav.sim.state import SELF_DISTANCE, PairConstants
from crowdnav.worlds.obstacles import nearest_on_edges

if TYPE_CHECKING:
    from crowdnav.sim.crowd_grid import CrowdGrid, GridGeometry
    from crowdnav.sim.robots import Team
    from crowdnav.worlds.obstacles import StaticObstacles

_NO_TABLE = np.zeros((0, 0))
"""The all-pairs tables of a crowd on the neighbour grid, which has none (and never reads them)."""


class Measured(NamedTuple):
    """What an all-pairs refresh measures at positions ``z`` (..., n+1): each array with ``z``'s leading world axis, if any.

    S = P + C static obstacles (polygons, then discs); a :class:`Geometry` holds one world's, a
    bucket of the batched simulator the rows of K worlds (its obstacle offsets: the robot's row).
    """

    pair_offset: np.ndarray
    """(..., n+1, n+1) complex, m: from agent i to agent j."""
    pair_distance: np.ndarray
    """(..., n+1, n+1) m: their lengths, an agent's own :data:`crowdnav.sim.state.SELF_DISTANCE`."""
    gap: np.ndarray
    """(..., n+1, n+1+S) m: surface gaps, agents then obstacles (touching where <= 0)."""
    humans_touch: np.ndarray | bool
    """(K,) bool, or one world's bool: whether a human touches someone or something."""
    repulsion: np.ndarray
    """(..., n+1) complex: the social-force repulsion on every agent (row 0: the humans' on the robot)."""
    polygon_offset: np.ndarray
    """(..., n+1, P) complex, m: from every agent to each polygon's nearest point."""
    polygon_distance: np.ndarray
    """(..., n+1, P) m: their lengths."""
    disc_offset: np.ndarray
    """(..., n+1, C) complex, m: from every agent to each round obstacle's centre."""
    disc_distance: np.ndarray
    """(..., n+1, C) m: their lengths."""


MEASURED: tuple[str, ...] = Measured._fields
"""The names of what :func:`measure` returns, in its order."""


def measure(z: np.ndarray, surface: Any, polygons: int, contact_all: np.ndarray, gain: np.ndarray, decay: np.ndarray) -> Measured:
    """The all-pairs geometry at positions ``z`` ((n+1,) one world's or (K, n+1) K worlds' complex positions, robot first).

    ``surface``: the obstacles' edge table (None: no obstacles), its first ``polygons`` columns
    polygons; ``contact_all``, ``gain``, ``decay``: the crowd size's
    :class:`crowdnav.sim.state.PairConstants` tables, shared by every world. Each world's numbers
    come from the same operations whatever the leading axes, so one world and a batch agree bit for bit.
    """
    m = z.shape[-1]
    offset, distance = pair_tables(z)
    static_offset, static_distance = measure_obstacles(z, surface)
    if static_offset is None or static_distance is None:
        gap = distance - contact_all
        repulsion = sf.repulsion(offset, distance, gain, decay)
    else:
        every_offset = np.concatenate([offset, static_offset], axis=-1)
        every_distance = np.concatenate([distance, static_distance], axis=-1)
        gap = every_distance - contact_all
        repulsion = sf.repulsion(every_offset, every_distance, gain, decay)
    touch: np.ndarray | bool
    if z.ndim == 1:  # one world: one reduction, no reshape (the single step's speed)
        touch = m > 1 and bool(np.minimum.reduce(gap[1:], axis=None) < 0.0)
    else:
        touch = np.minimum.reduce(gap[:, 1:].reshape(len(z), -1), axis=1) < 0.0 if m > 1 else np.zeros(len(z), dtype=bool)
    return Measured(offset, distance, gap, touch, repulsion, *obstacle_kinds(z, static_offset, static_distance, polygons))


def pair_tables(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """From agent i to agent j at positions ``z`` (..., n+1) and their lengths, (..., n+1, n+1) each: an agent's own distance
    :data:`crowdnav.sim.state.SELF_DISTANCE` (every ``pair_offset`` / ``pair_distance``: a simulator's, a batch's, a view's)."""
    m = z.shape[-1]
    offset = z[..., None, :] - z[..., :, None]  # [..., i, j]: from agent i to agent j
    distance = np.abs(offset)
    distance.reshape(-1, m * m)[:, :: m + 1] = SELF_DISTANCE  # every world's diagonal
    return offset, distance


def measure_obstacles(z: np.ndarray, surface: Any) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Every agent's offset and distance to each static obstacle, (..., n+1, S) each (``z`` (..., n+1)); None, None without any."""
    if surface is None:
        return None, None
    if z.ndim == 1:
        return nearest_on_edges(z, surface)
    offset, distance = nearest_on_edges(z.reshape(-1), surface)  # every world's agents at once
    return offset.reshape(*z.shape, -1), distance.reshape(*z.shape, -1)


def obstacle_kinds(z: np.ndarray, static_offset: np.ndarray | None, static_distance: np.ndarray | None,
                   polygons: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`measure_obstacles`' columns by kind: (polygon offset, polygon distance, disc offset, disc distance), empty without obstacles."""
    if static_offset is None or static_distance is None:
        empty_offset, empty_distance = np.zeros((*z.shape, 0), dtype=complex), np.zeros((*z.shape, 0))
        return empty_offset, empty_distance, empty_offset, empty_distance
    return static_offset[..., :polygons], static_distance[..., :polygons], static_offset[..., polygons:], static_distance[..., polygons:]


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
        self.polygons = obstacles.polygon_count
        """P: the polygons among them (the first P obstacle columns)."""
        self.surface = obstacles.surface if self.static_count else None
        """The obstacles' edge table (:attr:`crowdnav.worlds.obstacles.StaticObstacles.surface`); None: no obstacles."""
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
        (self._pair_offset, self._pair_distance, self.gap, touch, self.repulsion, self.polygon_offset, self.polygon_distance,
         self.disc_offset, self.disc_distance) = measure(z, self.surface, self.polygons, self.contact_all, self.gain, self.decay)
        self.robot_offset, self.robot_distance = self._pair_offset[0], self._pair_distance[0]
        self.robot_gap = self.gap[0]
        self.humans_touch = bool(touch)  # one world's is a bool (the kernel's type also covers K worlds')
        if team is not None:
            team.refresh(z, self.repulsion)

    def _measure_grid(self, z: np.ndarray, grid: CrowdGrid, team: Team | None) -> None:
        """:meth:`measure` for a large crowd: the robot against everyone, humans against neighbours."""
        static_offset, static_distance = measure_obstacles(z, self.surface)
        self.polygon_offset, self.polygon_distance, self.disc_offset, self.disc_distance = obstacle_kinds(z, static_offset, static_distance,
                                                                                                         self.polygons)
        geometry = grid.refresh(z, static_offset, static_distance)
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
            self._pair_offset, self._pair_distance = pair_tables(z)
        return self._pair_offset, self._pair_distance

    def push_humans_apart(self, positions: np.ndarray) -> None:
        """Push humans apart (half the overlap each), then out of walls and furniture (``positions`` in place).

        Obstacles go last, from the positions after the pair push, because a neighbour's push
        can move a human into furniture; a second obstacle pass settles corners where the first
        pass out of one obstacle lands in another. Repulsion keeps all of this rare; it is what
        holds humans out of walls and furniture (penetration under 1 cm, docs/simulator.md).
        """
        if self.grid is not None:
            positions += self.grid.push_apart(self.grid_geometry)
            if self.surface is not None:
                push_out_of_obstacles(positions[None], self.surface, self.grid.static_contact[1:])
            return
        pair_offset, pair_distance = self._pair_offset, self._pair_distance
        assert pair_offset is not None and pair_distance is not None  # all pairs: measure() measured them
        # the batch's kernel, on this one world (views with a world axis of one)
        resolve_overlaps(positions[None], pair_offset[None], pair_distance[None], self.gap[None], self.contact_all, self.surface)

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
