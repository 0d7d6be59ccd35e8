"""The shipped scenario library: every scenario loads, runs, and does what its description says."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import yaml
from pydantic import BaseModel
from shapely.geometry import Point

from crowdnav import Simulator, load_scenario
from crowdnav.scenario import schema
from crowdnav.scenario.library import camel_name, library_descriptions, library_dir, library_names
from tests.paths import REPO

REPO = REPO
NAMES = library_names()
REQUIRED = {
    "room_furniture", "open_space", "crowded_open_space", "corridor", "doorway", "circle_crossing", "perpendicular_crossing", "cafe", "empty_room",
}


def drive_to_goal(sim: Simulator) -> np.ndarray:
    """Holonomic full-speed action straight at the goal, in the robot frame."""
    direction = (sim.robot_goal - sim.robot_position) * np.exp(-1j * sim.robot_heading)
    direction /= max(abs(direction), 1e-9)
    return np.array([direction.real, direction.imag])


def test_library_holds_the_required_scenarios():
    assert REQUIRED <= set(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_library_file_has_description_and_comment_header(name):
    text = (library_dir() / f"{name}.yaml").read_text(encoding="utf-8")
    comments = [line for line in text.splitlines()[:6] if line.startswith("#") and "yaml-language-server" not in line]
    assert comments, f"{name}.yaml should start with a comment saying what the scenario is for"
    description = yaml.safe_load(text)["description"]
    assert "\n" not in description and 20 <= len(description) <= 160


@pytest.mark.parametrize("name", NAMES)
def test_library_scenario_runs_500_steps_with_random_actions(name):
    sim = Simulator(name)
    sim.reset(seed=7)
    rng = np.random.default_rng(7)
    episodes = 1
    for _ in range(500):
        events = sim.step(rng.uniform(-1.0, 1.0, size=2))
        assert np.isfinite(sim.positions).all()
        if events.outcome is not None:
            sim.reset()
            episodes += 1
    assert sim.n_humans <= sim.max_humans
    assert episodes >= 1


@pytest.mark.parametrize("name", NAMES)
def test_library_scenario_uses_realistic_numbers(name):
    scenario = load_scenario(name)
    assert scenario.time_step == pytest.approx(0.2)
    assert scenario.robot.radius == pytest.approx(0.3)
    if scenario.humans.max_count:
        assert scenario.humans.radius == pytest.approx(0.3)
        low, high = scenario.humans.preferred_speed
        assert 0.3 <= low <= high <= 1.2  # from strolling (open_space: 0.3-0.7 m/s) to brisk walking


@pytest.mark.parametrize("name", NAMES)
def test_library_scenario_gives_the_robot_time_to_reach_its_farthest_goal(name):
    sim = Simulator(name)
    placement, robot = sim.placement, sim.scenario.robot
    farthest = np.abs(placement.robot_start.points[:, None] - placement.robot_goal.points[None, :]).max()
    straight_line_steps = farthest / (robot.max_speed * sim.dt)
    assert sim.scenario.max_steps >= 1.5 * straight_line_steps


def test_empty_room_driving_straight_at_the_goal_always_succeeds():
    sim = Simulator("empty_room")
    for seed in range(10):
        sim.reset(seed=seed)
        assert sim.n_humans == 0
        events = sim.step(drive_to_goal(sim))
        while events.outcome is None:
            events = sim.step(drive_to_goal(sim))
        assert events.outcome == "success", f"seed {seed}"


def test_open_space_has_no_static_obstacles():
    sim = Simulator("open_space")
    assert sim.obstacles.polygon_count == 0 and sim.obstacles.disc_count == 0
    assert sim.max_humans > 0


def test_circle_crossing_humans_start_on_the_circle_and_head_for_the_opposite_point():
    sim = Simulator("circle_crossing")
    for seed in range(5):
        sim.reset(seed=seed)
        humans = sim.human_positions
        assert np.allclose(np.abs(humans), 4.0, atol=1e-6)
        assert np.allclose(sim.human_goals, -humans)
        assert sim.robot_position == pytest.approx(-4j) and sim.robot_goal == pytest.approx(4j)


def test_corridor_humans_start_at_an_end_and_walk_to_the_other():
    sim = Simulator("corridor")
    for seed in range(5):
        sim.reset(seed=seed)
        x = sim.human_positions.real
        assert (np.abs(x) >= 4.4).all()
        assert (np.sign(sim.human_goals.real) == -np.sign(x)).all()
        assert sim.robot_position.real < -5 and sim.robot_goal.real > 5


def test_doorway_door_is_1_2_m_wide_and_every_human_path_runs_through_it():
    sim = Simulator("doorway")
    sim.reset(seed=0)
    interior = [polygon for polygon, label in zip(sim.obstacles.polygons, sim.obstacles.labels, strict=True) if label.startswith("walls.")]
    assert len(interior) == 2
    assert [Point(0, 0).distance(polygon) for polygon in interior] == pytest.approx([0.6, 0.6])
    start, goal = sim.human_positions, sim.human_goals
    assert (np.sign(start.real) == -np.sign(goal.real)).all()
    # The straight start -> goal line crosses the dividing wall's line (x = 0) at the door's centre.
    t = start.real / (start.real - goal.real)
    assert np.abs((start + t * (goal - start)).imag) == pytest.approx(np.zeros(len(start)), abs=1e-9)
    assert sim.robot_position.real < 0 < sim.robot_goal.real


def test_perpendicular_crossing_humans_cross_sideways_while_the_robot_goes_up():
    sim = Simulator("perpendicular_crossing")
    sim.reset(seed=0)
    assert (np.sign(sim.human_goals.real) == -np.sign(sim.human_positions.real)).all()
    assert (np.abs(sim.human_positions.real) >= 3.4).all()
    assert sim.robot_position.imag < -4 and sim.robot_goal.imag > 4


def test_cafe_has_tables_and_chairs():
    sim = Simulator("cafe")
    labels = sim.obstacles.labels + sim.obstacles.disc_labels
    assert sum("table" in label for label in labels) >= 6
    assert sum("chair" in label for label in labels) >= 6


def test_camel_names_are_distinct_gymnasium_id_stems():
    ids = [camel_name(name) for name in NAMES]
    assert len(set(ids)) == len(ids)
    assert all(re.fullmatch(r"[A-Z][A-Za-z0-9]*", stem) for stem in ids)
    assert camel_name("circle_crossing") == "CircleCrossing"


def test_library_descriptions_match_the_files():
    descriptions = library_descriptions()
    assert set(descriptions) == set(NAMES)
    for name, description in descriptions.items():
        assert load_scenario(name).description == description


def test_committed_json_schema_is_up_to_date():
    committed = json.loads((REPO / "docs" / "scenario.schema.json").read_text(encoding="utf-8"))
    assert committed == schema.scenario_json_schema(), (
        "regenerate it: crowdnav scenario schema --output docs/scenario.schema.json"
    )


def _all_models(model: type[BaseModel], seen: set) -> set:
    seen.add(model)
    for field in model.model_fields.values():
        for sub in _models_in(field.annotation):
            if sub not in seen:
                _all_models(sub, seen)
    return seen


def _models_in(annotation) -> list:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in getattr(annotation, "__args__", ()) for m in _models_in(arg)]


def test_scenario_docs_mention_every_field_of_every_section():
    docs = (REPO / "docs" / "scenarios.md").read_text(encoding="utf-8")
    missing = [
        f"{model.__name__}.{name}"
        for model in _all_models(schema.Scenario, set())
        for name in model.model_fields
        if f"`{name}`" not in docs
    ]
    assert not missing, f"docs/scenarios.md does not document: {missing}"
