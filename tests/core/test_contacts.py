"""The step's checks as kernels on K worlds: K at once equals each world alone, bit for bit."""

from __future__ import annotations

import numpy as np

from crowdnav import Simulator
from crowdnav.sim.contacts import deepest_contact, goal_distance, outside, push_humans_apart, push_out_of_obstacles, touching
from crowdnav.sim.state import SELF_DISTANCE
from crowdnav.worlds.obstacles import nearest_on_edges


def _crowded_worlds(sim: Simulator, k: int) -> np.ndarray:
    """(k, n+1) positions of ``sim``'s scenario with humans squeezed together and into the furniture."""
    rng = np.random.default_rng(0)
    worlds = []
    for seed in range(k):
        sim.reset(seed=seed)
        z = sim.positions.copy()
        z[1:] = z[1:] * 0.3 + rng.normal(0, 0.2, sim.n_humans) + 1j * rng.normal(0, 0.2, sim.n_humans)
        worlds.append(z)
    return np.stack(worlds)


def test_overlap_kernels_on_k_worlds_equal_each_world_alone_and_separate_the_crowd():
    sim = Simulator("room_furniture", {"humans.count": 12})
    z = _crowded_worlds(sim, 6)
    n = z.shape[1] - 1
    offset = z[:, None, 1:] - z[:, 1:, None]
    distance = np.abs(offset)
    distance.reshape(len(z), -1)[:, :: n + 1] = SELF_DISTANCE
    gap = distance - 2 * sim.scenario.humans.radius
    contact = sim.pair_constants(n).contact_all[1:, n + 1 :]
    together = z.copy()
    push_humans_apart(together, offset, distance, gap)
    assert _overlap(together, sim) < _overlap(z, sim)  # half the overlap each: pairs come apart
    inside = _inside(together, sim, contact)
    push_out_of_obstacles(together, sim.obstacles.surface, contact)
    assert inside > 0.05 and _inside(together, sim, contact) < inside / 10
    for k in range(len(z)):
        alone = z[k : k + 1].copy()
        push_humans_apart(alone, offset[k : k + 1], distance[k : k + 1], gap[k : k + 1])
        push_out_of_obstacles(alone, sim.obstacles.surface, contact)
        assert alone.tobytes() == together[k : k + 1].tobytes()
    assert (together[:, 0] == z[:, 0]).all()  # the robot is never pushed


def _overlap(z: np.ndarray, sim: Simulator) -> float:
    """Total overlap of the humans' bodies (m), over all pairs of all worlds."""
    d = np.abs(z[:, 1:, None] - z[:, None, 1:])
    d[:, np.eye(z.shape[1] - 1, dtype=bool)] = np.inf
    return float(np.maximum(2 * sim.scenario.humans.radius - d, 0.0).sum())


def _inside(z: np.ndarray, sim: Simulator, contact: np.ndarray) -> float:
    """How deep (m) the deepest human is inside an obstacle, over all worlds (0: none inside)."""
    _, distance = nearest_on_edges(z[:, 1:].reshape(-1), sim.obstacles.surface)
    return float(max(0.0, -(distance.reshape(len(z), z.shape[1] - 1, -1) - contact).min()))


def test_robot_checks_give_the_same_answer_for_one_world_and_for_many():
    gaps = np.array([[1e9, 0.4, 0.2, 0.3, 0.5], [1e9, 0.1, -0.05, 0.2, -0.2], [1e9, 0.3, 0.0, 0.1, 0.2]])
    assert touching(gaps).tolist() == [False, True, True]
    assert [bool(touching(row)) for row in gaps] == [False, True, True]
    labels = ["table", "wall"]
    hit = deepest_contact(gaps[1], 2, labels)
    assert (hit.kind, hit.partner, hit.surface_distance) == ("static", "wall", -0.2)
    assert deepest_contact(gaps[2], 2, labels).partner == "human_1"
    bounds = (-1.0, -2.0, 1.0, 2.0)
    x, y = np.array([0.0, 1.0, 1.0000001, -1.5]), np.array([0.0, 2.0, 0.0, 3.0])
    assert outside(x, y, bounds).tolist() == [outside(float(a), float(b), bounds) for a, b in zip(x, y, strict=True)]
    assert outside(x, y, bounds).tolist() == [False, False, True, True]
    goals, points = np.array([3 + 4j, 0.1 + 0.7j]), np.array([0j, -0.3 + 1e-9j])
    many = goal_distance(goals, points)
    assert [goal_distance(complex(g), complex(p)) for g, p in zip(goals, points, strict=True)] == many.tolist()
    assert many[0] == 5.0
