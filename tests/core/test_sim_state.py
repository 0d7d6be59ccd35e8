"""The simulator's declared state: one SimState per world, changed only by the simulators, handed out current."""

from __future__ import annotations

import ast
import dataclasses

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from crowdnav import Simulator
from crowdnav.batch.simulator import BatchSimulator
from crowdnav.batch.stacked_state import StackedState
from crowdnav.envs.vector.env import CrowdNavVectorEnv
from crowdnav.sim.state import SimState, StateFields
from crowdnav.worlds.compiled import load_world
from tests.paths import REPO

ROOT = REPO
FIELDS = [f.name for f in dataclasses.fields(SimState)]


def _same_state(sim: Simulator, state: SimState) -> None:
    """``sim``'s state equals ``state`` (one world's) bit for bit, field by field."""
    for name in FIELDS:
        mine, theirs = np.asarray(getattr(sim.state, name)), np.asarray(getattr(state, name))
        assert mine.dtype == theirs.dtype and mine.tobytes() == theirs.tobytes(), name


def test_every_state_field_is_declared_with_shape_dtype_and_meaning():
    source = (ROOT / "crowdnav" / "sim" / "state.py").read_text()
    tree = ast.parse(source)
    body = next(node for node in tree.body if isinstance(node, ast.ClassDef) and node.name == "StateFields").body
    docs = {}
    for field, doc in zip(body, body[1:], strict=False):  # an annotated field, then its docstring
        if isinstance(field, ast.AnnAssign) and isinstance(doc, ast.Expr) and isinstance(doc.value, ast.Constant):
            docs[field.target.id] = doc.value.value
    assert sorted(docs) == sorted(FIELDS)
    for name, doc in docs.items():
        assert ":" in doc and len(doc) > 20, f"StateFields.{name}: say shape, dtype, unit and meaning"


def test_simulator_attributes_read_its_one_state():
    sim = Simulator("station_hall")
    sim.reset(seed=3)
    state = sim.state
    for name in FIELDS:
        assert getattr(sim, name) is getattr(state, name), name
        assert name not in vars(sim), f"{name} lives in the SimState, not on the simulator"
    for _ in range(5):
        sim.step(np.array([0.5, 0.2]))
    assert sim.state is state and sim.step_count == 5 and sim.positions is state.positions


def test_stop_humans_stops_them_where_they_are_for_the_rest_of_the_episode():
    sim = Simulator("open_space", {"humans.count": 6})
    sim.reset(seed=1)
    sim.step(np.zeros(2))
    where = sim.human_positions.copy()
    sim.stop_humans(np.array([0, 3]))
    assert sim.human_stopped[[0, 3]].all() and (sim.human_velocities[[0, 3]] == 0).all()
    for _ in range(10):
        sim.step(np.zeros(2))
    assert (sim.human_positions[[0, 3]] == where[[0, 3]]).all()
    assert (sim.human_positions[[1, 2, 4, 5]] != where[[1, 2, 4, 5]]).any()


def test_clone_is_independent_and_continues_like_the_original():
    sim = Simulator("station_hall")
    sim.reset(seed=5)
    for _ in range(10):
        sim.step(np.array([0.3, 0.1]))
    twin = sim.clone()
    _same_state(twin, sim.state)
    assert twin.robot_distance.tobytes() == sim.robot_distance.tobytes()
    for _ in range(30):  # goal rules draw from each one's own generator copy
        a, b = sim.step(np.array([0.4, -0.2])), twin.step(np.array([0.4, -0.2]))
        assert a == b
    _same_state(twin, sim.state)
    twin.step(np.array([1.0, 1.0]))
    assert sim.step_count == twin.step_count - 1 and sim.positions.tobytes() != twin.positions.tobytes()


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_vector_env_simulator_hands_out_every_worlds_current_state_at_every_step_and_after_autoresets(mode):
    # short episodes and crowd sizes varying across worlds: autoresets move worlds between buckets
    env = CrowdNavVectorEnv("station_hall", 4, autoreset_mode=mode, modalities=["goal"], overrides={"max_steps": 12})
    env.reset(seed=11)
    rng, resets = np.random.default_rng(0), 0
    for _ in range(40):
        _, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, (4, 2)))
        resets += int((terminated | truncated).sum())
        for i in range(4):
            sim = env.simulator(i)
            bucket, row = env.engine.batch.locate(i)
            _same_state(sim, bucket.state.row(row))
            assert sim.positions.tobytes() == env.positions(i).tobytes()
            assert sim.robot_distance.tobytes() == bucket.pair_distance[row, 0].tobytes()
            assert complex(sim.robot_social_force) == complex(env.robot_social_force()[i])
    assert resets >= 8


