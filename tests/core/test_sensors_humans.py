"""The ``humans`` modality: the k nearest humans (robot-frame position, relative velocity, radius, presence)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode

import crowdnav  # noqa: F401  (registers the ids)
from crowdnav import Simulator, load_scenario
from crowdnav.batch.state import BatchState
from crowdnav.envs import CrowdNavEnv
from crowdnav.envs.vector.env import CrowdNavVectorEnv
from crowdnav.scenario import ScenarioError
from crowdnav.scenario.schema import HumansSensor, Sensors
from crowdnav.sensors import MODALITIES, HumansModality, build_modalities
from tests.core.test_sensors_batch import assert_batch_matches, run_worlds
from tests.core.test_vector_env import _compare_with_sync

RADIUS = 0.25  # a dyadic radius: centre distances max_range + RADIUS give surface distances of exactly max_range


def crowd(n: int, **sensors) -> Simulator:
    """A 20 m x 20 m open world with ``n`` humans of radius 0.25 m, reset; tests then place everyone by hand."""
    scenario = {
        "description": "open world for the humans modality",
        "world": {"min": [-10, -10], "max": [10, 10], "boundary_walls": False},
        "robot": {"start": {"type": "points", "points": [[0, 0]]}, "goal": {"type": "points", "points": [[3, 4]]}},
        "humans": {
            "count": n, "radius": RADIUS, "preferred_speed": [0.5, 1.0],
            "spawn": [{"type": "rectangle", "min": [-9, -9], "max": [9, 9]}],
            "goal": [{"type": "rectangle", "min": [-9, -9], "max": [9, 9]}],
        },
        "sensors": sensors,
    }
    sim = Simulator(load_scenario(scenario))
    sim.reset(seed=0)
    return sim


def place(sim: Simulator, humans, velocities=None, robot: complex = 0j, heading: float = 0.0, robot_velocity: complex = 0j) -> None:
    """Put the robot and the humans where given (world frame) and measure the geometry again."""
    sim.positions[0], sim.velocities[0], sim.robot_heading = robot, robot_velocity, heading
    sim.positions[1:] = humans
    sim.velocities[1:] = 0j if velocities is None else velocities
    with np.errstate(divide="ignore", invalid="ignore"):  # hand-placed overlaps: the social force may divide by 0
        sim.refresh()


def humans_of(sim: Simulator, **settings) -> HumansModality:
    return HumansModality(sim.world, HumansSensor(**settings))


def rotate(z: complex, angle: float) -> complex:
    return z * complex(math.cos(angle), math.sin(angle))


# ------------------------------------------------------------------------- space and settings


def test_space_is_count_by_six_float32_with_the_documented_bounds():
    sim = crowd(3)
    modality = humans_of(sim, count=4, max_range=3.0)
    space = modality.space()
    assert space.shape == (4, 6) and space.dtype == np.float32 and space is modality.space()
    humans, robot = sim.scenario.humans, sim.scenario.robot
    speed = humans.max_preferred_speed * humans.social_force.max_speed_factor + robot.max_speed  # 1.0 * 1.2 + 1.0
    np.testing.assert_allclose(space.high, np.tile([3.0 + RADIUS, 3.0 + RADIUS, speed, speed, RADIUS, 1.0], (4, 1)), rtol=1e-6)
    np.testing.assert_allclose(space.low, np.tile([-3.0 - RADIUS, -3.0 - RADIUS, -speed, -speed, 0.0, 0.0], (4, 1)), rtol=1e-6)
    observation = modality.observe(sim)
    assert observation.dtype == np.float32 and observation.shape == (4, 6) and space.contains(observation)
    assert observation is not modality.observe(sim)


def test_default_settings_are_five_humans_within_five_metres_and_come_from_the_sensors_model():
    sim = crowd(3)
    default = build_modalities(["humans"], sim.world, sim.scenario.sensors)["humans"]
    assert isinstance(default, HumansModality) and MODALITIES["humans"] is HumansModality
    assert (default.count, default.max_range) == (5, 5.0) and default.space().shape == (5, 6)
    built = build_modalities(["humans"], sim.world, Sensors(humans=HumansSensor(count=2, max_range=1.5)))["humans"]
    assert built.space().shape == (2, 6) and built.max_range == 1.5


def test_scale_is_the_range_the_speed_bound_and_one():
    sim = crowd(3)
    modality = humans_of(sim, count=3, max_range=4.0)
    offset, scale = modality.scale()
    assert offset.dtype == scale.dtype == np.float32 and np.all(offset == 0.0)
    np.testing.assert_allclose(scale, np.tile([4.0, 4.0, modality.speed_bound, modality.speed_bound, 1.0, 1.0], (3, 1)), rtol=1e-6)
    normalized = modality.normalized_space()
    np.testing.assert_allclose(normalized.high[0], [1 + RADIUS / 4.0, 1 + RADIUS / 4.0, 1.0, 1.0, RADIUS, 1.0], rtol=1e-6)


@pytest.mark.parametrize(("settings", "path", "message"), [
    ({"count": 0}, "sensors.humans.count", "expected an integer >= 1, got 0"),
    ({"count": 65}, "sensors.humans.count", "expected an integer <= 64, got 65"),
    ({"max_range": 0.0}, "sensors.humans.max_range", "sensors.humans.max_range"),
    ({"range": 3.0}, "sensors.humans.range", "sensors.humans.range"),
])
def test_bad_settings_raise_the_usual_scenario_error_naming_the_field(settings, path, message):
    with pytest.raises(ScenarioError) as caught:
        CrowdNavEnv("room_furniture", modalities=["humans", "goal"], sensors={"humans": settings})
    (issue,) = caught.value.issues
    assert issue.path == path and message in str(caught.value)


# ------------------------------------------------------------------------- readings


def test_hand_placed_human_reads_its_robot_frame_position_relative_velocity_radius_and_flag():
    sim = crowd(1)
    # the robot at (1, 2) faces world +y and moves forward at 1 m/s; the human 2 m ahead moves at (1, 1) m/s
    place(sim, [1 + 4j], [1 + 1j], robot=1 + 2j, heading=math.pi / 2, robot_velocity=1j)
    observation = humans_of(sim, count=3).observe(sim)
    # relative velocity (1, 0) in the world: to the right of a robot facing +y, i.e. robot-frame (0, -1)
    np.testing.assert_allclose(observation[0], [2.0, 0.0, 0.0, -1.0, RADIUS, 1.0], atol=1e-6)
    assert np.all(observation[1:] == 0.0)


def test_rows_are_nearest_first_by_surface_distance_with_ties_by_index():
    sim = crowd(5)
    # centre distances 3, 1, 2, 1 (a tie with human 1) and 4, all along the robot's heading (x)
    place(sim, [3 + 0j, 1 + 0j, 2 + 0j, -1 + 0j, 4 + 0j])
    observation = humans_of(sim, count=5).observe(sim)
    np.testing.assert_allclose(observation[:, 0], [1.0, -1.0, 2.0, 3.0, 4.0], atol=1e-6)  # human 1 before its tie, human 3
    # surface distance, not centre distance: a larger body (radius 1.2 m) 2 m away is nearer than one 1.5 m away
    place(sim, [2 + 0j, 1.5 + 0j, 6 + 0j, 7 + 0j, 8 + 0j])
    sim.radii = np.array([sim.radii[0], 1.2, RADIUS, RADIUS, RADIUS, RADIUS])  # a new array: the cached one stays intact
    observation = humans_of(sim, count=2, max_range=5.0).observe(sim)
    np.testing.assert_allclose(observation[:, 0], [2.0, 1.5], atol=1e-6)


def test_rows_of_absent_humans_are_zero_beyond_the_crowd_and_beyond_max_range():
    sim = crowd(3)
    # surfaces at exactly max_range (present), just beyond it (absent), and near (present)
    place(sim, [2.0 + RADIUS + 0j, 1j * (2.0 + RADIUS + 1e-9), -0.5 + 0j], [0.3 + 0j, 0.4j, -0.2j])
    observation = humans_of(sim, count=5, max_range=2.0).observe(sim)
    np.testing.assert_allclose(observation[0], [-0.5, 0.0, 0.0, -0.2, RADIUS, 1.0], atol=1e-6)
    np.testing.assert_allclose(observation[1], [2.0 + RADIUS, 0.0, 0.3, 0.0, RADIUS, 1.0], atol=1e-6)
    assert np.all(observation[2:] == 0.0)  # the far human and the two slots beyond the crowd of 3
    far = humans_of(sim, count=5, max_range=1.0).observe(sim)
    assert np.all(far[1:] == 0.0) and far[0, 5] == 1.0


def test_an_empty_crowd_reads_all_zero_rows_single_and_batched():
    sims = run_worlds("empty_room", worlds=3, max_steps=5)
    modality = build_modalities(["humans"], sims[0].world, sims[0].scenario.sensors)["humans"]
    assert all(sim.n_humans == 0 for sim in sims)
    assert all(np.all(modality.observe(sim) == 0.0) for sim in sims)
    batch = modality.observe_batch(BatchState.stack(sims))
    assert batch.shape == (3, 5, 6) and batch.dtype == np.float32 and np.all(batch == 0.0)


def test_positions_and_velocities_turn_with_the_robot():
    sim = crowd(2)
    humans, velocities, robot, robot_velocity = np.array([2 + 1j, -1 - 1.5j]), np.array([0.5 - 0.2j, -0.7j]), -1 + 0.5j, 0.3 + 0.6j
    modality = humans_of(sim, count=2)
    for heading in (0.0, 0.7, math.pi / 2, -2.5, math.pi):
        place(sim, humans, velocities, robot=robot, heading=heading, robot_velocity=robot_velocity)
        observation = modality.observe(sim)
        order = np.argsort(np.abs(humans - robot))
        for row, i in enumerate(order):
            offset, relative = rotate(humans[i] - robot, -heading), rotate(velocities[i] - robot_velocity, -heading)
            np.testing.assert_allclose(observation[row, :4], [offset.real, offset.imag, relative.real, relative.imag], atol=1e-6)


def test_positions_and_velocities_are_clipped_to_the_box():
    sim = crowd(1)
    # a robot velocity far above its max speed makes the relative velocity exceed the bound
    place(sim, [1 + 0j], [0j], robot_velocity=-40 + 30j)
    modality = humans_of(sim, count=1)
    observation = modality.observe(sim)
    assert modality.space().contains(observation)
    np.testing.assert_allclose(observation[0, 2:4], [modality.speed_bound, -modality.speed_bound], rtol=1e-6)


def test_observations_stay_in_their_space_and_normalise_to_order_one_over_random_episodes():
    sim = Simulator("hotel_lobby")  # walking and standing groups, furniture
    modality = build_modalities(["humans"], sim.world, sim.scenario.sensors)["humans"]
    rng, rows = np.random.default_rng(0), []
    for episode in range(2):
        sim.reset(seed=episode)
        for _ in range(40):
            observation = modality.observe(sim)
            assert modality.space().contains(observation)
            rows.append(modality.normalize(observation))
            if sim.step(rng.uniform(-1, 1, size=2)).terminated:
                break
    stacked = np.stack(rows)
    assert np.all(np.abs(stacked) <= 1.0 + RADIUS) and stacked[..., 5].max() == 1.0
    assert np.abs(stacked[..., 2:4]).max() > 0.05  # humans move: relative velocities are not all zero


# ------------------------------------------------------------------------- batch and environments


@pytest.mark.parametrize(("scenario", "overrides"), [
    ("open_space", None),
    ("crowded_open_space", None),
    ("station_hall", None),  # groups of several sizes, standing circles
    ("hotel_lobby", None),
    ("cafe", {"robot.kinematics": "unicycle", "robot.max_angular_speed": 1.5}),
    ("open_space", {"humans.count": [0, 3]}),  # crowds smaller than k, and none
])
def test_observe_batch_equals_observe_bit_for_bit_over_scenarios_seeds_and_steps(scenario, overrides):
    for seed in (0, 1):
        sims = run_worlds(scenario, worlds=6, max_steps=30, seed=seed, overrides=overrides)
        world = sims[0].world
        modalities = {
            "default": HumansModality(world),
            "one_short": HumansModality(world, HumansSensor(count=1, max_range=0.5)),
            "three": HumansModality(world, HumansSensor(count=3, max_range=2.0)),
            "all_far": HumansModality(world, HumansSensor(count=64, max_range=100.0)),
        }
        assert_batch_matches(modalities, sims)


def test_observe_batch_equals_observe_with_hand_placed_ties_overlaps_and_odd_headings():
    sims = [crowd(4) for _ in range(4)]
    place(sims[0], [1 + 0j, -1 + 0j, 1j, -1j], [0.5 + 0j, 0j, -0.5j, 0.3 + 0.3j], heading=0.3)  # four-way tie
    place(sims[1], [0j, 0.1 + 0j, 5 + 5j, -3 + 0j], robot_velocity=40 + 30j, heading=-20.0)  # on a centre, overspeed
    place(sims[2], [2.25 + 0j, 2.2500001 + 0j, 9 + 9j, -9 - 9j], heading=3 * math.pi)
    place(sims[3], [0.2 + 0.1j, 1 + 1j, 1 - 1j, 4j], [1 + 1j, -1j, 1 + 0j, 0j], robot=0.3 - 0.1j, heading=-0.0)
    world = sims[0].world
    assert_batch_matches({"default": HumansModality(world), "near": HumansModality(world, HumansSensor(count=3, max_range=2.0))}, sims)


def test_gymnasium_check_env_passes_with_humans_and_goal():
    env = CrowdNavEnv("room_furniture", modalities=["humans", "goal"])
    check_env(env, skip_render_check=True)
    observation, _ = env.reset(seed=0)
    assert observation["humans"].shape == (5, 6) and env.observation_space.contains(observation)


def test_native_vector_env_observes_humans_like_the_sync_vector_env():
    env = CrowdNavVectorEnv("open_space", 3, modalities=["humans", "goal"])
    observation, _ = env.reset(seed=0)
    assert observation["humans"].shape == (3, 5, 6) and observation["humans"].dtype == np.float32
    assert _compare_with_sync("OpenSpace", AutoresetMode.NEXT_STEP, 60, num_envs=3, modalities=["humans", "goal"],
                              sensors={"humans": {"count": 7, "max_range": 3.0}}) >= 0
    single = gym.make("crowdnav/OpenSpace-v0", modalities=["humans", "goal"])
    assert single.observation_space["humans"] == env.single_observation_space["humans"]
