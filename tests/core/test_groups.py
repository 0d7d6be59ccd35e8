"""Human groups (humans.groups): own regions, speeds, goal rules and colours; standing circles; errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from crowdnav.envs import parallel_env
from crowdnav.scenario import ScenarioError
from crowdnav.sim.simulator import Simulator
from crowdnav.worlds.compiled import load_world

ROOM = {
    "description": "A test hall.",
    "world": {"min": [-6, -4], "max": [6, 4]},
    "robot": {
        "start": {"type": "rectangle", "min": [-5.5, -3.5], "max": [-4.5, -2.5]},
        "goal": {"type": "rectangle", "min": [4.5, 2.5], "max": [5.5, 3.5]},
    },
}
WEST = {"type": "rectangle", "min": [-5.8, -1.0], "max": [-3.5, 1.0]}
EAST = {"type": "rectangle", "min": [3.5, -1.0], "max": [5.8, 1.0]}
MIDDLE = {"type": "rectangle", "min": [-1.5, -1.5], "max": [1.5, 1.5]}


def hall(**humans) -> dict:
    return {**ROOM, "humans": humans}


def inside(points: np.ndarray, region: dict) -> np.ndarray:
    (x0, y0), (x1, y1) = region["min"], region["max"]
    margin = 0.06  # the placement jitter
    return (points.real >= x0 - margin) & (points.real <= x1 + margin) & (points.imag >= y0 - margin) & (points.imag <= y1 + margin)


def rollout(sim: Simulator, seed: int, steps: int) -> list[np.ndarray]:
    sim.reset(seed=seed)
    states = [sim.positions.copy()]
    for _ in range(steps):
        sim.step(np.array([0.3, 0.1]))
        states.append(np.concatenate([sim.positions, sim.human_goals]))
    return states


def test_a_file_without_groups_gives_the_same_episodes_as_the_same_crowd_written_as_one_group():
    crowd = {"count": [3, 6], "preferred_speed": [0.6, 1.1], "spawn": [WEST, EAST], "goal": [EAST, WEST], "on_goal": "respawn"}
    plain = Simulator(hall(**crowd))
    grouped = Simulator(hall(groups=[{"name": "flow", **crowd}]))
    assert [g.name for g in plain.groups] == ["crowd"] and [g.name for g in grouped.groups] == ["flow"]
    for seed in range(4):
        for a, b in zip(rollout(plain, seed, 60), rollout(grouped, seed, 60), strict=True):
            np.testing.assert_array_equal(a, b)


def test_each_walking_group_spawns_walks_to_and_draws_speeds_from_its_own_regions_and_range():
    sim = Simulator(hall(groups=[
        {"name": "eastbound", "count": 4, "preferred_speed": [0.5, 0.6], "spawn": [WEST], "goal": [EAST]},
        {"name": "westbound", "count": 3, "preferred_speed": [1.0, 1.1], "spawn": [EAST], "goal": [WEST]},
    ]))
    for seed in range(10):
        sim.reset(seed=seed)
        east, west = sim.human_group == 0, sim.human_group == 1
        assert east.sum() == 4 and west.sum() == 3
        assert inside(sim.human_positions[east], WEST).all() and inside(sim.human_goals[east], EAST).all()
        assert inside(sim.human_positions[west], EAST).all() and inside(sim.human_goals[west], WEST).all()
        assert (sim.human_preferred_speed[east] <= 0.6).all() and (sim.human_preferred_speed[west] >= 1.0).all()


def test_goal_rules_apply_per_group_stop_for_one_new_goal_for_the_other():
    sim = Simulator(hall(groups=[
        {"name": "stoppers", "count": 3, "spawn": [WEST], "goal": [{"type": "rectangle", "min": [-3, -3], "max": [3, 3]}], "on_goal": "stop"},
        {"name": "wanderers", "count": 3, "spawn": [EAST], "goal": [MIDDLE, EAST], "on_goal": "new_goal"},
    ]))
    sim.reset(seed=1)
    for _ in range(120):
        sim.step(np.zeros(2))
    stoppers, wanderers = sim.human_group == 0, sim.human_group == 1
    assert sim.human_stopped[stoppers].all() and not sim.human_stopped[wanderers].any()
    assert np.abs(sim.human_velocities[stoppers]).max() == 0.0 and np.abs(sim.human_velocities[wanderers]).max() > 0.1


def test_respawned_members_reappear_in_their_own_groups_spawn_regions():
    sim = Simulator(hall(groups=[
        {"name": "a", "count": 2, "spawn": [WEST], "goal_rule": "mirror", "mirror_center": [0, 0], "on_goal": "respawn"},
        {"name": "b", "count": 2, "spawn": [MIDDLE], "goal": [EAST], "on_goal": "respawn"},
    ]))
    sim.reset(seed=0)
    jumps = {0: 0, 1: 0}
    for _ in range(150):
        before = sim.human_positions.copy()
        sim.step(np.zeros(2))
        jumped = np.abs(sim.human_positions - before) > 0.5  # a respawn, not a walk
        for k in np.flatnonzero(jumped):
            group = int(sim.human_group[k])
            jumps[group] += 1
            assert inside(sim.human_positions[k : k + 1], [WEST, MIDDLE][group]).all()
    assert jumps[0] > 0 and jumps[1] > 0


def test_a_standing_group_is_a_still_circle_clear_of_obstacles_the_robot_and_its_goal():
    table = {"type": "circle", "center": [0.0, 0.0], "radius": 0.5}
    sim = Simulator({**hall(groups=[{"name": "talk", "count": [2, 5], "behaviour": "stand", "spawn": [MIDDLE]}]), "furniture": [table]})
    ring = (2 * 0.3 + 0.2) / (2 * math.sin(math.pi / 5))  # sized for the largest count
    counts = set()
    for seed in range(20):
        sim.reset(seed=seed)
        members = sim.human_positions
        counts.add(len(members))
        centre = members.mean()
        np.testing.assert_allclose(np.abs(members - centre), ring, atol=1e-9)
        pairs = np.abs(members[:, None] - members[None, :]) + 10 * np.eye(len(members))
        assert pairs.min() >= 0.6  # no overlap
        assert np.abs(members - 0).min() >= 0.5 + 0.3  # clear of the table
        assert np.abs(members - sim.robot_goal).min() >= 0.3 + 0.3 and np.abs(members - sim.robot_position).min() >= 0.6
        assert sim.human_stopped.all() and (sim.human_preferred_speed == 0).all()
        start = members.copy()
        for _ in range(40):
            sim.step(np.zeros(2))
        np.testing.assert_array_equal(sim.human_positions, start)
    assert counts == {2, 3, 4, 5}


def test_walkers_steer_around_a_standing_group_in_their_way():
    sim = Simulator(hall(groups=[
        {"name": "talk", "count": 4, "behaviour": "stand", "spawn": [{"type": "points", "points": [[0.0, 0.0]]}]},
        {"name": "walker", "count": 1, "preferred_speed": [1.0, 1.0], "spawn": [{"type": "points", "points": [[-4.0, 0.05]]}],
         "goal": [{"type": "points", "points": [[4.0, 0.05]]}], "on_goal": "stop"},
    ]))
    sim.reset(seed=0)
    closest = np.inf
    for _ in range(100):
        sim.step(np.zeros(2))
        walker = sim.human_positions[sim.human_group == 1][0]
        closest = min(closest, np.abs(sim.human_positions[sim.human_group == 0] - walker).min())
    assert abs(walker - 4.05) < 0.4  # it got past
    assert closest > 0.55  # without walking through the circle (contact distance: 0.6)


def test_groups_are_drawn_in_their_colours_and_named_in_the_legend():
    from crowdnav.rendering.renderer import Overlays, Renderer

    sim = Simulator(hall(groups=[
        {"name": "red", "count": 2, "spawn": [WEST], "goal": [EAST], "colour": "#ff0000"},
        {"name": "talk", "count": 3, "behaviour": "stand", "spawn": [MIDDLE]},
    ]))
    sim.reset(seed=0)
    renderer = Renderer(sim)
    assert renderer._group_colours[0] == (255, 0, 0) and renderer._group_colours[1] == renderer.palette.groups[1]
    labels = [label for _, label, _ in renderer._legend_entries(Overlays())]
    assert "red" in labels and "talk (standing)" in labels and "human" not in labels
    frame = renderer.frame()
    x, y = np.round(renderer.to_pixels(sim.human_positions[:1])[0]).astype(int)
    assert tuple(frame[y + 3, x + 3]) == (255, 0, 0)  # inside the disc, off the heading tick


def test_the_multi_agent_env_names_each_humans_group_in_its_infos():
    env = parallel_env("station_hall", modalities=["goal"])
    _, infos = env.reset(seed=0)
    groups = {infos[name]["group"] for name in env.agents if name != "robot"}
    assert groups == {"commuters", "shoppers", "talking", "meeting", "friends"}
    _, _, _, _, infos = env.step({agent: env.action_space(agent).sample() * 0 for agent in env.agents})
    assert {"group", "goal_reached"} <= set(infos["human_0"])


def test_library_group_scenarios_reset_many_times_without_running_out_of_room():
    for name in ("station_hall", "hotel_lobby"):
        sim = Simulator(name)
        for seed in range(150):
            sim.reset(seed=seed)
            gaps = np.abs(sim.positions[:, None] - sim.positions[None, :]) + 10 * np.eye(len(sim.positions))
            assert gaps.min() >= 0.6, (name, seed)


def test_groups_near_capacity_sharing_one_region_always_fit():
    # the loader's worst-case bound: if it accepts the counts, no reset may fail
    small = {"type": "rectangle", "min": [-2.0, -1.0], "max": [2.0, 1.0]}
    accepted = 0
    for first, second in [(3, 3), (4, 4), (5, 5), (6, 6), (8, 8)]:
        document = hall(groups=[{"name": "a", "count": first, "spawn": [small], "goal": [EAST]},
                                {"name": "b", "count": second, "spawn": [small], "goal": [WEST]}])
        try:
            sim = Simulator(document)
        except ScenarioError as error:
            assert "humans.groups.1.count" in str(error) and "groups listed before" in str(error)
            continue
        accepted += 1
        for seed in range(100):
            sim.reset(seed=seed)
    assert accepted >= 1


def write(tmp_path: Path, humans: dict) -> Path:
    path = tmp_path / "groups.yaml"
    path.write_text(yaml.safe_dump(hall(**humans), sort_keys=False), encoding="utf-8")
    return path


@pytest.mark.parametrize(("humans", "fragments"), [
    ({"count": 3, "spawn": [WEST], "goal": [EAST], "groups": [{"name": "a", "count": 1, "spawn": [WEST], "goal": [EAST]}]},
     ["humans.count: give the crowd either as humans.groups or with humans.count, humans.spawn, humans.goal, not both"]),
    ({"groups": [{"name": "a", "count": 1, "spawn": [WEST], "goal": [EAST]}, {"name": "a", "count": 1, "spawn": [EAST], "goal": [WEST]}]},
     ["humans: expected unique group names, got 'a' more than once"]),
    ({"groups": [{"name": "talk", "count": 3, "behaviour": "stand", "spawn": [MIDDLE], "goal": [EAST]}]},
     ["humans.groups.0: a standing group does not walk; remove goal"]),
    ({"groups": [{"name": "a", "count": 2, "spawn": [WEST], "goal": [EAST], "circle_radius": 1.0}]},
     ["humans.groups.0: circle_radius only applies to standing groups"]),
    ({"groups": [{"name": "talk", "count": 6, "behaviour": "stand", "circle_radius": 0.4, "spawn": [MIDDLE]}]},
     ["humans.groups.0.circle_radius: 6 humans of radius 0.3 m overlap on a circle of radius 0.4 m; expected at least 0.60 m"]),
    ({"groups": [{"name": "a", "count": 2, "spawn": [WEST], "goal": [EAST], "colour": "red"}]},
     ["humans.groups.0.colour: expected a colour '#rrggbb'"]),
    ({"groups": [{"name": "a/b", "count": 2, "spawn": [WEST], "goal": [EAST]}]},
     ["humans.groups.0.name: expected a name of 1-128 letters"]),
    ({"groups": [{"name": "a", "count": 2, "spawn": [WEST]}]},
     ["humans.groups.0.goal: expected at least one goal region when goal_rule is 'sample'"]),
    ({"groups": [{"name": "a", "count": 40, "spawn": [WEST], "goal": [EAST]}]},
     ["humans.groups.0.count: the spawn regions hold at most", "asked for up to 40"]),
    ({"groups": [{"name": "talk", "count": 4, "behaviour": "stand", "spawn": [{"type": "rectangle", "min": [-6, -4], "max": [-5.5, -3.5]}]}]},
     ["humans.groups.0.spawn.0:"]),
])
def test_group_mistakes_are_one_line_errors_with_file_line_and_field(tmp_path, humans, fragments):
    path = write(tmp_path, humans)
    with pytest.raises(ScenarioError) as caught:
        load_world(path)
    message = str(caught.value)
    assert message.startswith(f"{path}:") and "\n" not in message.strip()
    for fragment in fragments:
        assert fragment in message, message


def test_a_dumped_group_scenario_loads_again_as_the_same_scenario():
    # defaults are dumped too: the group rules judge values, not which keys were written
    from crowdnav.scenario.schema import Scenario

    for name in ("station_hall", "hotel_lobby"):
        scenario = Simulator(name).scenario
        assert Scenario.model_validate(scenario.model_dump()).model_dump() == scenario.model_dump()
