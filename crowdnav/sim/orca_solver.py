"""ORCA (optimal reciprocal collision avoidance) through the optional package pyrvo (RVO2's bindings).

Used by the humans of groups with ``model: orca`` (the crowd model :class:`crowdnav.crowd.orca.OrcaModel`,
one per :class:`crowdnav.Simulator`) and by the ORCA robot baseline (:class:`crowdnav.planning.scripted.OrcaRobot`).
The core install does not need pyrvo: it is imported only when something asks for ORCA, and its
absence is one line saying ``pip install -e ".[orca]"`` (in crowdnav's clone).

ORCA chooses, for every agent, the velocity closest to its *preferred* velocity that stays
collision-free for ``time_horizon`` seconds with the other agents (each assumed to take half of
the avoidance) and ``time_horizon_obstacles`` with the static obstacles (the scenario's walls,
furniture and boundary as RVO2 polygons; round furniture as a circumscribed 16-gon), never faster
than the agent's max speed. Given the same positions, velocities and preferred velocities it
returns the same velocities (RVO2 is single-threaded here and keeps no state between steps that
:meth:`OrcaSolver.velocities` does not overwrite), so the same seed still gives the same episode.

pyrvo's API is per agent (one call sets one agent's position), so a step costs a few calls per
agent; they run through ``map`` (no Python bytecode per agent), see docs/simulator.md for the cost.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Callable, Sequence
from itertools import chain
from typing import Any

import numpy as np
from shapely.geometry.polygon import orient

from crowdnav.errors import CrowdNavError, install_line
from crowdnav.scenario.schema import Orca
from crowdnav.worlds.obstacles import StaticObstacles

INSTALL = install_line("orca")
DISC_SIDES = 16
"""Round furniture is given to ORCA as the regular polygon with this many sides around the disc."""


class OrcaUnavailableError(CrowdNavError, ValueError):
    """ORCA was asked for but pyrvo is not installed; ``str()`` is one line with the install command."""


def pyrvo_module(who: str) -> Any:
    """The pyrvo module, or :class:`OrcaUnavailableError` naming ``who`` needed it."""
    try:
        import pyrvo
    except ImportError:
        raise OrcaUnavailableError(f"{who} needs the optional package pyrvo, which the core install leaves out: {INSTALL}") from None
    return pyrvo


def obstacle_rings(obstacles: StaticObstacles) -> list[list[tuple[float, float]]]:
    """Every static obstacle as RVO2 vertex lists: exteriors counter-clockwise, holes clockwise.

    RVO2's obstacle edges are one-sided (an agent sees an edge only from its right), so a hole
    listed clockwise is a "negative" obstacle that keeps agents inside it: the floor of a world
    given as a polygon (``world.points``) is such a hole in the solid outside.
    """
    rings = []
    for polygon in obstacles.polygons:
        polygon = orient(polygon, sign=1.0)
        for ring in (polygon.exterior, *polygon.interiors):
            rings.append([(float(x), float(y)) for x, y in ring.coords[:-1]])
    corner = 1.0 / math.cos(math.pi / DISC_SIDES)  # the polygon's edges touch the disc
    angles = np.exp(2j * np.pi * np.arange(DISC_SIDES) / DISC_SIDES)
    for center, radius in zip(obstacles.disc_center, obstacles.disc_radius, strict=True):
        vertices = center + radius * corner * angles
        rings.append(list(zip(vertices.real.tolist(), vertices.imag.tolist(), strict=True)))
    return rings


def _pairs(z: np.ndarray) -> Any:
    """(x, y) tuples of a complex array, for pyrvo's per-agent setters."""
    return zip(z.real.tolist(), z.imag.tolist(), strict=True)


