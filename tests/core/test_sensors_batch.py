"""Batched observation: ``Modality.observe_batch(state)`` equals ``observe(sim)`` of every world, bit for bit.

Single simulators are run with random robot actions, grouped by crowd size, stacked into a
:class:`BatchState`, and every built-in modality's batch row k is compared byte for byte with
its single observation of world k. Hand-placed states (robot far outside the world, inside an
obstacle, on a human's centre, headings beyond +-pi) reach the clipping and fallback branches.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from crowdnav import Simulator
from crowdnav.batch.state import BatchState
from crowdnav.scenario.schema import ClosestObstacleSensor, GoalSensor, HumansSensor, LeogSensor, LidarSensor, ObstaclesSensor
from crowdnav.sensors import (
    ClosestObstacleModality,
    GoalModality,
    HumansModality,
    LeogModality,
    LidarModality,
    Modality,
    ObstaclesModality,
    VelocityModality,
    build_modalities,
)
from crowdnav.sensors.frames import encode_vector, encode_vectors

BUILT_IN = ["goal", "velocity", "closest_obstacle", "lidar", "leog", "humans", "obstacles", "geodesic"]


def all_modalities(world) -> dict[str, Modality]:
    """The scenario's built-in modalities plus variants: partial-fov LIDARs, cartesian frames, short ranges, a coarse grid, k humans,
    the world's sides as shapes."""
    modalities = build_modalities(BUILT_IN, world, world.scenario.sensors)
    modalities["lidar_fov180"] = LidarModality(world, LidarSensor(beams=90, fov_deg=180))
    modalities["lidar_fov270_odd"] = LidarModality(world, LidarSensor(beams=77, fov_deg=270, max_range=8.0))
    modalities["goal_cartesian"] = GoalModality(world, GoalSensor(frame="cartesian"))
    modalities["closest_cartesian"] = ClosestObstacleModality(world, ClosestObstacleSensor(frame="cartesian"))
    modalities["closest_short_range"] = ClosestObstacleModality(world, ClosestObstacleSensor(max_range=0.8))
    modalities["closest_short_cartesian"] = ClosestObstacleModality(world, ClosestObstacleSensor(frame="cartesian", max_range=0.8))
    modalities["leog_coarse"] = LeogModality(world, LeogSensor(size=4.0, resolution=0.25))
    modalities["humans_short"] = HumansModality(world, HumansSensor(count=2, max_range=0.8))
    modalities["humans_all"] = HumansModality(world, HumansSensor(count=64, max_range=100.0))
    modalities["obstacles_short"] = ObstaclesModality(world, ObstaclesSensor(count=2, max_range=0.8))
    modalities["obstacles_all"] = ObstaclesModality(world, ObstaclesSensor(count=64, max_range=100.0))
    modalities["obstacles_edge"] = ObstaclesModality(world, ObstaclesSensor(count=3, max_range=3.0, world_edge=True))
    return modalities


def run_worlds(scenario, worlds: int, max_steps: int, seed: int = 0, overrides=None) -> list[Simulator]:
    """``worlds`` simulators of one compiled world, each reset with its own seed and stepped 0..max_steps random actions."""
    world = Simulator(scenario, overrides=overrides).world
    rng = np.random.default_rng(seed)
    sims = []
    for k in range(worlds):
        sim = Simulator(world)
        sim.reset(seed=seed * 1000 + k)
        for _ in range(int(rng.integers(0, max_steps + 1))):
            events = sim.step(rng.uniform(-1.0, 1.0, 2))
            if events.terminated or events.truncated:
                break
        sims.append(sim)
    return sims


def assert_batch_matches(modalities: dict[str, Modality], sims: list[Simulator]) -> int:
    """Stack the simulators per crowd size and compare every modality's batch rows with single observations; returns the group count."""
    groups: dict[int, list[Simulator]] = {}
    for sim in sims:
        groups.setdefault(sim.n_humans, []).append(sim)
    for n, group in groups.items():
        state = BatchState.stack(group)
        before = {field: np.copy(value) for field, value in vars(state).items()}
        for name, modality in modalities.items():
            batch = modality.observe_batch(state)
            assert all(np.array_equal(value, before[field]) for field, value in vars(state).items()), f"{name} modified the state"
            space = modality.space()
            assert batch.shape == (len(group), *space.shape), name
            assert batch.dtype == space.dtype, name
            for k, sim in enumerate(group):
                single = modality.observe(sim)
                assert batch[k].tobytes() == single.tobytes(), (
                    f"{name}: world {k} of {len(group)} (n={n}) differs:\nbatch  {batch[k].ravel()[:12]}\nsingle {single.ravel()[:12]}"
                )
    return len(groups)


@pytest.mark.parametrize(
    "scenario",
    [
        "room_furniture",  # boundary walls, polygon furniture, one round table
        "cafe",  # several round tables and polygons
        "open_space",  # no walls, no furniture: humans only
        "station_hall",  # groups of several sizes, pillars
        "hotel_lobby",  # groups, round furniture
    ],
)
def test_observe_batch_equals_single_observe_in_library_scenarios(scenario):
    sims = run_worlds(scenario, worlds=10, max_steps=40)
    assert assert_batch_matches(all_modalities(sims[0].world), sims) >= 1


def test_observe_batch_matches_with_unicycle_robot_and_turning_headings():
    sims = run_worlds("room_furniture", worlds=8, max_steps=40, seed=3,
                      overrides={"robot.kinematics": "unicycle", "robot.max_angular_speed": 1.5})
    assert len({sim.robot_heading for sim in sims}) == len(sims)
    assert_batch_matches(all_modalities(sims[0].world), sims)


