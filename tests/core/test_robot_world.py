"""What is read from a world is declared once, :class:`crowdnav.sim.robot_view.RobotWorld`, and every view is checked against it.

Every :data:`ROBOT_WORLD` name, of its declared kind and shape, on each thing the sensors, the reward and the scripted
policies read (a simulator, every robot's :class:`RobotView` with and without the other robots, the tracker's view);
:class:`BatchState`'s fields are names of the declaration, and ``stack`` / ``rows`` read every field from the dataclass
(a field added to a subclass is stacked); :func:`reads_the_rest` forwards every declared name a view does not compute,
a name added to the declaration too.
"""

from __future__ import annotations

import dataclasses
import typing

import numpy as np
import pytest

from crowdnav import Simulator
from crowdnav.batch.state import ROBOT_ROW, SHARED_BY_WORLDS, BatchState, FloatArray, dtypes
from crowdnav.scenario.schema import Scenario
from crowdnav.sensors.tracked import TrackedView
from crowdnav.sensors.tracker import TrackedColumns
from crowdnav.sim import robot_view
from crowdnav.sim.geometry import pair_tables
from crowdnav.sim.robot_view import ROBOT_WORLD, RobotView, RobotWorld, reads_the_rest, robot_offsets
from crowdnav.sim.state import SELF_DISTANCE
from crowdnav.worlds.compiled import CompiledWorld
from crowdnav.worlds.obstacles import StaticObstacles

KINDS = {name: typing.get_type_hints(getattr(RobotWorld, name).fget, {"np": np, "CompiledWorld": CompiledWorld, "Scenario": Scenario,
                                                                      "StaticObstacles": StaticObstacles})["return"] for name in ROBOT_WORLD}
"""Each declared name's type, resolved."""
DISCS = ("positions", "velocities", "radii", "robot_offset", "robot_distance")
"""The declared (N+1,) arrays: this robot, then every disc it sees."""


def stepped(scenario: str, seed: int, steps: int = 5) -> Simulator:
    sim = Simulator(scenario)
    sim.reset(seed=seed)
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        others = rng.uniform(-1, 1, (sim.robot_count - 1, 2)) if sim.robot_count > 1 else None
        sim.step(rng.uniform(-1, 1, 2), other_robot_actions=others)
    return sim


@pytest.fixture(scope="module")
def views() -> dict[str, RobotWorld]:
    """One of everything that is read as a RobotWorld."""
    one, several = stepped("room_furniture", 0), stepped("robots_crossing_hall", 1)
    out: dict[str, RobotWorld] = {"simulator": one, "simulator of several robots": several}
    for k in range(several.robot_count):
        for with_robots in (True, False):
            out[f"robot {k}, with_robots={with_robots}"] = several.robot_view(k, with_robots)
        view = several.robot_view(k)
        assert isinstance(view, RobotView)
        out[f"robot {k} without_robots()"] = view.without_robots()
    several.retire_robots([several.robot_count - 1])  # a robot gone: the views list the others only
    out["robot 1, the last robot gone"] = several.robot_view(1)
    columns = TrackedColumns(*(np.asarray(values)[None] for values in (one.positions, one.velocities, one.robot_offset, one.robot_distance)))
    out["tracked"] = typing.cast(RobotWorld, TrackedView(one, columns))
    return out


@pytest.mark.parametrize("name", ROBOT_WORLD)
def test_every_view_has_every_declared_name_of_its_kind(views: dict[str, RobotWorld], name: str) -> None:
    kind = KINDS[name]
    for label, view in views.items():
        value = getattr(view, name)
        assert isinstance(value, kind), f"{label}: {name} is a {type(value).__name__}, declared {kind}"


def test_views_are_shaped_as_declared(views: dict[str, RobotWorld]) -> None:
    for label, view in views.items():
        n = view.n_humans
        for name in DISCS:
            assert getattr(view, name).shape == (n + 1,), (label, name)
        assert view.human_max_speed.shape == (n,), label
        assert view.pair_offset.shape == view.pair_distance.shape == (n + 1, n + 1), label
        assert view.robot_distance[0] == SELF_DISTANCE and view.robot_position == view.positions[0], label
        for name in ROBOT_ROW:
            table = getattr(view, name)
            assert table.ndim == 2 and table.shape[0] in (1, n + 1), (label, name)