class OrcaSolver:
    """An RVO2 simulator over fixed static obstacles with a fixed number of agents, reused step after step.

    RVO2 cannot remove agents (its ``clear_agents`` leaves its k-d tree pointing at the freed
    ones), so a solver serves one agent count; :meth:`configure` sets each agent's radius and max
    speed for a new episode.
    """

    def __init__(self, rings: Sequence[Sequence[tuple[float, float]]], params: Orca, dt: float, count: int, who: str):
        pyrvo = pyrvo_module(who)
        self.count = count
        self._sim = sim = pyrvo.RVOSimulator()
        sim.set_time_step(dt)
        sim.set_agent_defaults(params.neighbour_distance, params.max_neighbours, params.time_horizon, params.time_horizon_obstacles, 1.0, 1.0)
        for ring in rings:  # once per solver, at reset: a handful of polygons
            sim.add_obstacle(ring)
        sim.process_obstacles()
        self._ids = range(count)
        self._margin = params.safety_margin
        list(map(sim.add_agent, [(0.0, 0.0)] * count))
        self._vector = pyrvo.Vector2.to_tuple
        self._held: np.ndarray | None = None
        """(2 count,) int64: the bits of the velocities RVO2 holds (those it last returned, as float64), None before the first step."""
        self.episode: object = None
        """A caller's token for the episode the agents were last configured for."""

    def configure(self, radii: np.ndarray, max_speeds: np.ndarray) -> None:
        """Each agent's body radius (m, the safety margin added) and max speed (m/s) for the episode."""
        sim = self._sim
        list(map(sim.set_agent_radius, self._ids, (np.asarray(radii, dtype=float) + self._margin).tolist()))
        list(map(sim.set_agent_max_speed, self._ids, np.asarray(max_speeds, dtype=float).tolist()))

    def velocities(self, positions: np.ndarray, velocities: np.ndarray, preferred: np.ndarray) -> np.ndarray:
        """(count,) complex: ORCA's new velocity of every agent (m/s) from their positions, velocities and preferred velocities.

        A velocity is set only where it differs, bit for bit, from the one RVO2 holds (its answer of
        the step before, which agents moved by it keep): the same inputs reach RVO2 in fewer calls.
        """
        sim, ids = self._sim, self._ids
        list(map(sim.set_agent_position, ids, _pairs(positions)))
        velocities = np.ascontiguousarray(velocities, dtype=np.complex128)
        held, self._held = self._held, None  # unknown until RVO2 answers (if a call below raised)
        if held is None:
            list(map(sim.set_agent_velocity, ids, _pairs(velocities)))
        else:
            # one byte per x and per y, read two at a time: an agent whose x or y differs
            stale = np.flatnonzero(np.not_equal(velocities.view(np.int64), held).view(np.int16))
            if len(stale):
                list(map(sim.set_agent_velocity, stale.tolist(), _pairs(velocities[stale])))
        list(map(sim.set_agent_pref_velocity, ids, _pairs(preferred)))
        sim.do_step()
        xy = np.fromiter(chain.from_iterable(map(self._vector, map(sim.get_agent_velocity, ids))), dtype=float, count=2 * self.count)
        self._held = xy.view(np.int64)
        xy = xy.reshape(self.count, 2)
        return xy[:, 0] + 1j * xy[:, 1]


SOLVERS_KEPT = 4
"""Solvers one :class:`SolverCache` keeps (the most recently used agent counts); others are freed."""


class SolverCache:
    """The solvers of the last few agent counts (:data:`SOLVERS_KEPT`), the least recently used freed first.

    A solver serves one agent count for good (RVO2 cannot remove agents), so a crowd whose size
    changes at each reset (``humans.count: [1, 2000]``) would otherwise keep one solver per size
    ever seen. A solver's results do not depend on what it computed before (it keeps no state
    between steps that :meth:`OrcaSolver.velocities` does not overwrite), so one built again gives
    the same velocities as the one freed: only the cost of building it (its obstacles) is paid again.
    """

    def __init__(self, size: int = SOLVERS_KEPT):
        self.size = size
        self._solvers: OrderedDict[int, OrcaSolver] = OrderedDict()

    def __len__(self) -> int:
        return len(self._solvers)

    def get(self, count: int, build: Callable[[int], OrcaSolver]) -> OrcaSolver:
        """The solver for ``count`` agents: the kept one, or ``build(count)`` (then the least recently used beyond the size is freed)."""
        solver = self._solvers.get(count)
        if solver is not None:
            self._solvers.move_to_end(count)
            return solver
        while len(self._solvers) >= self.size:  # freed before building: at most ``size`` solvers alive at once
            self._solvers.popitem(last=False)
        solver = self._solvers[count] = build(count)
        return solver


def toward_goal(to_goal: np.ndarray, speed: np.ndarray | float, dt: float) -> np.ndarray:
    """Preferred velocity: ``speed`` towards the goal, slowed so as not to pass it within one step (complex, m/s)."""
    distance = np.abs(to_goal)
    velocity: np.ndarray = to_goal * (speed / np.maximum(np.maximum(distance, np.multiply(speed, dt)), 1e-12))
    return velocity