@pytest.mark.parametrize("scenario", ["open_space", "empty_room"])
def test_observe_batch_matches_with_zero_humans(scenario):
    # open_space without humans has nothing at all to see: closest_obstacle reads "nothing in range"
    sims = run_worlds(scenario, worlds=5, max_steps=20, overrides={"humans.count": 0})
    assert all(sim.n_humans == 0 for sim in sims)
    assert_batch_matches(all_modalities(sims[0].world), sims)


def test_observe_batch_matches_sixteen_worlds_over_many_steps():
    sims = run_worlds("room_furniture", worlds=16, max_steps=0, seed=7)
    modalities = all_modalities(sims[0].world)
    rng = np.random.default_rng(11)
    for step in range(8):
        assert_batch_matches(modalities, sims)
        for k, sim in enumerate(sims):
            events = sim.step(rng.uniform(-1.0, 1.0, 2))
            if events.terminated or events.truncated:
                sim.reset(seed=100 + 16 * step + k)


def place(sim: Simulator, robot: complex, heading: float, robot_velocity: complex = 0j) -> None:
    sim.positions[0] = robot
    sim.velocities[0] = robot_velocity
    sim.robot_heading = heading
    with np.errstate(divide="ignore", invalid="ignore"):  # on a human's centre the social force divides by 0; sensors do not read it
        sim.refresh()


def test_observe_batch_matches_in_hand_placed_corner_cases():
    """Far outside the world (goal clipped), overspeed velocity, on a human's centre, inside furniture, odd headings."""
    sims = run_worlds("room_furniture", worlds=6, max_steps=5, seed=5)
    table = complex(*sims[0].world.obstacles.disc_center[:1].view(float)) if sims[0].world.obstacles.disc_count else 0j
    place(sims[0], 1.0e3 - 2.0e3j, 50.0, robot_velocity=40.0 + 30.0j)  # goal beyond 2 diagonals, velocity beyond max_speed
    place(sims[1], complex(sims[1].positions[1]), -math.pi)  # on a human's centre: a disc at distance 0
    place(sims[2], table, math.pi)  # inside the round table
    place(sims[3], 0.3 + 0.2j, -20.0)  # heading far below -pi
    place(sims[4], complex(sims[4].robot_goal), -0.0)  # on the goal: zero goal vector
    place(sims[5], 4.9 + 4.9j, 3 * math.pi)  # a corner, near two walls; a tie-prone remainder
    modalities = all_modalities(sims[0].world)
    assert_batch_matches(modalities, sims)
    open_sims = run_worlds("open_space", worlds=3, max_steps=5, seed=9)
    place(open_sims[0], -3.0e2 + 1.0e2j, 1.0, robot_velocity=-5.0 + 0.0j)
    place(open_sims[1], complex(open_sims[1].positions[2]), 0.0)
    assert_batch_matches(all_modalities(open_sims[0].world), open_sims)


def test_encode_vectors_equals_encode_vector_on_edge_values():
    bound = 2.5
    rng = np.random.default_rng(0)
    special = [0j, complex(-0.0, 0.0), complex(0.0, -0.0), complex(-0.0, -0.0), bound + 0j, -bound + 0j, complex(0.0, -bound),
               3 * bound - 4 * bound * 1j, 1e-300 + 1e-300j, 1e300 - 1e300j, complex(bound, bound), complex(-bound, 1e-17)]
    vectors = np.array(special + list(rng.normal(size=200) * 3 + 1j * rng.normal(size=200) * 3))
    for frame in ("polar", "cartesian"):
        batch = encode_vectors(vectors.real.copy(), vectors.imag.copy(), frame, bound)
        single = np.stack([encode_vector(complex(v), frame, bound) for v in vectors])
        assert batch.tobytes() == single.tobytes(), frame


def test_batch_constants_follow_new_radii_without_disturbing_single_caches():
    # two crowd sizes alternate on one modality instance: each batch must use its own radii
    small = run_worlds("open_space", worlds=3, max_steps=5, overrides={"humans.count": 2})
    large = run_worlds("open_space", worlds=3, max_steps=5, overrides={"humans.count": 7})
    world = small[0].world
    modalities = {"lidar": LidarModality(world), "leog": LeogModality(world)}
    for sims in (small, large, small):
        assert_batch_matches(modalities, sims)


def test_every_built_in_modality_implements_observe_batch():
    for cls in (GoalModality, VelocityModality, ClosestObstacleModality, LidarModality, LeogModality, HumansModality):
        assert cls.observe_batch is not Modality.observe_batch, cls.__name__


def test_modality_without_observe_batch_raises_a_clear_error():
    class Heading(Modality):  # not registered: keeps the global registry clean
        key = "heading_only"

        def make_space(self):
            from gymnasium import spaces
            return spaces.Box(-4.0, 4.0, shape=(1,), dtype=np.float32)

        def observe(self, sim):
            return np.array([sim.robot_heading], dtype=np.float32)

    sims = run_worlds("open_space", worlds=2, max_steps=0)
    modality = Heading(sims[0].world)
    with pytest.raises(NotImplementedError) as caught:
        modality.observe_batch(BatchState.stack(sims))
    message = str(caught.value)
    assert "'heading_only'" in message and "observe_batch" in message
    assert "docs/sensors.md" in message and 'vectorization_mode="sync"' in message
