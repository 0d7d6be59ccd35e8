"""What a simulated world is made of: its episode state (:class:`SimState`) and the constants of its crowd size.

One declared structure for both simulators: :class:`StateFields` declares the fields once, with
an optional leading world axis. :class:`crowdnav.Simulator` owns one :class:`SimState` of one
world and reads its fields as its attributes (:func:`read_state_fields`, not listed again);
:class:`crowdnav.batch.simulator.BatchSimulator` keeps the worlds that have the same number of
humans as one :class:`crowdnav.batch.stacked_state.StackedState`: the same fields, each with a
leading world axis (K,) (its rows are :class:`SimState` views). Nothing outside the
simulators writes into a state: the simulator's methods (:meth:`crowdnav.Simulator.stop_humans`)
and the goal checks and rules (:func:`crowdnav.sim.groups.goal_checks`, :func:`crowdnav.sim.groups.apply_goal_rules`, on the
state they are given) do.

The geometry a simulator measures from a state (distances, gaps, repulsion) is not state: it is
recomputed from the positions by ``refresh`` and never written by anyone else.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, fields
from operator import attrgetter
from typing import Any, Generic, TypeVar, get_args

import numpy as np

from crowdnav.sim import forces as sf
from crowdnav.sim.crowd_grid import CrowdGrid

OBSTACLE_PASSES = 3
"""Obstacle pushes per overlapping step (corners between two obstacles need more than one)."""
SELF_DISTANCE = 1.0e9
"""Stand-in for an agent's distance to itself (m), so it neither repels nor overlaps itself."""


Goal = TypeVar("Goal")
Heading = TypeVar("Heading")
Count = TypeVar("Count")


@dataclass(eq=False)
class StateFields(Generic[Goal, Heading, Count]):
    """The fields of a world's episode state, declared once for one world and for K; agent 0 is the robot.

    Each field's docstring gives its shape, dtype, unit and meaning for one world
    (:class:`SimState`); K worlds with the same number of humans
    (:class:`crowdnav.batch.stacked_state.StackedState`) hold the same fields in the same order,
    each with a leading world axis (K,). ``Goal``, ``Heading`` and ``Count`` are the types of the
    robot's goal, heading and step count: Python numbers for one world (the robot's kinematics is
    Python float math, ~10x faster than numpy on 2-3 numbers), (K,) arrays for K worlds.
    Points and velocities are complex ``x + 1j*y`` (m, m/s, world frame); ``n`` is the episode's
    number of humans, human ``i`` is agent ``i + 1``.
    """

    positions: np.ndarray
    """(n+1,) complex128, m: the robot's centre, then every human's."""
    velocities: np.ndarray
    """(n+1,) complex128, m/s: every agent's velocity over the last step (0 after a reset)."""
    robot_goal: Goal
    """complex, m: the centre of the robot's goal disc."""
    robot_heading: Heading
    """float, rad, counter-clockwise from +x, in [-pi, pi]: the robot's heading."""
    step_count: Count
    """int: steps taken this episode."""
    human_group: np.ndarray
    """(n,) int64: each human's group, an index into the scenario's groups (file order)."""
    human_goals: np.ndarray
    """(n,) complex128, m: each human's current goal (standing members: where they stand)."""
    human_preferred_speed: np.ndarray
    """(n,) float64, m/s: each human's preferred walking speed, drawn at reset (standing: 0)."""
    human_max_speed: np.ndarray
    """(n,) float64, m/s: each human's speed cap, ``max_speed_factor`` times its preferred speed."""
    command_cap: np.ndarray
    """(n,) float64, m/s: the cap in the velocity command formula: ``human_max_speed``, 1 for standing members (no 0 / 0)."""
    human_stopped: np.ndarray
    """(n,) bool: humans that do not move: standing groups, arrivals under ``on_goal: stop``, humans a multi-agent env let leave."""
    human_arrived: np.ndarray
    """(n,) bool: humans that reached their goal in the last step (under ``on_goal: stop``: on arrival only)."""
    human_respawns: np.ndarray
    """(n,) int64: times each human respawned this episode (``on_goal: respawn``); after one it is a new pedestrian."""
    human_stall_mark: np.ndarray
    """(n,) float64, m: each human's distance to its goal at the last stall check (inf: a goal newer than that check)."""
    human_stalls: np.ndarray
    """(n,) int64: times each human stalled this episode (``humans.stall``), each time taking a new goal."""