def test_vector_env_simulator_is_a_snapshot_that_leaves_the_batch_alone():
    env, twin = (CrowdNavVectorEnv("station_hall", 3, modalities=["goal", "lidar"]) for _ in range(2))
    first, second = env.reset(seed=2)[0], twin.reset(seed=2)[0]
    rng = np.random.default_rng(4)
    snapshot = env.simulator(1)
    before = snapshot.positions.copy()
    for step in range(30):
        actions = rng.uniform(-1, 1, (3, 2))
        first, second = env.step(actions)[0], twin.step(actions)[0]
        assert all(first[key].tobytes() == second[key].tobytes() for key in first)
        if step == 5:  # stepping (and resetting) a snapshot draws from its own generator copy, not the world's
            for _ in range(20):
                snapshot.step(np.array([1.0, 0.0]))
            snapshot.reset()
    assert env.simulator(1).step_count == 30 and not np.array_equal(env.simulator(1).positions, before)


def test_batched_simulator_reads_no_private_field_of_another_object():
    for path in (ROOT / "crowdnav" / "batch").glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
                assert isinstance(node.value, ast.Name) and node.value.id == "self", f"{path.name}:{node.lineno}: .{node.attr}"


def _writes_into(node: ast.AST) -> str | None:
    """The state field a store target writes (``x.positions = ...``, ``x.velocities[1:][i] = ...``), if any."""
    while isinstance(node, ast.Subscript):
        node = node.value
    if isinstance(node, ast.Attribute) and node.attr in FIELDS and not (isinstance(node.value, ast.Name) and node.value.id == "self"):
        return node.attr
    return None


def test_only_the_simulators_and_goal_rules_write_a_worlds_state():
    owners = {"crowdnav/sim/simulator.py", "crowdnav/sim/state.py", "crowdnav/sim/groups.py",
              "crowdnav/sim/robots.py", "crowdnav/batch/simulator.py"}  # sim/robots.py: the other robots' state
    offenders = []
    for folder in ("crowdnav", "agents", "evaluation"):
        for path in (ROOT / folder).rglob("*.py"):
            if path.relative_to(ROOT).as_posix() in owners:
                continue
            for node in ast.walk(ast.parse(path.read_text())):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AugAssign) else []
                for target in targets:
                    for part in target.elts if isinstance(target, ast.Tuple) else [target]:
                        if (name := _writes_into(part)) is not None:
                            offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}: {name}")
    assert not offenders, "write through a simulator method instead: " + ", ".join(offenders)


def test_batch_buckets_hold_one_stacked_state_whose_rows_are_the_worlds():
    world = load_world("open_space", {"humans.count": [0, 4]})
    batch = BatchSimulator(world, 6)
    batch.reset(range(6), range(6))
    singles = [Simulator(world) for _ in range(6)]
    for i, sim in enumerate(singles):
        sim.reset(seed=i)
    for _ in range(25):
        batch.step(np.full((6, 2), 0.3))
        for i, sim in enumerate(singles):
            sim.step(np.full(2, 0.3))
            bucket, row = batch.locate(i)
            assert isinstance(bucket.state, StackedState)
            _same_state(sim, bucket.state.row(row))


def _class_body_names(path: str, name: str) -> set[str]:
    """The names a class of ``crowdnav/<path>`` declares or assigns in its own body."""
    tree = ast.parse((ROOT / "crowdnav" / path).read_text())
    body = next(node for node in ast.walk(tree) if isinstance(node, ast.ClassDef) and node.name == name).body
    names = {node.target.id for node in body if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)}
    names |= {target.id for node in body if isinstance(node, ast.Assign) for target in node.targets if isinstance(target, ast.Name)}
    return names | {node.name for node in body if isinstance(node, ast.FunctionDef)}


def test_state_fields_are_declared_once_for_one_world_and_for_k_worlds_in_the_same_order():
    assert issubclass(SimState, StateFields) and issubclass(StackedState, StateFields)
    assert [f.name for f in dataclasses.fields(StackedState)] == FIELDS == [f.name for f in dataclasses.fields(StateFields)]
    for path, name in (("sim/state.py", "SimState"), ("batch/stacked_state.py", "StackedState")):
        assert not _class_body_names(path, name) & set(FIELDS), f"{name} declares a field again"


def test_neither_simulator_lists_the_state_fields_again_it_reads_them_from_the_declaration():
    assert not _class_body_names("sim/simulator.py", "Simulator") & set(FIELDS)
    assert not _class_body_names("batch/bucket.py", "Bucket") & set(FIELDS)
    assert all(isinstance(getattr(Simulator, name), property) for name in FIELDS)
    sim = Simulator("room_furniture")
    sim.reset(seed=1)
    sim.robot_goal, sim.robot_heading = 2 + 3j, 1  # the staged fields take a new value, converted
    assert type(sim.state.robot_goal) is complex and type(sim.state.robot_heading) is float and sim.state.robot_heading == 1.0
    with pytest.raises(AttributeError):
        sim.human_goals = np.zeros(sim.n_humans, dtype=complex)  # the others change through the simulator's methods only


