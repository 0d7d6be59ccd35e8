"""Sensor modalities: registry, factory errors, spaces, and observations staying in their spaces."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gymnasium import spaces
from stable_baselines3.common.preprocessing import is_image_space

from crowdnav import Simulator, load_scenario
from crowdnav.scenario.schema import GoalSensor, LidarSensor, Sensors
from crowdnav.sensors import MODALITIES, Modality, build_modalities, register_modality
from crowdnav.sensors.base import MODALITIES as BASE_MODALITIES
from tests.paths import REPO

ALL = ["goal", "closest_obstacle", "lidar", "leog", "velocity"]


def open_world(**sensors) -> Simulator:
    """An empty 20 m x 20 m world without boundary walls, robot near the centre."""
    scenario = {
        "description": "open world for sensor tests",
        "world": {"min": [-10, -10], "max": [10, 10], "boundary_walls": False},
        "robot": {"start": {"type": "points", "points": [[0, 0]]}, "goal": {"type": "points", "points": [[3, 4]]}},
        "sensors": sensors,
    }
    sim = Simulator(load_scenario(scenario))
    sim.reset(seed=0)
    return sim


@pytest.fixture(scope="module")
def room():
    sim = Simulator("room_furniture", {"humans.count": 10})
    sim.reset(seed=3)
    return sim


def test_registry_holds_the_built_in_modalities():
    assert set(ALL) <= set(MODALITIES)
    assert MODALITIES is BASE_MODALITIES
    for key in ALL:
        assert MODALITIES[key].key == key


def test_build_modalities_keeps_the_requested_order(room):
    names = ["velocity", "leog", "goal", "lidar", "closest_obstacle"]
    built = build_modalities(names, room.world, room.scenario.sensors)
    assert list(built) == names
    assert all(isinstance(modality, Modality) for modality in built.values())


def test_build_modalities_names_unknown_keys_and_lists_available_ones(room):
    with pytest.raises(ValueError) as error:
        build_modalities(["goal", "sonar", "camera"], room.world, room.scenario.sensors)
    message = str(error.value)
    assert "'sonar'" in message and "'camera'" in message
    for key in ALL:
        assert key in message
    with pytest.raises(ValueError, match=r"'lidr' \(did you mean 'lidar'\?\)"):
        build_modalities(["lidr"], room.world, room.scenario.sensors)


@pytest.mark.parametrize(
    "names, fragment",
    [([], "at least one"), (["goal", "goal"], "duplicate modality key(s): 'goal'")],
)
def test_build_modalities_rejects_empty_and_duplicate_lists(room, names, fragment):
    with pytest.raises(ValueError, match=fragment.replace("(", r"\(").replace(")", r"\)")):
        build_modalities(names, room.world, room.scenario.sensors)


def test_build_modalities_rejects_a_bare_string(room):
    with pytest.raises(TypeError, match="sequence of modality keys"):
        build_modalities("lidar", room.world, room.scenario.sensors)


def test_settings_come_from_the_sensors_model(room):
    sensors = Sensors(lidar=LidarSensor(beams=90, fov_deg=180, max_range=3.0), goal=GoalSensor(frame="cartesian"))
    built = build_modalities(["lidar", "goal", "velocity"], room.world, sensors)
    assert built["lidar"].space().shape == (90,)
    assert built["goal"].space().shape == (2,)
    assert built["velocity"].settings is None


def test_wrong_settings_type_is_a_clear_error(room):
    with pytest.raises(TypeError, match="expects settings of type LidarSensor, got GoalSensor"):
        MODALITIES["lidar"](room.world, GoalSensor())


def test_space_is_built_once_and_observations_are_fresh_arrays_inside_it(room):
    built = build_modalities(ALL, room.world, room.scenario.sensors)
    for modality in built.values():
        assert modality.space() is modality.space()
        first, second = modality.observe(room), modality.observe(room)
        assert first is not second and not np.shares_memory(first, second)
        assert first.dtype == modality.space().dtype and first.shape == modality.space().shape
        assert modality.space().contains(first)


def test_default_spaces_have_the_documented_shapes_and_types(room):
    built = build_modalities(ALL, room.world, room.scenario.sensors)
    shapes = {key: modality.space().shape for key, modality in built.items()}
    assert shapes == {"goal": (3,), "closest_obstacle": (3,), "lidar": (360,), "leog": (1, 60, 60), "velocity": (2,)}
    leog = built["leog"].space()
    assert leog.dtype == np.uint8 and leog.low.min() == 0 and leog.high.max() == 255
    assert is_image_space(leog)  # SB3 sends it through its CNN as an image
    for key in ("goal", "closest_obstacle", "lidar", "velocity"):
        assert built[key].space().dtype == np.float32


def test_observing_leaves_the_simulator_state_untouched(room):
    names = ["positions", "velocities", "pair_offset", "pair_distance", "polygon_offset", "polygon_distance", "disc_offset", "radii"]
    before = {name: getattr(room, name).copy() for name in names}
    heading = room.robot_heading
    for modality in build_modalities(ALL, room.world, room.scenario.sensors).values():
        modality.observe(room)
    for name in names:
        np.testing.assert_array_equal(getattr(room, name), before[name], err_msg=name)
    assert room.robot_heading == heading


def test_observations_stay_in_the_dict_space_over_random_episodes():
    sim = Simulator("room_furniture", {"humans.count": 20})
    built = build_modalities(ALL, sim.world, sim.scenario.sensors)
    space = spaces.Dict({key: modality.space() for key, modality in built.items()})
    rng = np.random.default_rng(0)
    for episode in range(3):
        sim.reset(seed=episode)
        for _ in range(40):
            observation = {key: modality.observe(sim) for key, modality in built.items()}
            assert space.contains(observation)
            if sim.step(rng.uniform(-1, 1, size=2)).terminated:
                break


def test_leog_holds_only_free_and_occupied_values(room):
    grid = build_modalities(["leog"], room.world, room.scenario.sensors)["leog"].observe(room)
    assert set(np.unique(grid)) <= {0, 255}
    assert (grid == 255).any() and (grid == 0).any()


# ------------------------------------------------------------------ goal and velocity


def test_goal_is_polar_in_the_robot_frame():
    sim = open_world()
    sim.positions[0] = 1 + 1j
    sim.robot_goal = 1 + 3j  # 2 m along world +y
    sim.robot_heading = math.pi / 2  # facing +y: the goal is straight ahead
    goal = build_modalities(["goal"], sim.world, sim.scenario.sensors)["goal"]
    np.testing.assert_allclose(goal.observe(sim), [2.0, 0.0, 1.0], atol=1e-7)
    sim.robot_heading = 0.0  # facing +x: the goal is on the left
    np.testing.assert_allclose(goal.observe(sim), [2.0, 1.0, 0.0], atol=1e-7)


def test_goal_at_the_robot_has_bearing_zero():
    sim = open_world()
    sim.robot_goal = complex(sim.positions[0])
    goal = build_modalities(["goal"], sim.world, sim.scenario.sensors)["goal"]
    np.testing.assert_array_equal(goal.observe(sim), np.array([0.0, 0.0, 1.0], dtype=np.float32))


def test_goal_distance_is_clipped_to_twice_the_world_diagonal():
    sim = open_world(goal={"frame": "polar"})
    bound = 2 * sim.scenario.world_diagonal
    sim.positions[0] = -1000.0 + 0j  # far outside the open world
    sim.robot_heading = 0.0
    polar = build_modalities(["goal"], sim.world, sim.scenario.sensors)["goal"]
    observation = polar.observe(sim)
    assert observation[0] == np.float32(bound) and polar.space().contains(observation)
    cartesian = build_modalities(["goal"], sim.world, Sensors(goal=GoalSensor(frame="cartesian")))["goal"]
    observation = cartesian.observe(sim)
    assert cartesian.space().contains(observation)
    direction = (sim.robot_goal - sim.positions[0]) / abs(sim.robot_goal - sim.positions[0])
    np.testing.assert_allclose(observation, [bound * direction.real, bound * direction.imag], rtol=1e-6)


def test_velocity_is_the_robots_own_velocity_in_its_frame_and_clipped():
    sim = open_world()
    velocity = build_modalities(["velocity"], sim.world, sim.scenario.sensors)["velocity"]
    sim.robot_heading = math.pi / 2
    sim.velocities[0] = 0.5j  # moving along world +y = forward
    np.testing.assert_allclose(velocity.observe(sim), [0.5, 0.0], atol=1e-7)
    sim.velocities[0] = -0.3 + 0j  # world -x = to the robot's left when facing +y
    np.testing.assert_allclose(velocity.observe(sim), [0.0, 0.3], atol=1e-7)
    sim.velocities[0] = 5.0j  # faster than max_speed (1 m/s): scaled down, direction kept
    observation = velocity.observe(sim)
    np.testing.assert_allclose(observation, [1.0, 0.0], atol=1e-7)
    assert velocity.space().contains(observation)


def test_velocity_after_a_step_matches_the_commanded_action():
    sim = open_world()
    sim.robot_heading = 0.3
    velocity = build_modalities(["velocity"], sim.world, sim.scenario.sensors)["velocity"]
    sim.step(np.array([0.6, -0.4]))  # holonomic: (vx, vy) in the robot frame times max_speed
    np.testing.assert_allclose(velocity.observe(sim), [0.6, -0.4], atol=1e-6)


# ------------------------------------------------------------------------- registry


def test_a_new_modality_is_one_class_and_one_registration(room, monkeypatch):
    monkeypatch.setattr("crowdnav.sensors.base.MODALITIES", dict(MODALITIES))
    from crowdnav.sensors import base

    @base.register_modality
    class GoalDistance(Modality):
        key = "goal_distance"

        def make_space(self):
            return spaces.Box(0.0, np.inf, shape=(1,), dtype=np.float32)

        def observe(self, sim):
            return np.array([sim.robot_goal_distance], dtype=np.float32)

    built = base.build_modalities(["goal", "goal_distance"], room.world, room.scenario.sensors)
    assert built["goal_distance"].settings is None
    np.testing.assert_allclose(built["goal_distance"].observe(room), [room.robot_goal_distance], rtol=1e-6)
    assert "goal_distance" not in MODALITIES  # the patched registry was a copy


def test_registering_a_second_class_under_a_taken_key_is_an_error(monkeypatch):
    monkeypatch.setattr("crowdnav.sensors.base.MODALITIES", dict(MODALITIES))

    class Impostor(Modality):
        key = "lidar"

        def make_space(self):
            return spaces.Box(0.0, 1.0, shape=(1,), dtype=np.float32)

        def observe(self, sim):
            return np.zeros(1, dtype=np.float32)

    with pytest.raises(ValueError, match="'lidar' is already registered by crowdnav.sensors.lidar.LidarModality"):
        register_modality(Impostor)


@pytest.mark.parametrize("bad", [object, int])
def test_register_modality_rejects_non_modalities(bad):
    with pytest.raises(TypeError, match="expects a Modality subclass"):
        register_modality(bad)


def test_the_worked_example_in_the_docs_registers_and_observes(room, monkeypatch):

    monkeypatch.setattr("crowdnav.sensors.base.MODALITIES", dict(MODALITIES))
    text = (REPO / "docs" / "sensors.md").read_text(encoding="utf-8")
    section = text.split("## Adding a modality", 1)[1]
    example = section.split("```python", 1)[1].split("```", 1)[0]
    namespace: dict = {}
    exec(compile(example, "docs/sensors.md", "exec"), namespace)  # noqa: S102 - our own documentation
    from crowdnav.sensors import base

    built = base.build_modalities(["nearest_humans"], room.world, room.scenario.sensors)["nearest_humans"]
    observation = built.observe(room)
    assert built.space().contains(observation)
    nearest = np.sort(np.abs(room.pair_offset[0, 1:]))[:3]
    np.testing.assert_allclose(np.hypot(observation[:, 0], observation[:, 1]), nearest, rtol=1e-6)
    np.testing.assert_array_equal(built.scale()[1], np.full((3, 2), 10.0))  # the default scale, from its Box


# ------------------------------------------------------------------------- scales


@pytest.mark.parametrize("frame", ["polar", "cartesian"])
def test_every_registered_modality_declares_a_positive_scale_of_its_observation_shape(room, frame):
    sensors = room.scenario.sensors.model_copy(update={
        "goal": room.scenario.sensors.goal.model_copy(update={"frame": frame}),
        "closest_obstacle": room.scenario.sensors.closest_obstacle.model_copy(update={"frame": frame}),
    })
    built = build_modalities(sorted(MODALITIES), room.world, sensors)
    assert set(built) >= set(ALL)
    for key, modality in built.items():
        offset, scale = modality.scale()
        shape = modality.space().shape
        assert offset.shape == scale.shape == shape and offset.dtype == scale.dtype == np.float32, key
        assert np.all(np.isfinite(offset)) and np.all(np.isfinite(scale) & (scale > 0)), key
        normalized = modality.normalized_space()
        assert normalized.shape == shape and normalized.dtype == np.float32, key
        assert normalized.contains(modality.normalize(modality.observe(room))), key


def test_declared_scales_are_the_diagonal_the_ranges_and_the_max_speed(room):
    built = build_modalities(ALL, room.world, room.scenario.sensors)
    scales = {key: modality.scale()[1] for key, modality in built.items()}
    sensors, diagonal = room.scenario.sensors, room.scenario.world_diagonal
    np.testing.assert_allclose(scales["goal"], [diagonal, 1, 1], rtol=1e-6)  # one diagonal, not the 2x clip bound
    np.testing.assert_allclose(scales["closest_obstacle"], [sensors.closest_obstacle.max_range, 1, 1], rtol=1e-6)
    np.testing.assert_allclose(scales["velocity"], [room.scenario.robot.max_speed] * 2, rtol=1e-6)
    assert np.all(scales["lidar"] == 1.0) and np.all(scales["leog"] == 255.0)  # lidar kept in [0, 1]; grids -> 0/1
    assert all(np.all(modality.scale()[0] == 0.0) for modality in built.values())
    np.testing.assert_allclose(built["goal"].normalized_space().high, [2, 1, 1], rtol=1e-6)
    # "nothing within range" reads (1, 0, 1) once normalised, like a LIDAR beam that sees nothing
    far = built["closest_obstacle"].normalize(np.array([sensors.closest_obstacle.max_range, 0, 1], dtype=np.float32))
    np.testing.assert_allclose(far, [1, 0, 1])


@pytest.mark.parametrize("scenario", ["open_space", "room_furniture"])
def test_normalized_observations_of_random_episodes_are_finite_and_mostly_within_unit_range(scenario):
    sim = Simulator(scenario)
    keys = ["goal", "closest_obstacle", "lidar", "velocity"]
    built = build_modalities(keys, sim.world, sim.scenario.sensors)
    values: dict[str, list[np.ndarray]] = {key: [] for key in keys}
    rng = np.random.default_rng(0)
    for episode in range(3):
        sim.reset(seed=episode)
        for _ in range(60):
            for key, modality in built.items():
                normalized = modality.normalize(modality.observe(sim))
                assert modality.normalized_space().contains(normalized), key
                values[key].append(normalized)
            if sim.step(rng.uniform(-1, 1, size=2)).terminated:
                break
    for key, rows in values.items():
        stacked = np.stack(rows)
        assert np.all(np.isfinite(stacked)), key
        assert np.mean(np.abs(stacked) <= 1.0) >= 0.99, key
        assert np.abs(stacked).max() > 0.05, key  # and not squashed to nothing
    distances = np.stack(values["goal"])[:, 0]
    assert 0.1 < distances.max() <= 1.0  # goal distances inside the world: up to one diagonal


def test_a_modality_without_its_own_scale_gets_one_from_its_box(room):
    class Bounded(Modality):
        key = "bounded"

        def make_space(self):
            return spaces.Box(np.float32([-4.0, 0.0, 0.0]), np.float32([2.0, np.inf, 0.0]), dtype=np.float32)

        def observe(self, sim):
            return np.zeros(3, dtype=np.float32)

    offset, scale = Bounded(room.world).scale()
    np.testing.assert_array_equal(offset, [0, 0, 0])
    np.testing.assert_array_equal(scale, [4, 1, 1])  # max(|low|, |high|); 1 where infinite or zero

    class BadScale(Bounded):
        def scale(self):
            return np.zeros(2), np.ones(2)

    with pytest.raises(ValueError, match="'bounded': offset and scale must have the observation's shape"):
        BadScale(room.world).normalize(np.zeros(3, dtype=np.float32))
