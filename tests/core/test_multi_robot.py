"""Several robots in one scenario (``robots:``): the schema and the simulator (the envs: test_multi_robot_envs.py)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from crowdnav.scenario.errors import ScenarioError
from crowdnav.scenario.loader import load_scenario
from crowdnav.sim.simulator import Simulator
from crowdnav.worlds.compiled import load_world
from tests.core.multi_robot_scenes import HALL, HEAD_ON, hall


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
        "  - start: {type: points, points: [[0, 0]]}\n"
        "    goal: {type: points, points: [[3, 0]]}\n"
        "  - start: {type: points, points: [[1, 1]]}\n"
        "    goal: {type: points, points: [[3, 3]]}\n"
        "    max_speed: -1\n",
        encoding="utf-8",
    )
    message = error_of(path)
    assert "two.yaml:7: robots.1.max_speed" in message, message


# ----------------------------------------------------------------------------- simulator

def test_robots_driving_head_on_both_collide_with_each_other():
    sim = Simulator(HEAD_ON)
    sim.reset(seed=0)
    for _ in range(20):
        events = sim.step(np.array([1.0, 0.0]), other_robot_actions=np.array([[1.0, 0.0]]))
        if events.terminated:
            break
    east, west = sim.robot_events
    assert east.collision.kind == "robot" and east.collision.partner == "west"
    assert west.collision.kind == "robot" and west.collision.partner == "east"
    assert east.outcome == west.outcome == "collision"


def test_a_retired_robot_leaves_the_world_and_no_longer_collides():
    sim = Simulator(HEAD_ON)
    sim.reset(seed=0)
    sim.retire_robots([1])
    for _ in range(30):
        events = sim.step(np.array([1.0, 0.0]), other_robot_actions=np.array([[1.0, 0.0]]))
        assert sim.robot_events[1] is None
        if events.terminated:
            break
    assert events.outcome == "success"
    assert not sim.robots_active[1] and sim.team.state.left_at[1] == 1.5 + 0j


def _human_pushed_by_other_robot(see_robot: bool, model: str = "social_force") -> complex:
    document = hall(humans={"count": 1, "see_robot": see_robot, "model": model, "spawn": [{"type": "points", "points": [[1.5, 0.8]]}],
                            "goal": [{"type": "points", "points": [[1.5, 4]]}]})
    document["robots"] = copy.deepcopy(HEAD_ON["robots"])
    document["robots"][1]["start"] = {"type": "points", "points": [[1.5, 1.6]]}  # right in the human's way
    sim = Simulator(document)
    sim.reset(seed=0)
    return complex(sim.crowd_commands()[0])


def test_humans_are_repelled_by_every_robot_they_see():
    seen, unseen = _human_pushed_by_other_robot(True), _human_pushed_by_other_robot(False)
    assert unseen.imag > 0.0  # toward its goal, up
    assert seen.imag < unseen.imag  # the second robot above it pushes it back down


def test_an_orca_crowd_avoids_every_robot_it_sees():
    pytest.importorskip("pyrvo")
    seen, unseen = _human_pushed_by_other_robot(True, "orca"), _human_pushed_by_other_robot(False, "orca")
    assert seen != unseen


def test_every_robot_is_drawn_clear_of_the_others_and_the_crowd():
    sim = Simulator(hall(humans={**HALL["humans"], "count": 8}))
    for seed in range(20):
        sim.reset(seed=seed)
        robots = sim.robot_positions
        assert abs(robots[0] - robots[1]) > 0.6
        assert (np.abs(sim.human_positions[:, None] - robots[None, :]) > 0.6).all()


def test_same_seed_gives_the_same_multi_robot_episode_bit_for_bit():
    def run():
        sim = Simulator(hall(humans={**HALL["humans"], "count": 6, "see_robot": True}))
        sim.reset(seed=5)
        trace = []
        for _ in range(40):
            sim.step(np.array([0.8, 0.1]), other_robot_actions=np.array([[0.5, -0.2]]))
            trace.append(np.concatenate([sim.positions, sim.robot_positions]))
        return np.array(trace)

    assert np.array_equal(run(), run())


def test_one_robot_scenarios_have_no_team_and_see_themselves_as_the_view():
    sim = Simulator("room_furniture")
    sim.reset(seed=0)
    assert sim.team is None and sim.robot_count == 1 and sim.robot_view(0) is sim
    events = sim.step(np.zeros(2))
    assert sim.robot_events == [events]


def test_bad_other_robot_actions_and_indices_are_one_line_errors():
    sim = Simulator(HEAD_ON)
    sim.reset(seed=0)
    before = sim.robot_positions
    with pytest.raises(ValueError, match=r"other_robot_actions must be 1 finite rows of 2 values .* got shape \(2, 2\)"):
        sim.step(np.zeros(2), other_robot_actions=np.zeros((2, 2)))
    with pytest.raises(ValueError, match="other_robot_actions must be"):
        sim.step(np.ones(2), other_robot_actions=np.array([[np.nan, 0.0]]))
    assert np.array_equal(sim.robot_positions, before) and sim.step_count == 0  # nothing moved
    with pytest.raises(ValueError, match=r"robot indices must be in \[0, 1\], got \[2\]"):
        sim.retire_robots([2])
    with pytest.raises(ValueError, match="retire_robots needs a scenario with robots:"):
        Simulator("open_space").retire_robots([0])


def test_a_robot_view_offers_the_pair_tables_a_custom_modality_reads():
    sim = Simulator(HALL)
    sim.reset(seed=1)
    view = sim.robot_view(1)
    assert view.n_humans == sim.n_humans + 1 and view.pair_offset.shape == (view.n_humans + 1,) * 2
    np.testing.assert_allclose(view.pair_offset[0, 1:], view.human_positions - view.robot_position)
    assert view.pair_distance[0, -1] == abs(sim.robot_positions[0] - sim.robot_positions[1])  # the other robot, last
    people = sim.robot_view(1, with_robots=False)
    assert people.n_humans == sim.n_humans


def test_the_crowd_capacity_check_counts_every_robots_start():
    crowded = {"count": 24, "spawn": [{"type": "rectangle", "min": [-4.6, -2.5], "max": [-2.0, 2.5]}],
               "goal": [{"type": "rectangle", "min": [-2, 3], "max": [2, 4]}]}
    robots = [{"start": {"type": "points", "points": [[-4, -0.6]]}, "goal": {"type": "points", "points": [[4, 0]]}},
              {"start": {"type": "points", "points": [[-4, 0.6]]}, "goal": {"type": "points", "points": [[4, 3]]}}]
    document = hall(humans=crowded)
    document.pop("robots")
    load_world({**document, "robot": robots[0]})  # room for 24 next to the first robot alone
    with pytest.raises(ScenarioError, match=r"humans.count: the spawn regions hold at most 22 humans .* next to the robots"):
        load_world({**document, "robots": robots})


def test_robots_sharing_one_start_point_are_refused_at_validation_naming_both_regions():
    same = {"type": "points", "points": [[-4, 0]]}
    with pytest.raises(ScenarioError, match=r"^<mapping>: robots.1.start: no start is sure to be left for this robot \(radius 0.3 m\): "
                       r"the robots drawn before it \(robots.0.start\) can leave none of its 1 start position free; expected"):
        load_world(hall(robots=[{"start": same, "goal": {"type": "points", "points": [[4, 0]]}},
                                {"start": same, "goal": {"type": "points", "points": [[4, 2]]}}]))


def test_social_force_robots_driving_head_on_feel_each_other_and_do_not_collide():
    from crowdnav.planning.scripted import SocialForceRobot

    sim, policy = Simulator(HEAD_ON), SocialForceRobot()
    sim.reset(seed=0)
    for _ in range(60):
        east, west = policy(sim.robot_view(0)), policy(sim.robot_view(1))
        events = sim.step(east, other_robot_actions=west[None, :])
        if events.terminated:
            break
    assert [event.collision for event in sim.robot_events] == [None, None]  # blind to each other they collide at step 6


def test_the_social_force_robot_feels_no_other_robot_in_a_one_robot_world():
    sim = Simulator("open_space")
    sim.reset(seed=0)
    assert len(sim.positions[sim.other_robot_discs]) == 0
