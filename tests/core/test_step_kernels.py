"""The parts of a step written once: each kernel gives one world's bits with or without the world axis, the goal rules
run exactly where they change something, and the crowd views are built from the protocol's declaration."""

from __future__ import annotations

import ast
import copy
import dataclasses

import numpy as np
import pytest

from crowdnav import Simulator
from crowdnav.batch.stacked_state import StackedState
from crowdnav.crowd.base import SHARED_BY_WORLDS, CrowdView
from crowdnav.crowd.views import FROM_STATE, VIEWED, StateView, world_view, worlds_view
from crowdnav.sim.events import SimulationError, check_finite
from crowdnav.sim.geometry import MEASURED, measure
from crowdnav.sim.groups import apply_goal_rules, goal_checks
from crowdnav.sim.state import ONE_WORLD_SCALARS, SimState, StateFields
from crowdnav.worlds.compiled import load_world
from tests.core.test_replay import _write
from tests.core.test_vector_env import check_batch_equals_singles
from tests.paths import REPO

FIELDS = [f.name for f in dataclasses.fields(SimState)]
FIXED_STATION = {"humans.groups.2.count": 3, "humans.groups.4.count": 2}
"""station_hall with one crowd size (its talking circle's and its last group's sizes are drawn per episode)."""


def _worlds(scenario: str, overrides: dict | None, count: int, steps: int) -> list[Simulator]:
    """``count`` simulators of one scenario, each stepped ``steps`` times with its own random actions (same crowd size)."""
    sims = []
    for seed in range(count):
        sim = Simulator(scenario, overrides)
        sim.reset(seed=seed)
        rng = np.random.default_rng(seed)
        for _ in range(steps):
            sim.step(rng.uniform(-1, 1, 2))
        sims.append(sim)
    return sims


@pytest.mark.parametrize("scenario", ["room_furniture", "open_space", "station_hall"])
def test_measure_gives_each_world_its_own_bits_with_and_without_the_world_axis(scenario):
    sims = _worlds(scenario, {"humans.count": 6} if scenario != "station_hall" else FIXED_STATION, 3, 15)
    first = sims[0]
    geometry = first.geometry
    together = measure(np.stack([sim.positions for sim in sims]), geometry.surface, geometry.polygons, geometry.contact_all,
                       geometry.gain, geometry.decay)
    assert together._fields == MEASURED
    for k, sim in enumerate(sims):
        alone = measure(sim.positions, geometry.surface, geometry.polygons, geometry.contact_all, geometry.gain, geometry.decay)
        for name, one, many in zip(MEASURED, alone, together, strict=True):
            assert np.asarray(one).tobytes() == np.asarray(many[k]).tobytes(), name
        assert sim.geometry.repulsion.tobytes() == alone.repulsion.tobytes() and sim.geometry.gap.tobytes() == alone.gap.tobytes()


def test_goal_checks_on_k_rows_equal_each_world_alone_stalls_due_in_some_worlds_only():
    overrides = {"humans.stall.time": 1.0, "humans.count": 5}
    sims = _worlds("open_space", overrides, 4, 0)
    rng = np.random.default_rng(3)
    for k, sim in enumerate(sims):  # step counts 7, 8, 9, 10: a stall check is due in one world (window 5)
        for _ in range(7 + k):
            sim.step(rng.uniform(-1, 1, 2))
    stacked = StackedState.stack([sim.state for sim in sims])
    rows = np.array([3, 1, 2])
    together = goal_checks(stacked, sims[0], rows)
    assert together.stalled is not None  # world 3's check is due (window 5, its step 10), the others' are not
    for k, row in enumerate(rows):
        alone = sims[row].state.copy()
        checks = goal_checks(alone, sims[row])
        assert together.arrived[k].tobytes() == checks.arrived.tobytes()
        if checks.stalled is None:  # no check due in this world
            assert together.stalled is not None and not together.stalled[k].any()
        else:
            assert together.stalled is not None and together.stalled[k].tobytes() == checks.stalled.tobytes()
        assert bool(together.rules[k]) == bool(checks.rules)
        for name in ("human_arrived", "human_stall_mark"):
            assert getattr(stacked, name)[row].tobytes() == getattr(alone, name).tobytes(), name


def test_check_finite_names_the_agent_and_step_and_the_world_in_a_batch():
    positions = np.array([0j, 1 + 1j, complex(np.nan, 0.0)])
    with pytest.raises(SimulationError, match=r"^step 4: the position of human 1 became non-finite"):
        check_finite(positions, positions, 4)
    with pytest.raises(SimulationError, match=r"^world 7, step 9: the position of human 1 became non-finite"):
        check_finite(np.stack([np.array([0j, 1 + 1j, 2 + 2j]), positions]), np.zeros((2, 3), complex), np.array([8, 9]), np.array([5, 7]))
    check_finite(positions[:2], positions[:2], 1)  # finite: nothing


