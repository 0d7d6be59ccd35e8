"""The ``geodesic`` modality: the distance to the goal around walls and furniture, on a grid centred on the robot."""

from __future__ import annotations

import math

import numpy as np
import pytest

import crowdnav  # noqa: F401  (registers the ids)
from crowdnav import Simulator, load_scenario
from crowdnav.planning.predictive import PlannerSettings
from crowdnav.planning.static_map import MapCache
from crowdnav.scenario import ScenarioError
from crowdnav.scenario.library import library_names
from crowdnav.sensors import GeodesicModality
from tests.core.test_sensors_obstacles import assert_observed_inside_its_space

WALLED = {
    "description": "a 10 m room cut by a wall from the north, open 2 m at its south end",
    "world": {"min": [-5, -5], "max": [5, 5]},
    "walls": [{"points": [[0, 5], [0, -3]], "thickness": 0.2}],
    "robot": {"start": {"type": "points", "points": [[-2, 2]]}, "goal": {"type": "points", "points": [[2, 2]]}},
    "humans": {"count": 0},
}


def world(scenario=WALLED, **sensor) -> tuple[Simulator, GeodesicModality]:
    sim = Simulator(load_scenario({**scenario, "sensors": {"geodesic": sensor}}))
    sim.reset(seed=0)
    return sim, GeodesicModality(sim.world, sim.scenario.sensors.geodesic)


@pytest.mark.parametrize("heading", [0.0, 0.7, -2.0])
def test_each_entry_is_the_planners_distance_at_its_point_of_the_robot_frame(heading):
    sim, modality = world(size=5, spacing=0.25)
    sim.robot_heading = heading
    sim.refresh()
    grid = modality.observe(sim)
    settings = PlannerSettings()
    field = MapCache(settings.static_margin, settings.map_spacing).field(sim.world, complex(sim.robot_goal))
    turn = complex(math.cos(heading), math.sin(heading))
    for i in range(5):
        for j in range(5):
            point = complex(sim.positions[0]) + turn * complex((i - 2) * 0.25, (j - 2) * 0.25)
            assert grid[i, j] == pytest.approx(float(field(np.array([point]))[0]), rel=1e-6)


def test_the_distance_goes_around_the_wall_and_is_euclidean_in_an_empty_room():
    sim, modality = world()
    around = float(modality.observe(sim)[4, 4])
    detour = math.hypot(1.9, 5.1) * 2  # at least: down to the wall's end (-0.1 or 0.1, -3.1) and back up
    # the 8-connected wavefront's octile metric overestimates a straight line by up to 8.3%, plus the cells at the corner
    assert detour <= around <= 1.2 * detour
    empty, open_modality = world({**WALLED, "walls": []})
    assert float(open_modality.observe(empty)[4, 4]) == pytest.approx(4.0, abs=0.05)


def test_the_distance_keeps_rising_into_a_walls_margin_and_a_grid_without_a_standing_point_reads_the_bound():
    sim, modality = world(size=9, spacing=0.1)
    sim.positions[0], sim.robot_heading = -0.5 + 2j, 0.0  # 0.4 m from the wall's face: +x points reach into its margin
    sim.refresh()
    grid = modality.observe(sim)
    toward = grid[4:, 4] if sim.robot_heading == 0.0 else None
    assert toward is not None and np.all(grid < modality.bound) and np.all(np.diff(toward) > 0)  # rising toward the wall
    assert modality.space().contains(grid)
    small, small_modality = world(size=3, spacing=0.1)
    small.positions[0] = 2j  # inside the wall: no grid point near a place to stand, nothing to measure from
    small.refresh()
    assert np.all(small_modality.observe(small) == small_modality.bound)


def test_settings_are_validated_with_a_one_line_error():
    with pytest.raises(ScenarioError, match="odd"):
        load_scenario({**WALLED, "sensors": {"geodesic": {"size": 4}}})
    with pytest.raises(ScenarioError, match="spacing"):
        load_scenario({**WALLED, "sensors": {"geodesic": {"spacing": 0}}})


@pytest.mark.parametrize("name", library_names())
def test_every_library_scenario_observes_the_geodesic_grid_inside_the_space(name):
    assert_observed_inside_its_space(name, "geodesic")
