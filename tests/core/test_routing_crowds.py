"""``humans.routing: geodesic`` in a crowd: oncoming humans side-step (crowdnav.crowd.passing), walking groups arrive when
gathered (crowdnav.sim.groups.arrivals), and the L-shaped room of issue 52 keeps its groups moving."""

from pathlib import Path

import numpy as np
import pytest

from crowdnav import Simulator
from crowdnav.crowd.passing import passing_force
from crowdnav.sim.groups import arrivals

L_ROOM = Path(__file__).with_name("routing_l_room.yaml")


def _box(x: float, y: float) -> dict[str, object]:
    return {"type": "rectangle", "min": [x - 0.1, y - 0.1], "max": [x + 0.1, y + 0.1]}


def _one(name: str, spawn: tuple[float, float], goal: tuple[float, float]) -> dict[str, object]:
    return {"name": name, "count": 1, "spawn": [_box(*spawn)], "goal": [_box(*goal)], "on_goal": "stop"}


HEAD_ON = {
    "description": "Two humans on one line walking at each other.",
    "world": {"min": [-5, -5], "max": [5, 5]},
    "robot": {"start": {"type": "rectangle", "min": [-4.5, -4.5], "max": [-4.0, -4.0]},
              "goal": {"type": "rectangle", "min": [4.0, -4.5], "max": [4.5, -4.0]}},
    "humans": {"groups": [_one("east", (-3.0, 0.0), (3.0, 0.0)), _one("west", (3.0, 0.0), (-3.0, 0.0))]},
    "max_steps": 400,
}


def _head_on(routing: str) -> Simulator:
    sim = Simulator(HEAD_ON, {"humans.routing": routing})
    sim.reset(seed=0)
    sim.state.positions[1:] = [-3.0, 3.0]  # exactly on one line: the social force pushes only back along it
    sim.state.human_goals[:] = [3.0, -3.0]
    sim.state.velocities[1:] = 0.0
    sim.refresh()
    for _ in range(100):
        sim.step(np.zeros(2))
    return sim


def test_two_humans_meeting_head_on_pass_on_their_right_with_geodesic_routing_and_deadlock_straight():
    straight = _head_on("straight")
    assert not straight.state.human_stopped.any() and abs(straight.state.positions[2] - straight.state.positions[1]) < 1.0
    routed = _head_on("geodesic")
    assert routed.state.human_stopped.all()  # both at their goals after 20 s
    assert routed.state.positions[1].imag < 0 < routed.state.positions[2].imag  # each kept to its right while passing


def test_passing_force_steps_right_head_on_left_of_one_already_on_the_right_and_never_between_fellow_members():
    humans = np.array([0.0, 2.0, 2.0 - 0.5j, 1.0 + 5.0j])
    to_goal = np.array([5.0, -5.0, -5.0, 5.0])  # 0 walks east; 1 and 2 come at it; 3 walks east far off its lane
    walking = np.ones(4, dtype=bool)
    force = passing_force(humans[:2], to_goal[:2], walking[:2], 0.3, 2.0, np.array([0, 1]), np.array([False, False]))
    assert force[0] == pytest.approx(-1.5j) and force[1] == pytest.approx(1.5j)  # 0.75 x weight 2, each to its right
    force = passing_force(humans[[0, 2]], to_goal[[0, 2]], walking[:2], 0.3, 2.0, np.array([0, 1]), np.array([False, False]))
    assert force[0].imag > 0  # the oncoming one is on 0's right: 0 steps left, away from it
    fellows = passing_force(humans[:2], to_goal[:2], walking[:2], 0.3, 2.0, np.array([0, 0]), np.array([True]))
    np.testing.assert_array_equal(fellows, 0.0)  # members of one walking group do not side-step each other
    stopped = passing_force(humans[:2], to_goal[:2], np.array([True, False]), 0.3, 2.0, np.array([0, 1]), None)
    np.testing.assert_array_equal(stopped, 0.0)
    assert passing_force(humans, to_goal, walking, 0.3, 2.0, np.arange(4), None)[3] == 0.0  # nobody in 3's lane


def test_passing_force_of_a_batch_of_worlds_equals_each_world_alone_bit_for_bit():
    rng = np.random.default_rng(1)
    humans = rng.uniform(-3, 3, (4, 7)) + 1j * rng.uniform(-3, 3, (4, 7))
    to_goal = rng.uniform(-3, 3, (4, 7)) + 1j * rng.uniform(-3, 3, (4, 7))
    group, together = rng.integers(0, 3, (4, 7)), np.array([True, False, True])
    walking = rng.random((4, 7)) < 0.8
    batch = passing_force(humans, to_goal, walking, 0.3, 1.0, group, together)
    assert (batch != 0).any()
    for k in range(4):
        np.testing.assert_array_equal(batch[k], passing_force(humans[k], to_goal[k], walking[k], 0.3, 1.0, group[k], together))


@pytest.mark.parametrize("routing", ["straight", "geodesic"])
def test_a_walking_group_gathered_beside_its_goal_has_arrived_only_with_geodesic_routing(routing):
    sim = Simulator(L_ROOM, {"humans.routing": routing})
    sim.reset(seed=0)
    ring = sim.placement.groups[0].circle_radius
    goal = -5.5 + 3.0j  # a goal 0.5 m from the west wall: members cannot stand around it
    members = goal + 0.6 + ring * np.exp(2j * np.pi * np.arange(3) / 3)  # gathered on a circle 0.6 m east of it
    humans = np.concatenate([members, sim.state.positions[4:]])
    goals = np.concatenate([np.full(3, goal), sim.state.human_goals[3:]])
    arrived = arrivals(np.abs(goals - humans), humans, goals, sim.state.human_group, sim.state.human_stopped, sim)
    assert arrived[:3].all() == (routing == "geodesic")


@pytest.mark.slow
def test_l_room_with_geodesic_routing_keeps_its_groups_moving():
    """Issue 52: seeds 0-4, 3,000 steps, the robot standing still: the six humans' mean speed over the last 100 s stays above
    0.35 m/s in every seed (measured 0.42-0.47; 0.21-0.38 before passing and gathered arrivals; a lone group: ~0.48)."""
    for seed in range(5):
        sim = Simulator(L_ROOM, {"humans.routing": "geodesic"})
        sim.reset(seed=seed)
        speeds = []
        for step in range(3000):
            sim.step(np.zeros(2))
            if step >= 2500:
                speeds.append(np.abs(sim.state.velocities[1:]).mean())
        assert np.mean(speeds) > 0.35, f"seed {seed}: mean speed {np.mean(speeds):.3f} m/s over the last 100 s"
