"""The vector env's two engines (crowdnav.envs.engines.protocol): the same protocol, the same worlds, and no one branching on which."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import numpy as np
import pytest

from crowdnav.batch.robot_policies import social_force_robots
from crowdnav.envs.core import load_env_world
from crowdnav.envs.engines.per_world import TeamWorlds
from crowdnav.envs.engines.protocol import WorldEngine
from crowdnav.envs.engines.stacked import StackedWorlds
from crowdnav.envs.engines.stacked_team import StackedTeamWorlds, first_robot_modalities
from crowdnav.planning.shield import validate_shield
from crowdnav.worlds.compiled import load_world

ROOT = Path(__file__).resolve().parents[2]
ENGINE_TYPES = {"BatchSimulator", "TeamWorlds", "StackedWorlds", "StackedTeamWorlds", "StackedRobots", "SingleRobots"}
PROTOCOL = [name for name, member in vars(WorldEngine).items() if inspect.isfunction(member) and not name.startswith("_")]


@pytest.mark.parametrize("engine", [StackedWorlds, StackedTeamWorlds, TeamWorlds])
def test_each_engine_has_every_method_of_the_protocol_with_its_parameters(engine: type) -> None:
    for name in PROTOCOL:
        ours = inspect.signature(getattr(engine, name)).parameters
        declared = inspect.signature(getattr(WorldEngine, name)).parameters
        assert list(ours) == list(declared), f"{engine.__name__}.{name}{list(ours)} != WorldEngine.{name}{list(declared)}"


def test_no_module_branches_on_which_engine_holds_the_worlds() -> None:
    offenders = []
    for folder in ("crowdnav", "agents", "evaluation"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "isinstance" and len(node.args) == 2:
                    named = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)}
                    if named & ENGINE_TYPES:
                        offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert offenders == []


def _engines(scenario: str, overrides: dict[str, object], keys: list[str]) -> tuple[StackedWorlds, TeamWorlds, dict[str, np.ndarray]]:
    world, modalities = load_env_world(scenario, {**overrides, "sensors.modalities": keys})
    if world.scenario.robots is not None:  # several robots: the first robot's modalities, the others driven by the social-force robot
        stacked: StackedWorlds = StackedTeamWorlds(world, 3, first_robot_modalities(world), social_force_robots)
    else:
        stacked = StackedWorlds(world, 3, modalities)
    team = TeamWorlds(world, 3)
    out = {key: np.zeros((3, *modality.space().shape), dtype=modality.space().dtype) for key, modality in team.modalities.items()}
    return stacked, team, out


@pytest.mark.parametrize("scenario", ["room_furniture", "open_space", "robots_crossing_hall"])
def test_stacked_and_single_env_engines_play_the_same_worlds_bit_for_bit(scenario: str) -> None:
    stacked, team, out = _engines(scenario, {"humans.count": 4}, ["goal", "lidar", "humans", "velocity", "closest_obstacle"])
    seeds = [11, 12, 13]
    for engine in (stacked, team):
        engine.reset(np.arange(3), seeds)
    rng = np.random.default_rng(0)
    every = np.ones(3, dtype=bool)
    for step in range(40):
        actions = rng.uniform(-1, 1, size=(3, 2))
        active = every if step % 5 else np.array([True, False, True])
        results = [engine.step(actions, None if active.all() else active) for engine in (stacked, team)]
        judged = [engine.judged(result, active, bool(active.all())) for engine, result in zip((stacked, team), results, strict=True)]
        (outcome_a, rewards_a, terms_a), (outcome_b, rewards_b, terms_b) = judged
        assert list(outcome_a) == list(outcome_b)
        np.testing.assert_array_equal(rewards_a, rewards_b)
        for term in terms_a:
            np.testing.assert_array_equal(terms_a[term], terms_b[term])
        observed = []
        for engine in (stacked, team):
            values = {key: array.copy() for key, array in out.items()}
            engine.observe(values)
            observed.append(values)
        for key in out:
            np.testing.assert_array_equal(observed[0][key], observed[1][key])
        assert stacked.other_robots(active) == team.other_robots(active)
        np.testing.assert_array_equal(stacked.stalls(), team.stalls())
        np.testing.assert_array_equal(stacked.social_force(), team.social_force())
        for world in range(3):
            a, b = stacked.frame(world), team.frame(world)
            for name in a:
                np.testing.assert_array_equal(a[name], b[name])
            assert stacked.robot_goal(world) == team.robot_goal(world)
        ended = np.flatnonzero((results[0].terminated | results[0].truncated) & active)
        if len(ended):  # both engines restart the ended worlds from their own generators
            for engine in (stacked, team):
                engine.reset(ended, [None] * len(ended))


def test_both_engines_shield_an_action_alike() -> None:
    stacked, team, _ = _engines("room_furniture", {"humans.count": 4}, ["goal"])
    shield = validate_shield(True, load_world("room_furniture", {"humans.count": 4}))
    assert shield is not None
    for engine in (stacked, team):
        engine.reset(np.arange(3), [5, 6, 7])
    actions = np.tile([1.0, 0.0], (3, 1))
    (out_a, replaced_a), (out_b, replaced_b) = stacked.shielded(shield, actions), team.shielded(shield, actions)
    np.testing.assert_array_equal(out_a, out_b)
    np.testing.assert_array_equal(replaced_a, replaced_b)
