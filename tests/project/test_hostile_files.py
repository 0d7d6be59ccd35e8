"""Hostile or broken files cost little: every file kind is refused with one line naming the file.

(Measured times are in docs/security.md; tests assert outcomes, never times.)
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml
from crowdnav.agents.training.config import ConfigError, load_config
from crowdnav.evaluation.experiment import ExperimentError, load_experiment

from crowdnav import ScenarioError, load_scenario
from crowdnav.scenario.library import library_dir
from crowdnav.worlds.compiled import load_world

BOMB = "\n".join(
    [f"l0: &l0 [{', '.join(['lol'] * 9)}]"] + [f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 9)}]" for i in range(1, 9)]
)
HOSTILE = {
    "alias bomb": (BOMB, "values once its aliases are expanded"),
    "10 MB": ("x: " + "a" * 10_000_000, "characters; expected at most"),
    "400,000 keys": ("\n".join(f"k{i}: {i}" for i in range(400_000)), "characters; expected at most"),
    "10,000 nesting levels": ("a: " + "[" * 10_000 + "]" * 10_000, "nest"),
    "recursive alias": ("a: &a [1, *a]", "recursive aliases"),
}
LOADERS = {
    "scenario": (load_scenario, ScenarioError),
    "training config": (load_config, ConfigError),
    "experiment": (load_experiment, ExperimentError),
}


@pytest.mark.parametrize("kind", LOADERS)
@pytest.mark.parametrize("case", HOSTILE)
def test_hostile_yaml_is_refused_in_one_line_naming_the_file(tmp_path, kind, case):
    text, expected = HOSTILE[case]
    path = tmp_path / "hostile.yaml"
    path.write_text(text)
    load, error = LOADERS[kind]
    with pytest.raises(error) as caught:
        load(path)
    message = str(caught.value)
    assert str(path) in message and expected in message and len(message.splitlines()) == 1


def _set_dotted(document: dict, changes: dict) -> dict:
    """``document`` with each dotted path (``humans.radius``) set to its value."""
    for dotted, value in changes.items():
        node = document
        *parents, last = dotted.split(".")
        for part in parents:
            node = node[part]
        node[last] = value
    return document


def _room(**changes) -> dict:
    document = yaml.safe_load((library_dir() / "room_furniture.yaml").read_text())
    document = copy.deepcopy(document)
    return _set_dotted(document, changes)


def test_five_thousand_obstacles_are_refused_naming_the_field():
    discs = [{"type": "circle", "center": [float(x), float(y)], "radius": 0.1} for x, y in np.random.default_rng(0).uniform(-4, 4, (5000, 2))]
    with pytest.raises(ScenarioError, match=r"furniture: expected at most 2000 items"):
        load_world(_room(furniture=discs))


def test_a_huge_world_covered_by_regions_loads_on_a_bounded_lattice():
    full = {"type": "rectangle", "min": [-5000, -5000], "max": [5000, 5000]}
    document = _room(**{"world.min": [-5000, -5000], "world.max": [5000, 5000], "robot.start": full, "robot.goal": full,
                        "humans.spawn": [full, full], "humans.goal": [full], "furniture": [], "walls": []})
    world = load_world(document)
    from crowdnav.worlds.placement import MAX_CANDIDATES

    assert len(world.placement.robot_start) <= 1.2 * MAX_CANDIDATES and len(world.placement.groups[0].spawn) <= 2.4 * MAX_CANDIDATES


@pytest.mark.parametrize(
    ("dotted", "value", "message"),
    [
        ("robot.radius", True, "robot.radius: expected a number, got True"),
        ("world.max", ["1e3", 5], "world.max.0: expected a number, got '1e3'"),
        ("humans.radius", 1e308, "humans.radius: expected a number <= 10000"),
        ("humans.count", 10**400, "humans.count: expected a count from 0 to 10,000"),
        ("max_steps", 2**63, "max_steps: expected an integer <= 100000"),
        ("robot.goal_radius", 1e-300, "robot.goal_radius: expected a number >= 0.01"),
        ("robot.goal_radius", 50.0, "robot.goal_radius: a start in robot.start can lie within the goal radius"),
        ("world.min", [-1e5, -1e5], "world.min.0: expected a value >= -10000"),
    ],
)
def test_values_that_only_overflow_later_or_make_the_task_meaningless_name_their_field(dotted, value, message):
    with pytest.raises(ScenarioError, match=message.replace("(", r"\(").replace(")", r"\)").replace(".", r"\.").replace("*", r"\*")):
        load_world(_room(**{dotted: value}))


def test_protocol_counts_too_large_for_numpy_name_their_field():
    from crowdnav.evaluation.protocol import Protocol

    with pytest.raises(ValueError, match=r"test_episodes: expected an integer <= 1000000"):
        Protocol(test_episodes=2**63)


def _walled_room(**changes) -> dict:
    """The empty 10 m room split by a full-height wall at x = 0 (no door)."""
    document = yaml.safe_load((library_dir() / "empty_room.yaml").read_text())
    document["walls"] = [{"points": [[0.0, -5.0], [0.0, 5.0]], "thickness": 0.2}]
    return _set_dotted(document, changes)


def test_a_robot_goal_region_walled_off_from_the_starts_is_refused():
    left, right = {"type": "rectangle", "min": [-4.5, -4.5], "max": [-1.0, 4.5]}, {"type": "rectangle", "min": [1.0, -4.5], "max": [4.5, 4.5]}
    with pytest.raises(ScenarioError, match=r"robot\.goal: no goal in robot\.goal can be reached from a start in robot\.start"):
        load_world(_walled_room(**{"robot.start": left, "robot.goal": right, "robot.min_start_goal_distance": 0.0}))


def test_partly_reachable_regions_only_pair_starts_and_goals_on_the_same_side():
    import numpy as np

    from crowdnav import Simulator

    both = {"type": "rectangle", "min": [-4.5, -4.5], "max": [4.5, 4.5]}
    document = _walled_room(**{"robot.start": both, "robot.goal": both, "robot.min_start_goal_distance": 1.0})
    sim = Simulator(document)
    for seed in range(30):
        sim.reset(seed=seed)
        assert np.sign(sim.robot_position.real) == np.sign(sim.robot_goal.real)


def test_human_regions_walled_off_from_each_other_are_refused():
    left, right = {"type": "rectangle", "min": [-4.5, -4.5], "max": [-1.0, 4.5]}, {"type": "rectangle", "min": [1.0, -4.5], "max": [4.5, 4.5]}
    document = _walled_room(**{"humans.count": 2, "humans.spawn": [left], "humans.goal": [right]})
    with pytest.raises(ScenarioError, match=r"humans\.goal\.0: region is walled off from the group.s other regions"):
        load_world(document)


L_HALL = {
    "description": "An L-shaped hallway.",
    "world": {"points": [[0, 0], [10, 0], [10, 2], [2, 2], [2, 8], [0, 8]]},
    "robot": {"start": {"type": "rectangle", "min": [8, 0.4], "max": [9.6, 1.6]},
              "goal": {"type": "rectangle", "min": [0.4, 6], "max": [1.6, 7.6]}},
    "humans": {"count": 3, "spawn": [{"type": "rectangle", "min": [0.4, 0.4], "max": [1.6, 7.6]}],
               "goal": [{"type": "rectangle", "min": [0.4, 0.4], "max": [9.6, 1.6]}]},
}


def test_a_polygon_world_is_solid_outside_its_floor_for_placement_sensors_and_collisions():
    import numpy as np

    from crowdnav import CrowdNavEnv

    world = load_world(L_HALL)
    assert world.scenario.world.min == (0.0, 0.0) and world.scenario.world.max == (10.0, 8.0)  # the floor's bounds
    assert "world.outside" in world.obstacles.labels
    env = CrowdNavEnv(L_HALL, modalities=["lidar", "goal"])
    for seed in range(5):
        observation, _ = env.reset(seed=seed)
        assert env.simulator.robot_position.imag < 2.0 and env.simulator.robot_goal.real < 2.0
        assert observation["lidar"].min() < 1.0  # the hallway's walls, 2 m apart, are seen
    env.reset(seed=0)
    for _ in range(40):  # driving sideways in a 2 m hallway ends against its walls: a static collision
        _, _, terminated, _, info = env.step(np.array([0.0, 1.0]))
        if terminated:
            break
    assert info.get("collision_kind") == "static"
    closed_off = {**L_HALL, "robot": {**L_HALL["robot"], "goal": {"type": "rectangle", "min": [6, 5], "max": [8, 7]}}}
    with pytest.raises(ScenarioError, match=r"robot\.goal: region is entirely covered by obstacles"):
        load_world(closed_off)
    with pytest.raises(ScenarioError, match=r"world\.points: polygon is not valid"):
        load_world({**L_HALL, "world": {"points": [[0, 0], [4, 4], [4, 0], [0, 4]]}})
