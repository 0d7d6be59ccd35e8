"""``humans.routing: geodesic`` (crowdnav.crowd.routing): humans walk around furniture; the batch agrees; straight stays the default."""

from pathlib import Path

import numpy as np
import pytest

from crowdnav import Simulator
from crowdnav.batch.simulator import BatchSimulator
from crowdnav.crowd.passing import passing_force
from crowdnav.crowd.routing import Router
from crowdnav.scenario.errors import ScenarioError
from crowdnav.scenario.library import library_names
from crowdnav.worlds.compiled import load_world

L_ROOM = Path(__file__).with_name("routing_l_room.yaml")

BEHIND_BENCH = {
    "description": "One human behind a 4 m bench, its goal on the other side.",
    "world": {"min": [-5, -5], "max": [5, 5]},
    "furniture": [{"type": "rectangle", "name": "bench", "center": [0.0, 0.0], "size": [4.0, 0.5]}],
    "robot": {"start": {"type": "rectangle", "min": [-4.5, -4.5], "max": [-4.0, -4.0]},
              "goal": {"type": "rectangle", "min": [4.0, -4.5], "max": [4.5, -4.0]}},
    "humans": {"count": 1, "spawn": [{"type": "rectangle", "min": [-0.1, -1.6], "max": [0.1, -1.4]}],
               "goal": [{"type": "rectangle", "min": [-0.1, 1.4], "max": [0.1, 1.6]}], "on_goal": "stop"},
    "max_steps": 400,
}


def _arrives(routing: str) -> bool:
    sim = Simulator(BEHIND_BENCH, {"humans.routing": routing})
    sim.reset(seed=0)
    for _ in range(300):
        sim.step(np.zeros(2))
    return bool(sim.state.human_stopped[0])


def test_a_human_behind_a_bench_reaches_its_goal_with_geodesic_routing_and_not_straight():
    assert _arrives("geodesic")
    assert not _arrives("straight")


def test_router_keeps_the_straight_goal_vector_where_the_goal_is_in_sight_and_turns_where_the_bench_blocks_it():
    router = Router(load_world(BEHIND_BENCH))
    humans = np.array([3.0 - 1.5j, 0.5 - 1.5j])
    goals = np.array([3.0 + 1.5j, 0.5 + 1.5j])
    routed = router.to_goal(humans, goals)
    assert routed[0] == goals[0] - humans[0]  # in sight: exactly the straight vector
    assert abs(routed[1].real) > abs(routed[1].imag)  # blocked: sideways, around the bench's end
    assert abs(routed[1]) > 3.0 + 1.0  # its length is the way around, longer than the straight 3 m


def test_router_pool_drops_the_least_recently_used_goal_and_gives_the_same_vectors(monkeypatch):
    monkeypatch.setattr("crowdnav.crowd.routing.POOL_BYTES", 1)  # one slot: every new goal evicts the last
    router = Router(load_world(BEHIND_BENCH))
    humans, goals = np.array([0.0 - 1.5j]), np.array([0.0 + 1.5j])
    first = router.to_goal(humans, goals)
    router.to_goal(humans, np.array([2.0 + 2.0j]))
    assert router.fields == 1
    np.testing.assert_array_equal(router.to_goal(humans, goals), first)


def test_a_call_with_more_goals_than_the_pool_holds_grows_it_for_that_call(monkeypatch):
    monkeypatch.setattr("crowdnav.crowd.routing.POOL_BYTES", 1)
    router = Router(load_world(BEHIND_BENCH))
    goals = np.array([0.0 + 1.5j, 2.0 + 2.0j, -2.0 + 2.0j])
    routed = router.to_goal(np.zeros(3, dtype=complex) - 1.5j, goals)
    assert router.fields == 3 and np.isfinite(routed).all()


def test_routing_other_than_straight_or_geodesic_is_refused_in_one_line():
    with pytest.raises(ScenarioError, match="routing"):
        Simulator(BEHIND_BENCH, {"humans.routing": "shortest"})


def test_batched_simulator_gives_the_single_simulators_episodes_with_geodesic_routing(monkeypatch):
    sidesteps = []  # the passing force (crowdnav.crowd.passing) acts in these episodes: the batch agrees on it too

    def counted(*args: object) -> np.ndarray:
        force = passing_force(*args)  # type: ignore[arg-type]
        sidesteps.append(int((force != 0).sum()))
        return force

    monkeypatch.setattr("crowdnav.sim.simulator.passing_force", counted)
    world = load_world(L_ROOM, {"humans.routing": "geodesic"})
    batch = BatchSimulator(world, 3)
    batch.reset(range(3), [0, 1, 2])
    singles = [Simulator(world) for _ in range(3)]
    for seed, single in enumerate(singles):
        single.reset(seed=seed)
    for _ in range(400):
        batch.step(np.zeros((3, 2)))
        for single in singles:
            single.step(np.zeros(2))
    for k, single in enumerate(singles):
        bucket, row = batch.locate(k)
        np.testing.assert_array_equal(bucket.state.positions[row], single.state.positions)
        np.testing.assert_array_equal(bucket.state.human_goals[row], single.state.human_goals)
        np.testing.assert_array_equal(bucket.state.human_stalls[row], single.state.human_stalls)
    assert sum(sidesteps) > 0


@pytest.mark.parametrize("name", library_names())
def test_every_library_scenario_runs_geodesic_routing_with_the_calibrated_preset_and_the_batch_agrees(name):
    world = load_world(name, {"humans.routing": "geodesic", "humans.preset": "calibrated"})
    single = Simulator(world)
    single.reset(seed=0)
    batch = BatchSimulator(world, 2) if world.scenario.robots is None else None  # robot teams step through the envs
    if batch is not None:
        batch.reset(range(2), [0, 1])
    for _ in range(50):
        single.step(np.zeros(2))  # the other robots of a team stand still
        if batch is not None:
            batch.step(np.zeros((2, 2)))
    assert np.isfinite(single.state.positions).all()
    if batch is not None:
        bucket, row = batch.locate(0)
        np.testing.assert_array_equal(bucket.state.positions[row], single.state.positions)