@dataclass(eq=False)
class SimState(StateFields[complex, float, int]):
    """One world's episode state: the fields of :class:`StateFields` (K worlds': :class:`crowdnav.batch.stacked_state.StackedState`)."""

    @property
    def n_humans(self) -> int:
        humans: int = self.positions.shape[-1] - 1
        return humans

    def copy(self) -> SimState:
        """A deep copy (arrays copied; scalars are immutable)."""
        return SimState(**{name: value.copy() if isinstance(value, np.ndarray) else value for name, value in self._items()})

    def _items(self) -> list[tuple[str, Any]]:
        return [(f.name, getattr(self, f.name)) for f in fields(self)]


def _one_world_scalars() -> dict[str, Callable[[Any], Any]]:
    """The fields :class:`SimState` holds as Python numbers, each with its type, read from the two declarations above."""
    parameters = StateFields.__parameters__  # type: ignore[attr-defined]  # (Goal, Heading, Count)
    kinds = get_args(SimState.__orig_bases__[0])  # type: ignore[attr-defined]  # (complex, float, int)
    by_parameter = {parameter.__name__: kind for parameter, kind in zip(parameters, kinds, strict=True)}
    return {field.name: by_parameter[field.type] for field in fields(StateFields) if field.type in by_parameter}


ONE_WORLD_SCALARS = _one_world_scalars()
"""Field name -> the Python type one world holds it as (``robot_goal``: complex, ``robot_heading``: float, ``step_count``: int):
K worlds hold (K,) arrays of them, and a row read as one world converts its entries (:meth:`StackedState.row`, a crowd view's world)."""


def read_through(path: str, convert: Callable[[Any], Any] | None = None, doc: str | None = None) -> Any:
    """A property of an owner that reads one of its parts' attributes: ``owner.<path>`` (``path`` dotted, ``"_state.positions"``).

    How :class:`crowdnav.Simulator` shows its measured geometry as its own attributes (its class
    body annotates each name with the part's type and assigns this) and, through
    :func:`read_state_fields`, its :class:`SimState`'s fields. The getter is
    :func:`operator.attrgetter` (no Python frame per read). ``convert``: the property is settable too, ``convert(value)`` written into the part
    (tests and scripted set-ups stage a scene that way); None: read only.
    """
    getter = attrgetter(path)
    if convert is None:
        return property(getter, doc=doc)
    part_path, name = path.rsplit(".", 1)
    part = attrgetter(part_path)

    def setter(owner: object, value: Any) -> None:
        setattr(part(owner), name, convert(value))

    return property(getter, setter, doc=doc)


def read_with(read: Callable[[Any], object]) -> Any:
    """A read-only property computed by the module function ``read`` from its owner (its docstring too)."""
    return property(read, doc=read.__doc__)


STAGED: dict[str, Callable[[Any], Any]] = {"positions": np.asarray, "velocities": np.asarray, "robot_goal": complex, "robot_heading": float}
"""The fields a test or scripted set-up may replace on a simulator to stage a scene (then ``refresh()``), each with its conversion."""


def read_state_fields(owner: type) -> None:
    """Give ``owner`` (a class holding one world's :class:`SimState` as ``_state``) every field as a property: ``owner.positions``.

    Read from :class:`StateFields`, not listed again: a new field reads as the simulator's
    attribute too. Each returns the state's own array (read it; the simulator's methods change
    it); those in :data:`STAGED` may also be set.
    """
    for field in fields(SimState):
        doc = f":attr:`crowdnav.sim.state.StateFields.{field.name}` of this world."
        setattr(owner, field.name, read_through(f"_state.{field.name}", STAGED.get(field.name), doc))