def _skip_is_exact(sim: Simulator, steps: int, rng: np.random.Generator, stop_every: int = 0) -> int:
    """Step ``sim``; before each step's goal rules would be skipped (``rules`` False), run them on copies: nothing may change."""
    skipped = 0
    for t in range(steps):
        if stop_every and t % stop_every == 3 and sim.n_humans:
            sim.stop_humans(np.array([t % sim.n_humans]))
        events = sim.step(rng.uniform(-1, 1, 2))
        state = sim.state.copy()
        checks = goal_checks(state, sim)
        if not checks.rules:
            skipped += 1
            after, generator = state.copy(), copy.deepcopy(sim.rng)
            world = copy.copy(sim)
            world._rng = generator
            assert not apply_goal_rules(after, world, checks.arrived, checks.stalled)
            for name in FIELDS:
                assert np.asarray(getattr(after, name)).tobytes() == np.asarray(getattr(state, name)).tobytes(), name
            assert generator.bit_generator.state == sim.rng.bit_generator.state
        if events.terminated or events.truncated:
            sim.reset()
    return skipped


@pytest.mark.parametrize(("scenario", "overrides", "stop_every"), [
    ("circle_crossing", None, 0),  # on_goal: stop, humans stand at their goals
    ("station_hall", {"humans.stall.time": 1.0}, 0),  # standing circles, respawn, new goals, stalls
    ("room_furniture", None, 7),  # humans a multi-agent env stopped, in a group that takes new goals
])
def test_the_goal_rules_are_skipped_only_where_they_would_change_nothing(scenario, overrides, stop_every):
    sim = Simulator(scenario, overrides)
    sim.reset(seed=2)
    assert _skip_is_exact(sim, 300, np.random.default_rng(0), stop_every) > 100


def test_recorded_people_beside_a_group_that_stops_at_its_goal_batch_equals_single(tmp_path):
    """The goal rule of a group with ``on_goal: stop`` zeroes every stopped human's velocity, the recorded people's too: the
    batch used to skip it in worlds where nobody arrived, so its recorded velocities differed from the single simulator's."""
    _write(tmp_path / "walk.txt")
    source = (REPO / "scenarios" / "open_space.yaml").read_text()
    head = source.split("humans:\n")[0]
    (tmp_path / "mixed.yaml").write_text(head + """humans:
  radius: 0.3
  preferred_speed: [0.3, 0.7]
  replay: {file: walk.txt}
  groups:
    - {name: recorded, count: 3, model: replay, spawn: [{type: rectangle, min: [-4.7, -4.7], max: [4.7, 4.7]}],
       goal: [{type: rectangle, min: [-4.5, -4.5], max: [4.5, 4.5]}]}
    - {name: walkers, count: 3, on_goal: stop, spawn: [{type: rectangle, min: [-4.7, -4.7], max: [-2, 4.7]}],
       goal: [{type: rectangle, min: [-4.5, -1], max: [-2.5, 1]}]}
time_step: 0.2
max_steps: 60
""")
    world = load_world(tmp_path / "mixed.yaml")
    assert Simulator(world).rules_every_step
    check_batch_equals_singles(world, worlds=3, first_seed=5, steps=150, rng_seed=1, scale=0.3)


def test_the_crowd_view_is_built_from_the_protocol_and_one_world_reads_as_a_row_of_k():
    declared = [name for name, member in vars(CrowdView).items() if isinstance(member, property)]
    assert list(VIEWED) == declared and all(isinstance(getattr(StateView, name), property) for name in declared)
    assert FROM_STATE == set(declared) & {f.name for f in dataclasses.fields(StateFields)} and FROM_STATE
    source = (REPO / "crowdnav" / "crowd" / "views.py").read_text()
    strings = {node.value for node in ast.walk(ast.parse(source)) if isinstance(node, ast.Constant) and isinstance(node.value, str)}
    assert not strings & FROM_STATE, "views.py names a state field again: read it from the declaration"
    sims = _worlds("station_hall", FIXED_STATION, 2, 10)
    stacked = StackedState.stack([sim.state for sim in sims])
    rows = np.array([1, 0])
    radii = sims[0].radii
    view = worlds_view(stacked, rows, stacked.positions[rows], stacked.velocities[rows], radii, sims[0].scenario.robot.max_speed,
                       lambda: np.stack([sims[row].social_force_commands() for row in rows]))
    for k, row in enumerate(rows):
        one, alone = view.world(k), world_view(sims[row])
        for name in (*declared, "social_force"):
            mine, theirs = (one.social_force(), alone.social_force()) if name == "social_force" else (getattr(one, name), getattr(alone, name))
            assert type(mine) is type(theirs) or name not in ONE_WORLD_SCALARS, name
            assert np.asarray(mine).tobytes() == np.asarray(theirs).tobytes(), name
        assert one.world(0) is one and alone.world(0) is alone
    assert {name for name in declared if np.ndim(getattr(view, name)) == np.ndim(getattr(view.world(0), name))} == SHARED_BY_WORLDS
