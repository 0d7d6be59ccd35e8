"""Several robots in one scenario (``robots:``): schema, simulator, both envs, rendering."""

from __future__ import annotations

import copy

import pytest

from crowdnav.scenario.errors import ScenarioError
from crowdnav.scenario.loader import load_scenario

HALL = {
    "description": "Two robots swap sides of an empty hall.",
    "world": {"min": [-5, -5], "max": [5, 5]},
    "robots": [
        {"name": "east", "start": {"type": "rectangle", "min": [-4.5, -1], "max": [-3.5, 1]},
         "goal": {"type": "rectangle", "min": [3.5, -1], "max": [4.5, 1]}},
        {"name": "west", "start": {"type": "rectangle", "min": [3.5, -1], "max": [4.5, 1]},
         "goal": {"type": "rectangle", "min": [-4.5, -1], "max": [-3.5, 1]}},
    ],
    "humans": {"count": 4, "spawn": [{"type": "rectangle", "min": [-2, -4], "max": [2, -3]}],
               "goal": [{"type": "rectangle", "min": [-2, 3], "max": [2, 4]}]},
}


def hall(**changes):
    document = copy.deepcopy(HALL)
    document.update(changes)
    return document


def error_of(document) -> str:
    with pytest.raises(ScenarioError) as caught:
        load_scenario(document)
    return str(caught.value)


def test_robots_list_names_the_agents_and_its_first_entry_is_the_ego_robot():
    scenario = load_scenario(hall())
    assert scenario.robot_names == ["east", "west"]
    assert scenario.robot is scenario.robots[0]
    assert load_scenario(scenario.model_dump()).robot_names == ["east", "west"]  # a dump loads again: no robot written


def test_unnamed_robots_are_robot_i_and_one_robot_keeps_the_name_robot():
    document = hall()
    for robot in document["robots"]:
        del robot["name"]
    assert load_scenario(document).robot_names == ["robot_0", "robot_1"]
    assert load_scenario("room_furniture").robot_names == ["robot"]


def test_robot_and_robots_together_is_an_error_at_robots():
    one = {key: value for key, value in HALL["robots"][0].items() if key != "name"}
    assert error_of(hall(robot=one)).endswith("robots: give either robot (one robot) or robots (several), not both")


def test_a_single_entry_under_robots_asks_for_at_least_two():
    assert "robots: expected at least 2 items" in error_of(hall(robots=HALL["robots"][:1]))


def test_repeated_robot_names_are_an_error():
    robots = copy.deepcopy(HALL["robots"])
    robots[1]["name"] = "east"
    assert error_of(hall(robots=robots)).endswith("robots: expected unique robot names, got 'east' more than once")


@pytest.mark.parametrize("name", ["robot", "human_0", "East", "a-b"])
def test_a_robot_name_that_could_clash_with_agent_names_is_refused(name):
    robots = copy.deepcopy(HALL["robots"])
    robots[1]["name"] = name
    assert "robots.1.name: expected lowercase letters" in error_of(hall(robots=robots))


def test_cross_field_rules_name_the_robot_in_the_list():
    robots = copy.deepcopy(HALL["robots"])
    robots[1]["kinematics"] = "unicycle"
    assert "robots.1.max_angular_speed: expected a maximum angular speed" in error_of(hall(robots=robots))


def test_file_errors_carry_the_line_of_the_robot(tmp_path):
    path = tmp_path / "two.yaml"
    path.write_text(
        "description: two robots\n"
        "robots:\n"
        "  - start: {type: point, position: [0, 0]}\n"
        "    goal: {type: point, position: [3, 0]}\n"
        "  - start: {type: point, position: [1, 1]}\n"
        "    goal: {type: point, position: [3, 3]}\n"
        "    max_speed: -1\n",
        encoding="utf-8",
    )
    message = error_of(path)
    assert "two.yaml:7: robots.1.max_speed" in message, message