@dataclass(frozen=True, eq=False)
class PairConstants:
    """What the pairwise and obstacle repulsion of a crowd of n humans need, shared by every world of that size.

    S = P + C static obstacles (polygons, then discs). All-pairs crowds fill the tables; crowds of
    ``Simulator.grid_from`` or more have ``grid`` instead (no (n+1)^2 tables).
    """

    radii: np.ndarray
    """(n+1,) float64, m: body radii, robot first."""
    contact: np.ndarray | None
    """(n+1, n+1) float64, m: ``radii[i] + radii[j]``, the centre distance at which two agents touch."""
    gain: np.ndarray | None
    """(n+1, n+1+S) float64: repulsion gain of column j on agent i (agents, then obstacles); 0 where nothing pushes."""
    decay: np.ndarray | None
    """(n+1, n+1+S) float64, 1/m: ``-1 / range`` of each column's repulsion."""
    contact_all: np.ndarray | None
    """(n+1, n+1+S) float64, m: surface contact distance of each column: touching where distance - contact <= 0."""
    grid: CrowdGrid | None
    """The neighbour-grid constants of a large crowd (None: all pairs)."""


CONSTANTS_KEPT = 8
"""Crowd sizes whose :class:`PairConstants` a simulator keeps (a crowd of [1, 2000] humans would otherwise keep one set per size seen)."""


class ConstantsCache:
    """The :class:`PairConstants` of the last few crowd sizes (:data:`CONSTANTS_KEPT`), the least recently used freed first.

    The constants are a pure function of the scenario and the size (:func:`pair_constants`): a set built again equals the
    one freed bit for bit, so only the cost of building it is paid again.
    """

    def __init__(self, size: int = CONSTANTS_KEPT):
        self.size = size
        self._kept: OrderedDict[tuple[int, bool], PairConstants] = OrderedDict()

    def __len__(self) -> int:
        return len(self._kept)

    def get(self, key: tuple[int, bool], build: Callable[[], PairConstants]) -> PairConstants:
        """The constants of ``key`` (crowd size, neighbour grid): the kept ones, or ``build()`` (the oldest beyond the size freed first)."""
        kept = self._kept.get(key)
        if kept is not None:
            self._kept.move_to_end(key)
            return kept
        while len(self._kept) >= self.size:  # freed before building: at most ``size`` sets alive at once (in this cache)
            self._kept.popitem(last=False)
        kept = self._kept[key] = build()
        return kept


def pair_constants(scenario: Any, obstacles: Any, n: int, grid: bool = False) -> PairConstants:
    """The :class:`PairConstants` of ``n`` humans in ``scenario`` among ``obstacles`` (a pure function of them)."""
    robot, humans, force = scenario.robot, scenario.humans, scenario.humans.social_force
    radii = np.full(n + 1, humans.radius)
    radii[0] = robot.radius
    # Obstacle columns (both geometries): polygons by surface distance, discs by centre distance
    # with their radius folded into the gain (same force, one array op less per step).
    static_strength = np.full((n + 1, 1), force.obstacle_strength)
    static_strength[0] = 0.0  # the robot does not follow the social force
    static_contact = radii[:, None] + obstacles.surface_radius[None, :]
    static_gain = sf.repulsion_gain(static_strength, static_contact, force.obstacle_range)
    if grid:  # no (n+1)^2 tables: the robot's row and column, the obstacles' columns, one human-human gain
        crowd = CrowdGrid(n, robot.radius, humans.radius, force, humans.see_robot, static_gain, -1.0 / force.obstacle_range,
                          static_contact, SELF_DISTANCE)
        return PairConstants(radii, None, None, None, None, crowd)
    contact = radii[:, None] + radii[None, :]
    strength = np.full((n + 1, n + 1), force.human_strength)
    decay = np.full((n + 1, n + 1), force.human_range)
    # Column 0 is the robot: it pushes humans only when they see it. Row 0 (the humans'
    # force on the robot) keeps the human parameters: it is the reward's social term.
    strength[1:, 0] = force.robot_strength if humans.see_robot else 0.0
    decay[1:, 0] = force.robot_range
    np.fill_diagonal(strength, 0.0)
    pair_gain = sf.repulsion_gain(strength, contact, decay)
    static_count = obstacles.polygon_count + obstacles.disc_count
    return PairConstants(
        radii=radii,
        contact=contact,
        gain=np.concatenate([pair_gain, static_gain], axis=1),
        decay=np.concatenate([-1.0 / decay, np.full((n + 1, static_count), -1.0 / force.obstacle_range)], axis=1),
        contact_all=np.concatenate([contact, static_contact], axis=1),
        grid=None,
    )
