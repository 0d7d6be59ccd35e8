"""The views the simulators give their crowd models (:class:`crowdnav.crowd.base.CrowdView`): one world, K worlds, one row of K.

Each reads the simulator's state when asked (nothing is copied for a name no model reads), and
the social force's commands are computed once per view, on first use.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:
    from crowdnav.scenario.schema import Scenario
    from crowdnav.sim.robots import Team
    from crowdnav.sim.state import SimState


class OneWorld(Protocol):
    """What :class:`WorldView` reads of a :class:`crowdnav.Simulator`."""

    @property
    def state(self) -> SimState: ...
    @property
    def scenario(self) -> Scenario: ...
    @property
    def team(self) -> Team | None: ...
    @property
    def radii(self) -> np.ndarray: ...
    def social_force_commands(self) -> np.ndarray: ...


class Stacked(Protocol):
    """What :class:`BatchView` reads of a bucket's :class:`crowdnav.batch.stacked_state.StackedState` (K worlds' rows)."""

    @property
    def human_goals(self) -> np.ndarray: ...
    @property
    def human_preferred_speed(self) -> np.ndarray: ...
    @property
    def human_max_speed(self) -> np.ndarray: ...
    @property
    def human_group(self) -> np.ndarray: ...
    @property
    def step_count(self) -> np.ndarray: ...


class WorldView:
    """One simulator's world now: the ego robot, a ``robots:`` scenario's other robots, then the humans."""

    __slots__ = ("_sim", "_social")

    def __init__(self, sim: OneWorld):
        self._sim = sim
        self._social: np.ndarray | None = None

    @property
    def robot_count(self) -> int:
        team = self._sim.team
        return 1 if team is None else 1 + len(team.state.positions)

    @property
    def agent_positions(self) -> np.ndarray:
        positions, team = self._sim.state.positions, self._sim.team
        return positions if team is None else np.concatenate([positions[:1], team.state.positions, positions[1:]])

    @property
    def agent_velocities(self) -> np.ndarray:
        velocities, team = self._sim.state.velocities, self._sim.team
        return velocities if team is None else np.concatenate([velocities[:1], team.state.velocities, velocities[1:]])

    @property
    def human_goals(self) -> np.ndarray:
        return self._sim.state.human_goals

    @property
    def human_preferred_speed(self) -> np.ndarray:
        return self._sim.state.human_preferred_speed

    @property
    def human_max_speed(self) -> np.ndarray:
        return self._sim.state.human_max_speed

    @property
    def human_group(self) -> np.ndarray:
        return self._sim.state.human_group

    @property
    def agent_radii(self) -> np.ndarray:
        radii, team = self._sim.radii, self._sim.team
        return radii if team is None else np.concatenate([team.all_radii, radii[1:]])

    @property
    def robot_max_speeds(self) -> np.ndarray:
        speed, team = self._sim.scenario.robot.max_speed, self._sim.team
        return np.atleast_1d(speed) if team is None else np.concatenate([[speed], team.max_speeds])

    @property
    def step_count(self) -> int:
        return self._sim.state.step_count

    def social_force(self) -> np.ndarray:
        if self._social is None:
            self._social = self._sim.social_force_commands()
        return self._social

    def world(self, k: int) -> WorldView:
        if k != 0:
            raise IndexError(f"a one-world view has world 0 only, not {k}")
        return self


class BatchView:
    """Rows ``rows`` of a batched simulator's bucket (one robot per world), during a step: ``positions`` and
    ``velocities`` are the step's (K, n+1) copies of those rows; ``social_force`` computes the rows' social-force commands."""

    robot_count = 1

    def __init__(self, state: Stacked, rows: np.ndarray, positions: np.ndarray, velocities: np.ndarray, radii: np.ndarray,
                 robot_max_speed: float, social_force: Callable[[], np.ndarray]):
        self._state, self._rows = state, rows
        self.agent_positions = positions
        self.agent_velocities = velocities
        self.agent_radii = radii
        self.robot_max_speeds = np.atleast_1d(robot_max_speed)
        self._social_force = social_force
        self._rows_of: dict[str, np.ndarray] = {}

    def _field(self, name: str) -> np.ndarray:
        """The rows of the state's field ``name``, taken once per view."""
        value = self._rows_of.get(name)
        if value is None:
            value = self._rows_of[name] = _take(getattr(self._state, name), self._rows)
        return value

    @property
    def human_goals(self) -> np.ndarray:
        return self._field("human_goals")

    @property
    def human_preferred_speed(self) -> np.ndarray:
        return self._field("human_preferred_speed")

    @property
    def human_max_speed(self) -> np.ndarray:
        return self._field("human_max_speed")

    @property
    def human_group(self) -> np.ndarray:
        return self._field("human_group")

    @property
    def step_count(self) -> np.ndarray:
        return self._field("step_count")

    def social_force(self) -> np.ndarray:
        value = self._rows_of.get("social_force")
        if value is None:
            value = self._rows_of["social_force"] = self._social_force()
        return value

    def world(self, k: int) -> RowView:
        return RowView(self, k)


class RowView:
    """World ``k`` of a :class:`BatchView`, as one world (arrays are views of row ``k``)."""

    robot_count = 1

    def __init__(self, batch: BatchView, k: int):
        self._batch, self._k = batch, k

    @property
    def agent_positions(self) -> np.ndarray:
        return _take(self._batch.agent_positions, self._k)

    @property
    def agent_velocities(self) -> np.ndarray:
        return _take(self._batch.agent_velocities, self._k)

    @property
    def human_goals(self) -> np.ndarray:
        return _take(self._batch.human_goals, self._k)

    @property
    def human_preferred_speed(self) -> np.ndarray:
        return _take(self._batch.human_preferred_speed, self._k)

    @property
    def human_max_speed(self) -> np.ndarray:
        return _take(self._batch.human_max_speed, self._k)

    @property
    def human_group(self) -> np.ndarray:
        return _take(self._batch.human_group, self._k)

    @property
    def agent_radii(self) -> np.ndarray:
        return self._batch.agent_radii

    @property
    def robot_max_speeds(self) -> np.ndarray:
        return self._batch.robot_max_speeds

    @property
    def step_count(self) -> int:
        return int(self._batch.step_count[self._k])

    def social_force(self) -> np.ndarray:
        return _take(self._batch.social_force(), self._k)

    def world(self, k: int) -> RowView:
        if k != 0:
            raise IndexError(f"a one-world view has world 0 only, not {k}")
        return self


def _take(array: np.ndarray, index: np.ndarray | int) -> np.ndarray:
    """``array[index]``: the rows of a K-world array (or one row), typed."""
    taken: np.ndarray = array[index]
    return taken
