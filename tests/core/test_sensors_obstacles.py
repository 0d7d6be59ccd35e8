"""The ``obstacles`` modality: the nearest surface point of each of the nearest walls and pieces of furniture."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from shapely.geometry import LineString, Point

import crowdnav  # noqa: F401  (registers the ids)
from crowdnav import Simulator, load_scenario
from crowdnav.envs import CrowdNavEnv
from crowdnav.scenario import ScenarioError
from crowdnav.scenario.library import library_names
from crowdnav.scenario.schema import ObstaclesSensor
from crowdnav.sensors import ObstaclesModality

SCENARIO = {
    "description": "a walled 10 m room with a rotated table and a round table",
    "world": {"min": [-5, -5], "max": [5, 5]},
    "furniture": [
        {"type": "rectangle", "name": "table", "center": [2.0, 0.0], "size": [1.0, 2.0], "angle": 30},
        {"type": "circle", "name": "round", "center": [-1.5, 1.5], "radius": 0.5},
    ],
    "robot": {"start": {"type": "points", "points": [[0, 0]]}, "goal": {"type": "points", "points": [[0, -4]]}},
    "humans": {"count": 0},
}


def room(**sensor) -> tuple[Simulator, ObstaclesModality]:
    sim = Simulator(load_scenario({**SCENARIO, "sensors": {"obstacles": sensor}}))
    sim.reset(seed=0)
    return sim, ObstaclesModality(sim.world, sim.scenario.sensors.obstacles)


def place(sim: Simulator, robot: complex, heading: float) -> None:
    sim.positions[0], sim.robot_heading = robot, heading
    sim.refresh()


def expected_rows(sim: Simulator, count: int, max_range: float) -> np.ndarray:
    """Shapely's nearest point of every static shape, nearest first, rotated into the robot frame."""
    robot, heading = complex(sim.positions[0]), sim.robot_heading
    obstacles = sim.world.obstacles
    discs = zip(obstacles.disc_center, obstacles.disc_radius, strict=True)
    shapes = list(obstacles.polygons) + [Point(c.real, c.imag).buffer(r, 4096) for c, r in discs]
    points = []
    for shape in shapes:
        nearest = shape.exterior.interpolate(shape.exterior.project(Point(robot.real, robot.imag)))
        points.append(complex(nearest.x, nearest.y) - robot)
    points.sort(key=abs)
    rows = np.zeros((count, 3))
    for i, offset in enumerate(points[:count]):
        if abs(offset) <= max_range:
            local = offset * complex(math.cos(heading), -math.sin(heading))
            rows[i] = (local.real, local.imag, 1.0)
    return rows


@pytest.mark.parametrize("robot, heading", [(0j, 0.0), (1.0 - 0.5j, 1.0), (-3.5 + 3.9j, -2.5), (4.2 + 0.1j, math.pi)])
def test_rows_are_the_nearest_surface_points_of_the_nearest_shapes_in_the_robot_frame(robot, heading):
    sim, modality = room(count=8, max_range=20.0)
    place(sim, robot, heading)
    rows = modality.observe(sim)
    assert rows.shape == (8, 3) and rows.dtype == np.float32
    # 4 boundary walls + the table + the round table: the last two slots stay empty
    np.testing.assert_allclose(rows, expected_rows(sim, 8, 20.0), atol=2e-4)  # the circle: a 4096-gon in shapely
    assert rows[:6, 2].tolist() == [1.0] * 6 and not rows[6:].any()
    assert modality.space().contains(rows)


def test_shapes_beyond_max_range_or_count_are_absent_rows_of_zeros():
    sim, modality = room(count=2, max_range=2.0)
    place(sim, 0.5 + 0.5j, 0.3)
    rows = modality.observe(sim)
    expected = expected_rows(sim, 2, 2.0)
    np.testing.assert_allclose(rows, expected, atol=2e-4)
    assert rows[:, 2].sum() == expected[:, 2].sum() >= 1
    far_sim, far = room(count=4, max_range=0.1)
    place(far_sim, 0j, 0.0)  # the nearest surface (the round table) is 1.6 m away
    assert not far.observe(far_sim).any()