def test_batch_state_fields_are_declared_names() -> None:
    assert set(dtypes(BatchState)) <= set(ROBOT_WORLD)
    assert SHARED_BY_WORLDS | ROBOT_ROW <= set(dtypes(BatchState))


def same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@dataclasses.dataclass
class Wider(BatchState):
    """A batch with one more declared name: ``stack`` and ``rows`` take it without another line."""

    human_max_speed: FloatArray


def test_stack_and_rows_read_every_field() -> None:
    sims = [stepped("room_furniture", seed) for seed in range(4)]
    sims = [sim for sim in sims if sim.n_humans == sims[0].n_humans]
    state = Wider.stack(sims)
    for name, dtype in dtypes(Wider).items():
        value = getattr(state, name)
        assert value.dtype == dtype, name
        if name in SHARED_BY_WORLDS:
            assert same(value, np.asarray(getattr(sims[0], name), dtype)), name
            continue
        for k, sim in enumerate(sims):
            single = np.asarray(getattr(sim, name), dtype)
            assert same(value[k], single[0] if name in ROBOT_ROW else single), (name, k)
    rows = np.array([len(sims) - 1, 0])
    part = state.rows(rows)
    assert type(part) is Wider
    for name in dtypes(Wider):
        expected = getattr(state, name) if name in SHARED_BY_WORLDS else getattr(state, name)[rows]
        assert same(getattr(part, name), expected), name
    given = np.zeros((len(rows), state.positions.shape[1]), complex)
    assert state.rows(rows, positions=given).positions is given and state.rows(None, positions=given).human_max_speed is state.human_max_speed


def test_stack_refuses_crowd_sizes() -> None:
    sims = [Simulator("open_space", {"humans.count": n}) for n in (2, 3)]
    for sim in sims:
        sim.reset(seed=0)
    with pytest.raises(ValueError, match="one crowd size"):
        BatchState.stack(sims)


def test_reads_the_rest_forwards_every_name_not_computed(monkeypatch: pytest.MonkeyPatch) -> None:
    sim = stepped("room_furniture", 2)

    def build() -> type:
        @reads_the_rest("_world")
        class Moved:
            positions: np.ndarray

            def __init__(self, world: RobotWorld):
                self._world, self.positions = world, world.positions + 1.0

            @property
            def pair_offset(self) -> np.ndarray:
                return pair_tables(self.positions)[0]

        return Moved

    view = build()(sim)
    assert set(view.forwarded) == set(ROBOT_WORLD) - {"positions", "pair_offset"}
    for name in view.forwarded:
        ours, theirs = getattr(view, name), getattr(sim, name)
        assert same(ours, theirs) if isinstance(ours, np.ndarray) else ours is theirs or ours == theirs, name
    assert same(view.positions, sim.positions + 1.0) and same(view.pair_offset, pair_tables(sim.positions + 1.0)[0])
    assert isinstance(type(view).__dict__["world"], property)  # a class attribute: no __getattr__ on reads
    monkeypatch.setattr(robot_view, "ROBOT_WORLD", (*ROBOT_WORLD, "bounds"))  # a name added to the declaration
    wider = build()(sim)
    assert "bounds" in wider.forwarded and wider.bounds == sim.bounds


def test_the_trackers_view_computes_the_people_and_reads_the_rest_from_the_simulator() -> None:
    own = {"positions", "velocities", "robot_offset", "robot_distance", "pair_offset", "pair_distance"}
    assert set(TrackedView.forwarded) == set(ROBOT_WORLD) - own  # type: ignore[attr-defined]


def test_measured_from_positions_one_world_as_k() -> None:
    """The offsets every view measures from its positions: one world's are row k of K worlds', bit for bit."""
    positions = stepped("room_furniture", 3).positions
    z = np.stack([positions, positions + 0.25j, positions[::-1]])
    for k in range(len(z)):
        for one, many in zip(robot_offsets(z[k]), robot_offsets(z), strict=True):
            assert same(one, many[k])
        for one, many in zip(pair_tables(z[k]), pair_tables(z), strict=True):
            assert same(one, many[k])
