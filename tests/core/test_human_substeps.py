"""Sub-steps of the humans' motion: speeds people walk at (up to 2 m/s and more) load at the default step and cannot tunnel.

A step that would move a human its radius or more is split into sub-steps, each followed by the
overlap pushes (:func:`crowdnav.scenario.loader.human_substeps`); at the speeds that loaded before,
one sub-step: the same episodes bit for bit.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from crowdnav import Simulator
from crowdnav.scenario.errors import ScenarioError
from crowdnav.scenario.loader import MAX_HUMAN_SUBSTEPS, human_substeps, load_scenario
from crowdnav.worlds.compiled import load_world
from tests.core.test_vector_env import check_batch_equals_singles

# Computed with the code at 74994f8, before sub-steps existed (the same helper, the same episodes).
DIGESTS_BEFORE_SUBSTEPS = [
    ("room_furniture", {"humans.count": 12}, 3, "cbb6bf180b478b1a"),
    ("open_space", {"humans.count": 10, "humans.preferred_speed": [1.0, 1.2], "robot.max_speed": 0.5}, 5, "8f938963eaa46f18"),
    ("cafe", {}, 7, "10e051bf109acec9"),
]


def episode_digest(scenario: str, overrides: dict, seed: int, steps: int = 300) -> str:
    """A hash of every agent's position and velocity after each of ``steps`` random robot actions."""
    sim = Simulator(scenario, overrides)
    sim.reset(seed=seed)
    rng = np.random.default_rng(seed + 1000)
    digest = hashlib.sha256()
    for _ in range(steps):
        sim.step(rng.uniform(-1, 1, 2))
        digest.update(sim.positions.tobytes())
        digest.update(sim.velocities.tobytes())
    return digest.hexdigest()[:16]


@pytest.mark.parametrize(("scenario", "overrides", "seed", "expected"), DIGESTS_BEFORE_SUBSTEPS)
def test_episodes_at_todays_speeds_are_the_ones_before_substeps_bit_for_bit(scenario, overrides, seed, expected):
    assert human_substeps(load_scenario(scenario, overrides)) == 1
    assert episode_digest(scenario, overrides, seed) == expected


@pytest.mark.parametrize(("speed", "time_step", "expected"), [
    (1.2, 0.2, 1),  # 0.288 m per step (the fastest the loader took before): one sub-step
    (1.6, 0.2, 2),  # the fit's speed, 0.384 m per step
    (2.0, 0.4, 4),  # 0.96 m per step
])
def test_substep_count_is_the_fewest_that_move_a_human_less_than_its_radius(speed, time_step, expected):
    scenario = load_scenario("open_space", {"humans.preferred_speed": [speed, speed], "time_step": time_step})
    assert human_substeps(scenario) == expected
    assert speed * 1.2 * time_step / expected < scenario.humans.radius


def test_walking_speeds_load_at_the_default_step_and_a_far_faster_one_is_refused_in_one_line():
    load_scenario("open_space", {"humans.preferred_speed": [1.6, 1.6]})
    load_scenario("open_space", {"humans.preferred_speed": [1.14, 1.68]})  # what from-recording wrote for ETH hotel
    with pytest.raises(ScenarioError) as error:
        load_scenario("open_space", {"humans.preferred_speed": [5.0, 5.0]})
    message = str(error.value)
    assert "humans.preferred_speed" in message and "1.2 m per step" in message
    assert f"expected less than {MAX_HUMAN_SUBSTEPS} times their radius 0.3 m" in message


def _two_humans(overrides: dict) -> Simulator:
    sim = Simulator("open_space", {"humans.count": 2, "humans.preferred_speed": [1.6, 1.6], **overrides})
    sim.reset(seed=0)
    sim.positions[:] = [4 + 4j, 0j, 0.62 + 0j]  # robot far away; the humans just apart, face to face
    sim.human_goals[:] = [5 + 0j, -5 + 0j]
    sim.refresh()
    return sim


def test_humans_walking_into_each_other_at_two_metres_per_second_do_not_pass_through():
    sim = _two_humans({})
    assert sim.substeps == 2
    for _ in range(3):  # straight at each other at full speed (1.92 m/s each: 0.77 m closer per step, more than a body)
        sim.step(np.zeros(2), human_actions=np.array([[1.0, 0.0], [-1.0, 0.0]]))
        assert sim.human_positions[0].real < sim.human_positions[1].real


def test_a_fast_human_does_not_cross_a_thin_wall():
    wall = {"walls": [{"name": "thin wall", "points": [[0.5, -3], [0.5, 3]], "thickness": 0.05}],
            "humans.preferred_speed": [2.0, 2.0]}  # 2.4 m/s at most: 0.48 m per step against a 5 cm wall
    sim = Simulator("open_space", {"humans.count": 1, **wall})
    sim.reset(seed=0)
    sim.positions[:] = [-4 - 4j, 0.5 - 0.025 - 0.31 + 0j]  # 1 cm from touching the wall
    sim.refresh()
    for _ in range(5):
        sim.step(np.zeros(2), human_actions=np.array([[1.0, 0.0]]))
        assert sim.human_positions[0].real < 0.5 - 0.025 - 0.29  # held on its side, within 1 cm of touching


def test_batched_worlds_with_substeps_equal_single_simulators_bit_for_bit():
    world = load_world("room_furniture", {"humans.preferred_speed": [1.3, 1.7]})
    assert human_substeps(world.scenario) == 2
    check_batch_equals_singles(world, worlds=4, first_seed=3, steps=80, rng_seed=2, scale=1.0)