def test_a_world_without_walls_or_furniture_reads_all_absent():
    env = gym.make("crowdnav/OpenSpace-v0", modalities=["obstacles", "goal"])
    observation, _ = env.reset(seed=0)
    assert observation["obstacles"].shape == (8, 3) and not observation["obstacles"].any()
    env.close()


OPEN = {**SCENARIO, "world": {"min": [-5, -4], "max": [6, 4], "boundary_walls": False},
        "robot": {**SCENARIO["robot"], "goal": {"type": "points", "points": [[0, -3]]}}}


def open_room(**sensor) -> tuple[Simulator, ObstaclesModality]:
    sim = Simulator(load_scenario({**OPEN, "sensors": {"obstacles": sensor}}))
    sim.reset(seed=0)
    return sim, ObstaclesModality(sim.world, sim.scenario.sensors.obstacles)


@pytest.mark.parametrize("robot, heading", [(0j, 0.0), (5.2 - 3.5j, 1.0), (-4.6 + 3.9j, -2.5), (6.5 + 4.5j, 0.4)])
def test_world_edge_lists_the_world_rectangles_sides_as_shapes_without_boundary_walls(robot, heading):
    sim, modality = open_room(count=8, max_range=20.0, world_edge=True)
    place(sim, robot, heading)
    # the sides as shapely lines (the last robot is outside the world, past its top-right corner)
    sides = [LineString([(-5, -4), (6, -4)]), LineString([(-5, 4), (6, 4)]), LineString([(-5, -4), (-5, 4)]),
             LineString([(6, -4), (6, 4)])]
    here = Point(robot.real, robot.imag)
    points = [complex(*side.interpolate(side.project(here)).coords[0]) - robot for side in sides]
    turn = complex(math.cos(heading), -math.sin(heading))  # into the robot frame
    sides_rows = [((p * turn).real, (p * turn).imag, 1.0) for p in points]
    furniture_rows = [tuple(row) for row in expected_rows(sim, 8, 20.0)[:2]]  # the table and the round table
    rows = sorted(furniture_rows + sides_rows, key=lambda row: math.hypot(row[0], row[1]))
    np.testing.assert_allclose(modality.observe(sim)[:6], np.array(rows), atol=2e-4)
    assert not modality.observe(sim)[6:].any()


def test_world_edge_changes_nothing_with_boundary_walls_and_nothing_by_default():
    walled_sim, walled = room(count=8, max_range=20.0)
    edged_sim, edged = room(count=8, max_range=20.0, world_edge=True)
    open_sim, plain = open_room(count=8, max_range=20.0)
    for robot, heading in [(0j, 0.0), (1.0 - 0.5j, 1.0), (4.2 + 0.1j, math.pi)]:
        for sim in (walled_sim, edged_sim, open_sim):
            place(sim, robot, heading)
        assert walled.observe(walled_sim).tobytes() == edged.observe(edged_sim).tobytes()
        assert plain.observe(open_sim)[:, 2].sum() == 2  # without world_edge an open world lists its furniture only


def test_settings_are_validated_with_a_one_line_error():
    with pytest.raises(ScenarioError, match="count"):
        load_scenario({**SCENARIO, "sensors": {"obstacles": {"count": 0}}})
    with pytest.raises(ScenarioError, match="max_range"):
        load_scenario({**SCENARIO, "sensors": {"obstacles": {"max_range": -1}}})
    assert ObstaclesSensor().count == 8 and ObstaclesSensor().max_range == 4.0 and not ObstaclesSensor().world_edge


def assert_observed_inside_its_space(scenario: str, key: str) -> None:
    """The env with modality ``key`` passes Gymnasium's check and every observation of a few random steps is in the space."""
    env = CrowdNavEnv(scenario=scenario, modalities=[key, "goal"])
    check_env(env, skip_render_check=True)
    observation, _ = env.reset(seed=1)
    for _ in range(5):
        assert env.observation_space[key].contains(observation[key])
        observation, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            break
    env.close()


@pytest.mark.parametrize("name", library_names())
def test_every_library_scenario_observes_obstacles_inside_the_space(name):
    assert_observed_inside_its_space(name, "obstacles")
