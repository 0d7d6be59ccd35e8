"""Large crowds: the neighbour grid finds every close pair, and the grid geometry is the all-pairs model within its tolerance."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from crowdnav.envs import parallel_env
from crowdnav.sim.crowd_grid import PAIR_FORCE_TOLERANCE
from crowdnav.sim.neighbours import close_pairs
from crowdnav.sim.simulator import Simulator


def brute_force_pairs(points: np.ndarray, cutoff: float) -> set[tuple[int, int]]:
    distance = np.abs(points[:, None] - points[None, :])
    i, j = np.nonzero(np.triu(distance < cutoff, 1))
    return set(zip(i.tolist(), j.tolist(), strict=True))


@settings(max_examples=60, deadline=None)
@given(
    xs=st.lists(st.floats(-50, 50, allow_nan=False), min_size=0, max_size=80),
    cutoff=st.floats(0.05, 20),
    data=st.data(),
)
def test_close_pairs_finds_exactly_the_pairs_brute_force_finds_each_once(xs, cutoff, data):
    ys = data.draw(st.lists(st.floats(-50, 50, allow_nan=False), min_size=len(xs), max_size=len(xs)))
    points = np.array(xs) + 1j * np.array(ys) if xs else np.zeros(0, dtype=complex)
    i, j = close_pairs(points, cutoff)
    found = list(zip(i.tolist(), j.tolist(), strict=True))
    assert len(found) == len(set(found)) and all(a < b for a, b in found)
    assert set(found) == brute_force_pairs(points, cutoff)


def test_close_pairs_handles_points_stacked_on_one_spot_and_on_cell_borders():
    points = np.array([0, 0, 0, 1.0, 1.0 + 1e-12, 2.0, -1.0, -1.0 + 1j]) + 0j
    for cutoff in (0.5, 1.0, 1.5):
        i, j = close_pairs(points, cutoff)
        assert set(zip(i.tolist(), j.tolist(), strict=True)) == brute_force_pairs(points, cutoff)


HALL = {
    "description": "a busy hall",
    "world": {"min": [-12, -12], "max": [12, 12]},
    "furniture": [{"type": "circle", "center": [0, 0], "radius": 1.0}, {"type": "rectangle", "center": [6, -5], "size": [2, 1]}],
    "robot": {"start": {"type": "rectangle", "min": [-11, -11], "max": [-10, -10]},
              "goal": {"type": "rectangle", "min": [10, 10], "max": [11, 11]}},
    "humans": {"count": 300, "see_robot": True, "spawn": [{"type": "rectangle", "min": [-11.5, -11.5], "max": [11.5, 11.5]}],
               "goal": [{"type": "rectangle", "min": [-11, -11], "max": [11, 11]}]},
    "max_steps": 10_000,
}


def pair_of_simulators(seed: int) -> tuple[Simulator, Simulator]:
    all_pairs, grid = Simulator(HALL), Simulator(HALL)
    all_pairs.grid_from, grid.grid_from = 10**9, 0
    all_pairs.reset(seed=seed)
    grid.reset(seed=seed)
    assert all_pairs.geometry.grid is None and grid.geometry.grid is not None
    return all_pairs, grid


@pytest.mark.parametrize("seed", [0, 1])
def test_the_grid_geometry_is_the_all_pairs_geometry_within_the_stated_tolerance(seed):
    all_pairs, grid = pair_of_simulators(seed)
    np.testing.assert_array_equal(all_pairs.positions, grid.positions)
    # each left-out pair pushes less than the tolerance; a human has a few dozen of them here
    assert np.abs(all_pairs.geometry.repulsion - grid.geometry.repulsion).max() < 100 * PAIR_FORCE_TOLERANCE
    np.testing.assert_array_equal(all_pairs.geometry.robot_gap, grid.geometry.robot_gap)
    np.testing.assert_allclose(all_pairs.robot_distance, grid.robot_distance)
    assert all_pairs.geometry.humans_touch == grid.geometry.humans_touch
    for step in range(20):
        action = np.array([0.8, 0.3 * np.sin(step)])
        assert all_pairs.step(action) == grid.step(action)
        assert np.abs(all_pairs.positions - grid.positions).max() < 1e-3
    np.testing.assert_allclose(grid.pair_distance, np.abs(grid.positions[None, :] - grid.positions[:, None]) + 1e9 * np.eye(301), rtol=1e-12)


def test_overlapping_humans_are_pushed_apart_the_same_way_in_both_geometries():
    all_pairs, grid = pair_of_simulators(2)
    for sim in (all_pairs, grid):
        sim.positions[2] = sim.positions[1] + 0.4  # overlapping by 0.2 m
        sim.refresh()
        assert sim.geometry.humans_touch
        sim.geometry.push_humans_apart(sim.positions)
    np.testing.assert_allclose(all_pairs.positions, grid.positions, atol=1e-12)
    assert abs(grid.positions[2] - grid.positions[1]) >= 0.6 - 1e-9


def test_a_crowd_of_a_thousand_steps_with_finite_state_and_pays_its_social_term():
    sim = Simulator({**HALL, "world": {"min": [-30, -30], "max": [30, 30]},
                     "humans": {**HALL["humans"], "count": 1000, "spawn": [{"type": "rectangle", "min": [-29, -29], "max": [29, 29]}],
                                "goal": [{"type": "rectangle", "min": [-29, -29], "max": [29, 29]}]}})
    sim.reset(seed=0)
    assert sim.geometry.grid is not None
    for _ in range(30):
        sim.step(np.array([1.0, 0.0]))
    assert np.isfinite(sim.positions).all() and np.isfinite(sim.geometry.repulsion).all()
    gaps = np.abs(sim.human_positions[:, None] - sim.human_positions[None, :]) + 10 * np.eye(1000)
    assert gaps.min() > 0.6 - 0.05  # overlaps resolved each step (a push can leave a few cm)


def test_the_multi_agent_env_observes_a_grid_crowd_exactly_like_an_all_pairs_one():
    observations = []
    for grid_from in (10**9, 0):
        env = parallel_env("room_furniture", modalities=["goal", "closest_obstacle"])
        env.simulator.grid_from = grid_from
        observed, _ = env.reset(seed=5)
        assert (env.simulator.geometry.grid is not None) == (grid_from == 0)
        observations.append(observed)
    for agent, observed in observations[0].items():
        for key, value in observed.items():
            np.testing.assert_array_equal(value, observations[1][agent][key], err_msg=f"{agent}.{key}")
