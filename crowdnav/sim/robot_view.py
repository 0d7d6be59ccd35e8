"""Several robots seen one at a time: :class:`RobotView` (the world from one robot) and the simulator's robot accessors.

:class:`RobotView` shows the world from robot k: index 0 is that robot, then the humans, then
the other robots still in the world, with the attribute names the sensors, the reward and the
scripted policies read from a simulator, so all of them work for any robot unchanged.
:class:`RobotWorld` is the type of that shared reading (a :class:`typing.Protocol` both match), declared
once: its names (:data:`ROBOT_WORLD`) are what every view is checked against, :func:`reads_the_rest`
forwards those a view does not compute, and :func:`robot_offsets` measures a view's offsets from its
positions (one world's or K worlds', as :mod:`crowdnav.batch.robot_views` builds them).
:func:`robot_positions`, :func:`robot_goals`, ... read every robot of a simulator at once (one
robot: the first and only); :class:`crowdnav.Simulator` shows them as its attributes
(``sim.robot_positions``). Nothing here writes a state.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from operator import attrgetter
from typing import TYPE_CHECKING, Protocol, TypeVar

import numpy as np

from crowdnav.sim.geometry import pair_tables
from crowdnav.sim.state import SELF_DISTANCE

if TYPE_CHECKING:
    from crowdnav.scenario.schema import Scenario
    from crowdnav.sim.robots import Team
    from crowdnav.sim.state import SimState
    from crowdnav.worlds.compiled import CompiledWorld
    from crowdnav.worlds.obstacles import StaticObstacles


class RobotWorld(Protocol):
    """The world around one robot as its sensors, its reward and the scripted policies read it: a :class:`crowdnav.Simulator` or a :class:`RobotView`.

    Index 0 of the arrays is that robot, then the discs it sees (``positions`` (N+1,) complex m,
    ``velocities`` (N+1,) complex m/s, ``radii`` (N+1,) m, ``robot_offset`` / ``robot_distance``
    (N+1,) from that robot, its own distance a huge number, ``pair_offset`` / ``pair_distance``
    (N+1, N+1) between any two); the obstacle tables are (1, P) /
    (1, C) (a simulator's: (n+1, P) / (n+1, C), row 0 the robot's). Read only.
    """

    @property
    def world(self) -> CompiledWorld: ...
    @property
    def scenario(self) -> Scenario: ...
    @property
    def obstacles(self) -> StaticObstacles: ...
    @property
    def dt(self) -> float: ...
    @property
    def n_humans(self) -> int: ...
    @property
    def robot_position(self) -> complex: ...
    @property
    def robot_goal(self) -> complex: ...
    @property
    def robot_goal_distance(self) -> float: ...
    @property
    def robot_heading(self) -> float: ...
    @property
    def robot_social_force(self) -> complex: ...
    @property
    def other_robot_discs(self) -> slice: ...
    @property
    def positions(self) -> np.ndarray: ...
    @property
    def velocities(self) -> np.ndarray: ...
    @property
    def radii(self) -> np.ndarray: ...
    @property
    def human_max_speed(self) -> np.ndarray: ...
    @property
    def polygon_offset(self) -> np.ndarray: ...
    @property
    def polygon_distance(self) -> np.ndarray: ...
    @property
    def disc_offset(self) -> np.ndarray: ...
    @property
    def disc_distance(self) -> np.ndarray: ...
    @property
    def robot_offset(self) -> np.ndarray: ...
    @property
    def robot_distance(self) -> np.ndarray: ...
    @property
    def pair_offset(self) -> np.ndarray: ...
    @property
    def pair_distance(self) -> np.ndarray: ...


class Viewed(RobotWorld, Protocol):
    """What a :class:`RobotView` reads of a :class:`crowdnav.Simulator` of a ``robots:`` scenario: its world and its team."""

    @property
    def team(self) -> Team | None: ...
    @property
    def bounds(self) -> tuple[float, float, float, float] | None: ...
    @property
    def step_count(self) -> int: ...
    def robot_scenario(self, index: int) -> Scenario: ...


ROBOT_WORLD: tuple[str, ...] = tuple(name for name, member in vars(RobotWorld).items() if isinstance(member, property))
"""The names :class:`RobotWorld` declares, in its order: what every view of one robot has, each of the declared kind
(tests/core/test_robot_world.py checks the simulator, :class:`RobotView` and the tracker's view)."""

Kind = TypeVar("Kind", bound=type)


def reads_the_rest(source: str) -> Callable[[Kind], Kind]:
    """Class decorator for a view of one robot: each :data:`ROBOT_WORLD` name the class does not have (a property, a method,
    a class attribute or an annotated attribute its instances set) becomes a read-only property reading ``self.<source>.<name>``.

    The properties are :func:`operator.attrgetter` (no Python frame per read: the cost of a hand-written forwarding
    property, not of ``__getattr__``); the class's ``forwarded`` lists their names. A name added to :class:`RobotWorld`
    is read from the source by every such view that does not compute it. The type checker sees the class's own names
    only: a builder hands the view out as a :class:`RobotWorld` (``cast``).
    """

    def forward(cls: Kind) -> Kind:
        have = {name for owner in cls.__mro__ for name in (*vars(owner), *vars(owner).get("__annotations__", ()))}
        forwarded = tuple(name for name in ROBOT_WORLD if name not in have)
        for name in forwarded:
            setattr(cls, name, property(attrgetter(f"{source}.{name}"), doc=f"``{name}`` of the world it is read from."))
        cls.forwarded = forwarded  # type: ignore[attr-defined]
        return cls

    return forward


def robot_offsets(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A view's ``robot_offset`` and ``robot_distance`` from its ``positions`` (last axis: the robot first, any leading world
    axis): from the robot to every disc's centre, and their lengths, the robot's own :data:`crowdnav.sim.state.SELF_DISTANCE`."""
    offset = positions - (positions[0] if positions.ndim == 1 else positions[..., :1])  # one world: a scalar's faster subtraction
    distance = np.abs(offset)
    distance[..., 0] = SELF_DISTANCE
    return offset, distance


class RobotView:
    """The world seen from robot ``index`` (0: the ego robot): the simulator's attributes, that robot first.

    Agents are that robot, the humans, then the other active robots (``n_humans`` counts them
    all: for a sensor, another robot is one more moving disc; ``with_robots=False``: the humans
    only, for the modalities that track people). Built fresh after each step
    (:meth:`crowdnav.Simulator.robot_view`); reading it does not change the simulator.
    """

    def __init__(self, sim: Viewed, index: int, with_robots: bool = True):
        team = sim.team
        assert team is not None  # a view is of one robot among several
        state = team.state
        self.world, self.obstacles, self.dt, self.bounds, self.step_count = sim.world, sim.obstacles, sim.dt, sim.bounds, sim.step_count
        self.scenario = sim.robot_scenario(index)
        others = np.flatnonzero(state.active[1:]) if with_robots else np.zeros(0, dtype=int)
        if index:
            others = others[others != index - 1]
            j = index - 1
            me, velocity, radius = state.positions[j], state.velocities[j], team.radii[j]
            self.robot_heading, self.robot_goal = float(state.headings[j]), complex(state.goals[j])
            self.robot_social_force = complex(team.social[j])
            polygon_offset, polygon_distance = team.static_offset[j : j + 1], team.static_distance[j : j + 1]
            seen = bool(state.active[0]) and with_robots
            ego = [sim.positions[0]] if seen else []
            ego_velocity = [sim.velocities[0]] if seen else []
            ego_radius = [team.all_radii[0]] if seen else []
            ego_speed = [sim.scenario.robot.max_speed] if seen else []
        else:
            me, velocity, radius = sim.positions[0], sim.velocities[0], team.all_radii[0]
            self.robot_heading, self.robot_goal = sim.robot_heading, sim.robot_goal
            self.robot_social_force = sim.robot_social_force
            static_count = sim.obstacles.polygon_count + sim.obstacles.disc_count
            polygon_offset = np.concatenate([sim.polygon_offset[:1], sim.disc_offset[:1]], axis=1) if static_count else np.zeros((1, 0), complex)
            polygon_distance = np.concatenate([sim.polygon_distance[:1], sim.disc_distance[:1]], axis=1) if static_count else np.zeros((1, 0))
            ego, ego_velocity, ego_radius, ego_speed = [], [], [], []
        humans = sim.positions[1:]
        self.other_robot_discs = slice(len(humans) + 1, None)
        """Which entries of ``positions`` are the other robots (after this robot and the humans)."""
        self.positions = np.concatenate([[me], humans, ego, state.positions[others]])
        self.velocities = np.concatenate([[velocity], sim.velocities[1:], ego_velocity, state.velocities[others]])
        self.radii = np.concatenate([[radius], sim.radii[1:], ego_radius, team.radii[others]])
        self.human_max_speed = np.concatenate([sim.human_max_speed, ego_speed, team.max_speeds[others]])
        self.robot_offset, self.robot_distance = robot_offsets(self.positions)
        count = sim.obstacles.polygon_count
        self.polygon_offset, self.polygon_distance = polygon_offset[:, :count], polygon_distance[:, :count]
        self.disc_offset, self.disc_distance = polygon_offset[:, count:], polygon_distance[:, count:]
        self._pairs: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def n_humans(self) -> int:
        """Every disc this robot sees besides itself: the humans and the other active robots."""
        return len(self.positions) - 1

    @property
    def human_positions(self) -> np.ndarray:
        """(n_humans,) complex: the discs besides this robot (humans, then the other robots)."""
        return self.positions[1:]

    @property
    def human_velocities(self) -> np.ndarray:
        return self.velocities[1:]

    @property
    def pair_offset(self) -> np.ndarray:
        """(N+1, N+1) complex: from agent i to agent j of this view (built when first read)."""
        return self._pair_tables()[0]

    @property
    def pair_distance(self) -> np.ndarray:
        """(N+1, N+1): centre distances of this view's agents, the diagonal a huge number."""
        return self._pair_tables()[1]

    def _pair_tables(self) -> tuple[np.ndarray, np.ndarray]:
        if self._pairs is None:
            self._pairs = pair_tables(self.positions)
        return self._pairs

    def without_robots(self) -> RobotView:
        """This view without the other robots: the humans only, what a people tracker sees.

        The same arrays, bit for bit, as the simulator's ``robot_view(index, with_robots=False)``
        (the other robots are listed last, so this is a cut); this view itself when it holds none.
        """
        end = self.other_robot_discs.start
        if end is None or end >= len(self.positions):
            return self
        people = copy.copy(self)
        people._keep_first(end)
        return people

    def _keep_first(self, end: int) -> None:
        """Cut this view (a copy: the arrays are slices, nothing is written into them) to its first ``end`` discs."""
        self.positions, self.velocities, self.radii = self.positions[:end], self.velocities[:end], self.radii[:end]
        self.robot_offset, self.robot_distance = self.robot_offset[:end], self.robot_distance[:end]
        self.human_max_speed = self.human_max_speed[: end - 1]
        self._pairs = None

    @property
    def robot_position(self) -> complex:
        return complex(self.positions[0])

    @property
    def robot_goal_distance(self) -> float:
        return abs(self.robot_goal - complex(self.positions[0]))


def robot_scenario(scenario: Scenario, index: int) -> Scenario:
    """``scenario`` as robot ``index`` sees it: its spec as ``robot`` (a shallow copy; the same scenario for the ego robot)."""
    if index == 0:
        return scenario
    return scenario.model_copy(update={"robot": scenario.robot_specs[index]})  # no validation: robots stays as written


class Robots(Protocol):
    """What the robot readers below need of a simulator: its state (the ego robot) and its other robots (None: one robot)."""

    @property
    def state(self) -> SimState: ...
    @property
    def team(self) -> Team | None: ...


def robot_count(sim: Robots) -> int:
    """R: the scenario's robots (1 without ``robots:``)."""
    return 1 if sim.team is None else sim.team.count


def other_robot_discs(sim: Robots) -> slice:
    """Which entries of ``positions`` are other robots: none for the simulator itself (a view lists them after the humans)."""
    return slice(len(sim.state.positions), None)


def robot_positions(sim: Robots) -> np.ndarray:
    """(R,) complex (m): every robot's centre, the ego robot first (:data:`crowdnav.sim.robots.PARKED` once it left)."""
    first: np.ndarray = sim.state.positions[:1]
    return first.copy() if sim.team is None else np.concatenate([first, sim.team.state.positions])


def robot_goals(sim: Robots) -> np.ndarray:
    """(R,) complex (m): every robot's goal, the ego robot first."""
    if sim.team is None:
        return np.array([sim.state.robot_goal])
    return np.concatenate([[sim.state.robot_goal], sim.team.state.goals])


def robot_headings(sim: Robots) -> np.ndarray:
    """(R,) float (rad): every robot's heading, the ego robot first."""
    if sim.team is None:
        return np.array([sim.state.robot_heading])
    return np.concatenate([[sim.state.robot_heading], sim.team.state.headings])


def robots_active(sim: Robots) -> np.ndarray:
    """(R,) bool: robots still in the world (one robot: always ``[True]``)."""
    return np.ones(1, dtype=bool) if sim.team is None else sim.team.state.active.copy()
