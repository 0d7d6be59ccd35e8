"""The view the simulators give their crowd models: one class, built from :class:`crowdnav.crowd.base.CrowdView`'s declaration.

:class:`StateView` has a property for every property the protocol declares (:data:`VIEWED`: not listed
again here), each read through one function the simulator hands the view, ``read(source, name)``, the
first time a model asks, and kept for the view's life: nothing is copied for a name no model reads, and the
social force's commands are computed once per view. Those that are state fields
(:class:`crowdnav.sim.state.StateFields`: :data:`FROM_STATE`) read one world's state (:func:`world_view`)
or the rows of K worlds' (:func:`worlds_view`, a leading world axis (K,)); ``view.world(k)`` is row k of a
K-world view as one world, its Python numbers converted as :data:`crowdnav.sim.state.ONE_WORLD_SCALARS` says.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import fields
from operator import methodcaller
from typing import TYPE_CHECKING, Any, Protocol, cast

import numpy as np

from crowdnav.crowd.base import SHARED_BY_WORLDS, CrowdView
from crowdnav.sim.state import ONE_WORLD_SCALARS, StateFields

if TYPE_CHECKING:
    from crowdnav.scenario.schema import Scenario
    from crowdnav.sim.robots import Team
    from crowdnav.sim.state import SimState

VIEWED: tuple[str, ...] = tuple(name for name, member in vars(CrowdView).items() if isinstance(member, property))
"""The properties :class:`CrowdView` declares, in its order: :class:`StateView`'s."""
FROM_STATE = frozenset(VIEWED) & {field.name for field in fields(StateFields)}
"""The viewed names that are state fields (``human_goals``, ..., ``step_count``): read from the state itself."""


class OneWorld(Protocol):
    """What :func:`world_view` reads of a :class:`crowdnav.Simulator`."""

    @property
    def state(self) -> SimState: ...
    @property
    def scenario(self) -> Scenario: ...
    @property
    def team(self) -> Team | None: ...
    @property
    def radii(self) -> np.ndarray: ...
    def social_force_commands(self) -> np.ndarray: ...


class StateView:
    """A :class:`CrowdView` whose names are read through ``read(source, name)`` once, on first use.

    ``social_force``: computes the social force's commands (once, when first asked); ``worlds``: the
    arrays have a leading world axis (K,) (then :meth:`world` is row k as one world); ``taken``:
    names already known (read no further).
    """

    __slots__ = ("_read", "_social", "_social_force", "_source", "_taken", "_worlds")

    def __init__(self, read: Callable[[Any, str], Any], source: Any, social_force: Callable[[], np.ndarray], worlds: bool,
                 taken: dict[str, Any] | None = None):
        self._read, self._source, self._social_force, self._worlds = read, source, social_force, worlds
        self._taken: dict[str, Any] = {} if taken is None else taken
        self._social: np.ndarray | None = None

    def _field(self, name: str) -> Any:
        taken = self._taken
        if name not in taken:
            taken[name] = self._read(self._source, name)
        return taken[name]

    def social_force(self) -> np.ndarray:
        social = self._social
        if social is None:
            social = self._social = self._social_force()
        return social

    def world(self, k: int) -> CrowdView:
        if self._worlds:
            return cast(CrowdView, StateView(_read_row, (self, k), lambda: self.social_force()[k], worlds=False))
        if k != 0:
            raise IndexError(f"a one-world view has world 0 only, not {k}")
        return cast(CrowdView, self)


def _read_row(row: tuple[StateView, int], name: str) -> Any:
    """Name ``name`` of world ``k`` of a K-world view (``row``: the view and k; arrays: views of row k)."""
    view, k = row
    value = view._field(name)
    if name in SHARED_BY_WORLDS:
        return value
    convert = ONE_WORLD_SCALARS.get(name)
    return value[k] if convert is None else convert(value[k])


for _name in VIEWED:  # every declared property, its docstring the protocol's
    setattr(StateView, _name, property(methodcaller("_field", _name), doc=getattr(CrowdView, _name).__doc__))


def world_view(sim: OneWorld) -> CrowdView:
    """One simulator's world now: the ego robot, a ``robots:`` scenario's other robots, then the humans."""
    return cast(CrowdView, StateView(_read_world, sim, sim.social_force_commands, False))  # positional: once per step


WorldView = world_view
"""The one-world view's former class name (tests and scripts build ``WorldView(sim)``)."""


def _read_world(sim: OneWorld, name: str) -> Any:
    """What a one-world view reads of ``sim``: its state's fields and every agent (robots first)."""
    if name in FROM_STATE:
        return getattr(sim.state, name)
    team = sim.team
    if name == "robot_count":
        return 1 if team is None else 1 + len(team.state.positions)
    if name == "agent_radii":
        return sim.radii if team is None else np.concatenate([team.all_radii, sim.radii[1:]])
    if name == "robot_max_speeds":
        speed = sim.scenario.robot.max_speed
        return np.atleast_1d(speed) if team is None else np.concatenate([[speed], team.max_speeds])
    field = name.removeprefix("agent_")  # agent_positions, agent_velocities: the state's, a team's robots after the first
    ours = getattr(sim.state, field)
    return ours if team is None else np.concatenate([ours[:1], getattr(team.state, field), ours[1:]])


def worlds_view(state: StateFields[Any, Any, Any], rows: np.ndarray, positions: np.ndarray, velocities: np.ndarray, radii: np.ndarray,
                robot_max_speed: float, social_force: Callable[[], np.ndarray]) -> CrowdView:
    """Rows ``rows`` of K worlds' ``state`` (one robot per world) during a step: ``positions`` and ``velocities`` are the
    step's (K, n+1) copies of those rows; ``social_force()`` computes the rows' social-force commands."""
    agents = {"robot_count": 1, "agent_positions": positions, "agent_velocities": velocities, "agent_radii": radii,
              "robot_max_speeds": np.atleast_1d(robot_max_speed)}
    return cast(CrowdView, StateView(_read_rows, (state, rows), social_force, worlds=True, taken=agents))


def _read_rows(source: tuple[StateFields[Any, Any, Any], np.ndarray], name: str) -> Any:
    state, rows = source
    return getattr(state, name)[rows]
