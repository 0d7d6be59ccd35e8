"""The Gymnasium environment: registration, env_checker, determinism, options and action errors."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import crowdnav.envs  # noqa: F401  (registers the environments until crowdnav/__init__ imports them)
from crowdnav.envs import ENV_IDS, SCENARIO_FILE_ID, CrowdNavEnv, env_id
from crowdnav.scenario import ScenarioError, load_scenario
from crowdnav.scenario.library import library_dir, library_names
from crowdnav.scenario.reward_presets import REWARD_PRESETS

ALL_MODALITIES = ["goal", "closest_obstacle", "lidar", "leog", "velocity"]


def test_every_library_scenario_has_a_registered_id():
    assert ENV_IDS == [env_id(name) for name in library_names()]
    assert env_id("room_furniture") == "crowdnav/RoomFurniture-v0"
    assert {"crowdnav/RoomFurniture-v0", "crowdnav/OpenSpace-v0"} <= set(gym.registry)


@pytest.mark.parametrize("gym_id", ENV_IDS)
@pytest.mark.filterwarnings("error")
def test_env_checker_passes_with_all_modalities_and_no_warning(gym_id):
    env = gym.make(gym_id, modalities=ALL_MODALITIES)
    assert set(env.observation_space.spaces) == set(ALL_MODALITIES)
    check_env(env.unwrapped)  # unwrapped: gym.make's own checker wrapper would itself warn
    env.close()


@pytest.mark.filterwarnings("error")
def test_scenario_file_id_makes_any_yaml_file(tmp_path):
    path = tmp_path / "my_room.yaml"
    path.write_text((library_dir() / "room_furniture.yaml").read_text())
    env = gym.make(SCENARIO_FILE_ID, scenario=str(path), modalities=["goal", "lidar"])
    observation, info = env.reset(seed=0)
    assert env.unwrapped.scenario.name == "my_room"
    assert observation["lidar"].shape == (360,) and info == {}
    env.step(env.action_space.sample())


def test_scenario_file_id_without_a_scenario_says_what_to_pass():
    with pytest.raises(ValueError, match="a scenario is required: a library name"):
        gym.make(SCENARIO_FILE_ID)


def run_episode(env: gym.Env, seed: int, steps: int = 60) -> tuple[list[dict], list[float]]:
    actions = np.random.default_rng(123).uniform(-1, 1, size=(steps, 2)).astype(np.float32)
    observation, _ = env.reset(seed=seed)
    observations, rewards = [observation], []
    for action in actions:
        observation, reward, terminated, truncated, _ = env.step(action)
        observations.append(observation)
        rewards.append(reward)
        if terminated or truncated:
            break
    return observations, rewards


def test_same_seed_gives_the_same_episode_bit_for_bit():
    first = run_episode(gym.make("crowdnav/RoomFurniture-v0", modalities=ALL_MODALITIES), seed=11)
    second = run_episode(gym.make("crowdnav/RoomFurniture-v0", modalities=ALL_MODALITIES), seed=11)
    assert first[1] == second[1]
    assert len(first[0]) == len(second[0]) > 2
    for a, b in zip(*(first[0], second[0]), strict=True):
        assert all(np.array_equal(a[key], b[key]) and a[key].dtype == b[key].dtype for key in ALL_MODALITIES)


def test_different_seeds_give_different_episodes():
    env = gym.make("crowdnav/RoomFurniture-v0", modalities=["goal", "lidar"])
    first, rewards_first = run_episode(env, seed=1, steps=5)
    second, rewards_second = run_episode(env, seed=2, steps=5)
    assert not np.array_equal(first[0]["goal"], second[0]["goal"])
    assert rewards_first != rewards_second


def test_options_reach_the_scenario_and_the_spaces():
    env = CrowdNavEnv(
        "room_furniture",
        modalities=["lidar", "goal"],
        sensors={"lidar": {"beams": 180}, "goal": {"frame": "cartesian"}},
        reward_weights={"social": -50.0},
        overrides={"humans.count": 4, "max_steps": 20},
    )
    assert env.observation_space["lidar"].shape == (180,)
    assert env.observation_space["goal"].shape == (2,)
    assert env.scenario.reward.social == -50.0 and env.scenario.reward.step == REWARD_PRESETS["default"].weights["step"]
    env.reset(seed=0)
    assert env.simulator.n_humans == 4


def test_default_modalities_come_from_the_scenario():
    env = CrowdNavEnv("room_furniture")
    assert list(env.observation_space.spaces) == sorted(env.scenario.sensors.modalities)


@pytest.mark.parametrize(
    ("options", "path"),
    [
        ({"overrides": {"humans.count": -3}}, "humans.count"),
        ({"overrides": {"humans.bogus": 1}}, "humans.bogus"),
        ({"sensors": {"lidar": {"beams": 0}}}, "sensors.lidar.beams"),
        ({"sensors": {"lidar": {"range": 3.0}}}, "sensors.lidar.range"),
        ({"reward_weights": {"speed": 1.0}}, "reward.speed"),
        ({"reward_weights": {"step": float("nan")}}, "reward.step"),
        ({"modalities": ["goal", "sonar"]}, "sensors.modalities"),
        ({"modalities": []}, "sensors.modalities"),
    ],
)
def test_bad_options_raise_a_scenario_error_naming_the_path(options, path):
    with pytest.raises(ScenarioError, match=path.replace(".", r"\.")):
        CrowdNavEnv("room_furniture", **options)


def test_an_unknown_modality_in_the_file_is_reported_with_its_line_when_the_env_is_built(tmp_path):
    text = (library_dir() / "room_furniture.yaml").read_text(encoding="utf-8")
    file = tmp_path / "room.yaml"
    file.write_text(text + "sensors: {modalities: [goal, sonar]}\n", encoding="utf-8")
    with pytest.raises(ScenarioError) as caught:
        CrowdNavEnv(str(file))
    (issue,) = caught.value.issues
    assert issue.path == "sensors.modalities" and "'sonar'" in issue.message
    assert issue.line == text.count("\n") + 1


@pytest.mark.parametrize("make", [CrowdNavEnv, crowdnav.envs.parallel_env], ids=["gymnasium", "pettingzoo"])
def test_building_an_env_compiles_its_world_once(monkeypatch, make):
    import crowdnav.worlds.compiled

    calls = []
    compile_world = crowdnav.worlds.compiled.compile_world
    monkeypatch.setattr(crowdnav.worlds.compiled, "compile_world", lambda scenario: calls.append(scenario.name) or compile_world(scenario))
    env = make("room_furniture", modalities=["goal", "lidar"])
    env.reset(seed=0)
    assert calls == ["room_furniture"]


def test_malformed_options_raise_clear_errors():
    with pytest.raises(ValueError, match="modalities must be a list"):
        CrowdNavEnv("room_furniture", modalities="lidar")
    with pytest.raises(ValueError, match="sensors must be a mapping"):
        CrowdNavEnv("room_furniture", sensors=["lidar"])


def test_non_finite_or_misshapen_actions_raise_and_leave_the_state_alone():
    env = CrowdNavEnv("room_furniture", modalities=["goal"])
    env.reset(seed=0)
    for bad in ([np.nan, 0.0], [0.0, np.inf]):
        with pytest.raises(ValueError, match=r"robot action must be finite \(no NaN or inf\)"):
            env.step(np.array(bad, dtype=np.float32))
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        env.step(np.zeros(3))
    with pytest.raises(ValueError, match="2 numbers"):
        env.step("forward")
    assert env.simulator.step_count == 0


def test_out_of_range_actions_are_clipped():
    def after_one_step(action):
        env = CrowdNavEnv("room_furniture", modalities=["goal"], overrides={"humans.count": 0})
        env.reset(seed=4)
        env.step(np.array(action, dtype=np.float32))
        return env.simulator.robot_position

    assert after_one_step([5.0, -7.0]) == after_one_step([1.0, -1.0])
    assert after_one_step([0.5, -3.0]) == after_one_step([0.5, -1.0])


def test_both_envs_share_one_simulator_class_and_one_crowd_model():
    single = CrowdNavEnv("room_furniture", modalities=["goal"])
    multi = crowdnav.envs.parallel_env("room_furniture", modalities=["goal"])
    assert type(single.simulator) is type(multi.simulator)
    # driving the multi-agent humans with SocialForcePolicy reproduces the single-agent episode
    policy = crowdnav.envs.SocialForcePolicy(multi.scenario)
    single.reset(seed=9)
    observations, _ = multi.reset(seed=9)
    action = np.array([0.3, 0.2], dtype=np.float32)
    for _ in range(100):
        _, _, terminated, truncated, _ = single.step(action)
        observations, *_ = multi.step({**policy(observations), "robot": action})
        np.testing.assert_allclose(single.simulator.positions, multi.simulator.positions, atol=1e-4)
        if terminated or truncated:
            break
    assert single.simulator.step_count > 10 and not multi.agents


def flee_the_goal(env: CrowdNavEnv, limit: int = 200) -> tuple[int, float, bool, bool, dict]:
    """Drive the holonomic robot straight away from its goal until the episode ends: (steps, last reward, terminated, truncated, info)."""
    sim = env.simulator
    sim.robot_heading = 0.0  # holonomic: the action is then a world-frame direction
    away = sim.robot_position - sim.robot_goal
    action = np.array([away.real, away.imag]) / abs(away)
    for step in range(1, limit + 1):
        _, reward, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            return step, reward, terminated, truncated, info
    raise AssertionError("the episode did not end")


@pytest.mark.parametrize("scenario", ["open_space", "crowded_open_space", "circle_crossing", "perpendicular_crossing"])
def test_robot_driven_out_of_an_open_world_ends_out_of_bounds_and_pays_the_collision_term(scenario):
    env = CrowdNavEnv(scenario, modalities=["goal"], overrides={"humans.count": 0})
    assert not env.scenario.world.boundary_walls
    env.reset(seed=0)
    steps, reward, terminated, truncated, info = flee_the_goal(env)
    assert info["outcome"] == "out_of_bounds" and info["is_success"] is False
    assert terminated is True and truncated is False
    assert "collision_kind" not in info and "collision_partner" not in info
    assert steps < env.scenario.max_steps  # the robot did not wander until the time limit
    assert info["reward_terms"]["collision"] == env.scenario.reward.collision != 0.0
    assert info["reward_terms"]["goal_reached"] == 0.0
    assert reward == pytest.approx(sum(info["reward_terms"].values()))
    (x0, y0), (x1, y1) = env.scenario.world.min, env.scenario.world.max
    position = env.simulator.robot_position
    assert not (x0 <= position.real <= x1 and y0 <= position.imag <= y1)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(2))


def test_with_boundary_walls_the_same_drive_ends_in_a_static_collision():
    env = CrowdNavEnv("open_space", modalities=["goal"], overrides={"humans.count": 0, "world.boundary_walls": True})
    env.reset(seed=0)
    _, _, terminated, truncated, info = flee_the_goal(env)
    assert info["outcome"] == "collision" and info["collision_kind"] == "static" and "boundary" in info["collision_partner"]
    assert terminated is True and truncated is False
    assert info["reward_terms"]["collision"] == env.scenario.reward.collision
    assert not env.simulator.robot_left_world()  # leaving the world is impossible with walls


def test_every_library_scenario_either_walls_the_robot_in_or_ends_the_episode_when_it_leaves():
    for name in library_names():
        no_humans = {"humans.groups": []} if load_scenario(name).humans.groups else {"humans.count": 0}
        env = CrowdNavEnv(name, modalities=["goal"], overrides=no_humans)
        env.reset(seed=0)
        _, _, terminated, truncated, info = flee_the_goal(env, limit=env.scenario.max_steps)
        if env.scenario.world.boundary_walls:
            assert info["outcome"] == "collision" and info["collision_kind"] == "static", name  # walls or furniture first
        else:
            assert info["outcome"] == "out_of_bounds", name
        assert terminated and not truncated, name
        env.close()
