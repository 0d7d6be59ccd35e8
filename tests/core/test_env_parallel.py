"""The PettingZoo environment: API and seed tests, agents, spaces, human observations, action errors."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from shapely.geometry import Point

import crowdnav
import crowdnav.envs  # noqa: F401  (registers the environments until crowdnav/__init__ imports them)
from crowdnav.envs import CrowdNavParallelEnv, parallel_env

with warnings.catch_warnings():
    # pettingzoo.test's __init__ imports PettingZoo's own example envs through their deprecated
    # creation API; the warning is about PettingZoo's code, not ours.
    warnings.filterwarnings("ignore", message="The old environment creation API", category=DeprecationWarning)
    from pettingzoo.test import parallel_api_test, parallel_seed_test

FAST = {"modalities": ["goal", "closest_obstacle"]}
"""Cheap robot modalities: these tests are about the multi-agent API, not the sensors."""

API_CASES = {
    "room_furniture": ("room_furniture", {}),
    "open_space": ("open_space", {}),
    "crowd_range": ("room_furniture", {"overrides": {"humans.count": [2, 5]}}),
    "see_robot": ("corridor", {"overrides": {"humans.see_robot": True}}),
}


INACTIVE_HUMANS_WARNING = "No agents present but not all possible_agents are terminated or truncated"
"""With a crowd-size range, humans beyond this episode's count never enter ``agents``, so they
are never terminated; PettingZoo's API test notes it (it counts as finished only agents that were
live, so reporting their termination cannot silence it). It is the only warning allowed here;
``fixed_agents=True`` passes without any (tests/core/test_supersuit_fixed_agents.py)."""


@pytest.mark.parametrize("case", API_CASES)
def test_pettingzoo_parallel_api_test_passes(case):
    scenario, options = API_CASES[case]
    env = parallel_env(scenario, **FAST, **options)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        parallel_api_test(env, num_cycles=200)
    messages = {str(warning.message) for warning in caught}
    allowed = {INACTIVE_HUMANS_WARNING} if case == "crowd_range" else set()
    assert messages <= allowed


@pytest.mark.parametrize("case", API_CASES)
@pytest.mark.filterwarnings("error")
def test_pettingzoo_parallel_seed_test_passes(case):
    scenario, options = API_CASES[case]
    parallel_seed_test(lambda: parallel_env(scenario, **FAST, **options), num_cycles=50)


def test_crowdnav_parallel_env_is_exported_and_built_for_a_yaml_path(tmp_path):
    source = crowdnav.scenario.library.library_dir() / "room_furniture.yaml"
    path = tmp_path / "copy.yaml"
    path.write_text(source.read_text())
    env = parallel_env(str(path), **FAST)
    assert isinstance(env, CrowdNavParallelEnv)
    assert env.possible_agents == ["robot", *(f"human_{i}" for i in range(10))]


def test_crowd_range_activates_the_first_n_humans():
    env = parallel_env("room_furniture", **FAST, overrides={"humans.count": [2, 5]})
    assert env.possible_agents == ["robot", *(f"human_{i}" for i in range(5))]
    counts = set()
    for seed in range(12):
        observations, infos = env.reset(seed=seed)
        n = env.simulator.n_humans
        counts.add(n)
        assert env.agents == ["robot", *(f"human_{i}" for i in range(n))]
        assert set(observations) == set(infos) == set(env.agents)
        mask = observations["human_0"]["humans_mask"]
        assert mask.shape == (4,) and mask.tolist() == [1.0] * (n - 1) + [0.0] * (5 - n)
    assert len(counts) > 1


def test_an_episode_with_an_empty_crowd_has_only_the_robot_active():
    env = parallel_env("room_furniture", **FAST, overrides={"humans.count": [0, 2]})
    seed = next(seed for seed in range(100) if env.reset(seed=seed) and env.simulator.n_humans == 0)
    observations, _ = env.reset(seed=seed)
    assert env.agents == ["robot"] and list(observations) == ["robot"]
    assert env.possible_agents == ["robot", "human_0", "human_1"]
    _, rewards, *_ = env.step({"robot": np.zeros(2, dtype=np.float32)})
    assert list(rewards) == ["robot"]


def test_spaces_are_the_same_object_every_call_and_distinct_per_agent():
    env = parallel_env("room_furniture", **FAST)
    for agent in env.possible_agents:
        assert env.observation_space(agent) is env.observation_space(agent)
        assert env.action_space(agent) is env.action_space(agent)
    assert env.observation_space("human_0") is not env.observation_space("human_1")
    assert env.action_space("human_0") == env.action_space("human_1")


def test_see_robot_adds_the_robot_to_human_observations():
    without = parallel_env("room_furniture", **FAST)
    with_robot = parallel_env("room_furniture", **FAST, overrides={"humans.see_robot": True})
    robot_keys = {"robot_offset", "robot_velocity", "robot_radius"}
    assert not robot_keys & set(without.observation_space("human_0").spaces)
    assert robot_keys <= set(with_robot.observation_space("human_0").spaces)
    observations, _ = with_robot.reset(seed=4)
    sim = with_robot.simulator
    robot_offset = observations["human_2"]["robot_offset"]
    np.testing.assert_allclose(robot_offset, _xy(sim.positions[0] - sim.positions[3]), atol=1e-6)
    assert observations["human_2"]["robot_radius"][0] == pytest.approx(sim.radii[0])


def _xy(z: complex) -> np.ndarray:
    return np.array([z.real, z.imag])


def test_human_observations_describe_the_simulator_state():
    env = parallel_env("room_furniture", **FAST)
    observations, _ = env.reset(seed=7)
    rng = np.random.default_rng(0)
    for _ in range(5):  # seeded human actions and a robot standing still: the episode cannot end by chance
        actions = {agent: rng.uniform(-1, 1, 2).astype(np.float32) for agent in env.agents}
        actions["robot"] = np.zeros(2, dtype=np.float32)
        observations, *_ = env.step(actions)
    sim, obstacles = env.simulator, env.simulator.obstacles
    discs = zip(obstacles.disc_center, obstacles.disc_radius, strict=True)
    shapes = list(obstacles.polygons) + [Point(c.real, c.imag).buffer(r, 256) for c, r in discs]
    assert obstacles.disc_count == 1  # the round table: its nearest point is on the disc's surface
    for i in rng.choice(sim.n_humans, 4, replace=False):
        obs = observations[f"human_{i}"]
        assert obs in env.observation_space(f"human_{i}")
        p = sim.positions[1 + i]
        np.testing.assert_allclose(obs["position"], _xy(p), atol=1e-5)
        np.testing.assert_allclose(obs["velocity"], _xy(sim.velocities[1 + i]), atol=1e-6)
        np.testing.assert_allclose(obs["goal"], _xy(sim.human_goals[i]), atol=1e-5)
        assert obs["max_speed"][0] == pytest.approx(sim.human_max_speed[i], rel=1e-6)
        assert obs["preferred_speed"][0] == pytest.approx(sim.human_preferred_speed[i], rel=1e-6)
        others = [j for j in range(sim.n_humans) if j != i]
        expected = np.array([_xy(sim.positions[1 + j] - p) for j in others])
        np.testing.assert_allclose(obs["humans_offset"], expected, atol=1e-5)
        relative = np.array([_xy(sim.velocities[1 + j] - sim.velocities[1 + i]) for j in others])
        np.testing.assert_allclose(obs["humans_velocity"], relative, atol=1e-6)
        # nearest points lie on the obstacles' outlines: their distance matches shapely's
        centre = Point(p.real, p.imag)
        distances = np.hypot(obs["obstacles_offset"][:, 0], obs["obstacles_offset"][:, 1])
        np.testing.assert_allclose(distances, [shape.exterior.distance(centre) for shape in shapes], atol=1e-3)
        nearest = obs["obstacles_offset"] + obs["position"]
        on_outline = [shape.exterior.distance(Point(*q)) for shape, q in zip(shapes, nearest, strict=True)]
        assert max(on_outline) < 1e-3


def test_robot_is_rewarded_and_humans_get_zero():
    env = parallel_env("room_furniture", **FAST)
    env.reset(seed=0)
    actions = {agent: env.action_space(agent).sample() for agent in env.agents}
    _, rewards, terminations, truncations, infos = env.step(actions)
    assert set(rewards) == set(terminations) == set(truncations) == set(infos) == set(env.possible_agents)
    assert "reward_terms" in infos["robot"]
    assert rewards["robot"] == sum(infos["robot"]["reward_terms"].values())
    assert all(rewards[f"human_{i}"] == 0.0 for i in range(10))


def test_episode_end_removes_every_agent_at_once():
    env = parallel_env("room_furniture", **FAST, overrides={"max_steps": 4})
    env.reset(seed=0)
    for _ in range(4):
        assert len(env.agents) == 11
        actions = {agent: np.zeros(2, dtype=np.float32) for agent in env.agents}
        _, _, terminations, truncations, infos = env.step(actions)
    assert env.agents == []
    assert set(truncations.values()) == {True} or set(terminations.values()) == {True}
    assert infos["robot"]["outcome"] in ("truncated", "collision", "success")
    with pytest.raises(RuntimeError, match="reset"):
        env.step({})


def test_robot_leaving_an_open_world_terminates_every_agent_out_of_bounds():
    env = parallel_env("open_space", **FAST, overrides={"humans.count": 3})
    env.reset(seed=0)
    sim = env.simulator
    # park the robot 0.1 m inside the right edge, where it is farthest from the (standing) humans, and drive right
    edge = sim.scenario.world.max[0] - 0.1
    spots = [complex(edge, y) for y in np.linspace(-4.0, 4.0, 17)]
    sim.positions[0] = max(spots, key=lambda spot: np.abs(sim.human_positions - spot).min())
    sim.robot_heading = 0.0
    sim.refresh()
    actions = {agent: np.zeros(2, dtype=np.float32) for agent in env.agents}
    actions["robot"] = np.array([1.0, 0.0], dtype=np.float32)
    agents = list(env.agents)
    _, rewards, terminations, truncations, infos = env.step(actions)
    assert terminations == dict.fromkeys(agents, True) and truncations == dict.fromkeys(agents, False)
    assert env.agents == []
    assert infos["robot"]["outcome"] == "out_of_bounds" and infos["robot"]["is_success"] is False
    assert infos["robot"]["reward_terms"]["collision"] == env.scenario.reward.collision
    assert all(rewards[agent] == 0.0 for agent in agents if agent != "robot")


def test_missing_unknown_and_non_finite_actions_raise_clear_errors():
    env = parallel_env("room_furniture", **FAST, overrides={"humans.count": 2})
    env.reset(seed=0)
    good = {agent: np.zeros(2, dtype=np.float32) for agent in env.agents}
    with pytest.raises(ValueError, match=r"missing: \['human_1'\]"):
        env.step({k: v for k, v in good.items() if k != "human_1"})
    with pytest.raises(ValueError, match=r"missing: \['robot'\]"):
        env.step({k: v for k, v in good.items() if k != "robot"})
    with pytest.raises(ValueError, match=r"not in env.agents: \['human_7'\]"):
        env.step({**good, "human_7": np.zeros(2)})
    with pytest.raises(ValueError, match="human_0.*nan"):
        env.step({**good, "human_0": np.array([np.nan, 0.0])})
    with pytest.raises(ValueError, match="wrong shapes"):
        env.step({**good, "human_1": np.zeros(3)})
    with pytest.raises(ValueError, match="robot action must be finite"):
        env.step({**good, "robot": np.array([0.0, np.inf])})
    env.step(good)  # the failed calls changed nothing
    assert env.simulator.step_count == 1


def test_scenario_without_humans_has_only_the_robot():
    env = parallel_env("room_furniture", **FAST, overrides={"humans.count": 0})
    observations, _ = env.reset(seed=0)
    assert env.possible_agents == env.agents == ["robot"] and list(observations) == ["robot"]
    observations, rewards, *_ = env.step({"robot": np.zeros(2, dtype=np.float32)})
    assert list(rewards) == ["robot"]


def test_same_seed_gives_the_same_multi_agent_episode_bit_for_bit():
    """PettingZoo's seed test stops after one step (it tests ``any(dict)``), so check whole episodes."""

    def episode(seed):
        env = parallel_env("room_furniture", **FAST, overrides={"humans.see_robot": True})
        policy = crowdnav.envs.SocialForcePolicy(env.scenario)
        robot = np.random.default_rng(0).uniform(-1, 1, size=(200, 2)).astype(np.float32)
        observations, _ = env.reset(seed=seed)
        history = [(observations, {})]
        for action in robot:
            observations, rewards, *_ = env.step({**policy(observations), "robot": action})
            history.append((observations, rewards))
            if not env.agents:
                break
        return history

    first, again, other = episode(8), episode(8), episode(9)
    assert len(first) == len(again) > 5
    for (observations, rewards), (observations_again, rewards_again) in zip(first, again, strict=True):
        assert rewards == rewards_again
        assert list(observations) == list(observations_again)
        for agent, observation in observations.items():
            assert all(np.array_equal(value, observations_again[agent][key]) for key, value in observation.items())
    assert not np.array_equal(first[0][0]["human_0"]["position"], other[0][0]["human_0"]["position"])


@pytest.mark.parametrize("actions", [None, [[0.0, 0.0]], "robot", 3])
def test_step_with_something_other_than_a_dict_is_a_one_line_type_error(actions):
    env = parallel_env("open_space")
    env.reset(seed=0)
    with pytest.raises(TypeError, match=r"^step\(\) takes a dict \{agent: action\}"):
        env.step(actions)


@pytest.mark.parametrize(
    ("value", "kind"), [([1 + 2j, 0.0], "complex numbers"), (["1", "0"], "strings"), ([True, False], "booleans"), ([object(), 1], "Python objects")]
)
@pytest.mark.parametrize("agent", ["robot", "human_0"])
def test_actions_that_only_look_numeric_are_refused_naming_the_agent(agent, value, kind):
    env = parallel_env("open_space")
    env.reset(seed=0)
    actions = {name: np.zeros(2) for name in env.agents}
    actions[agent] = value
    who = "the robot action" if agent == "robot" else f"the action of {agent}"
    with pytest.raises(ValueError, match=rf"^{who} must be 2 numbers \(real, not {kind}\)"):
        env.step(actions)


@pytest.mark.parametrize("seed", [-1, 1.5, True, "3"])
def test_reset_seed_must_be_a_non_negative_integer(seed):
    env = parallel_env("open_space")
    with pytest.raises(ValueError, match="seed must be a non-negative integer or None"):
        env.reset(seed=seed)
    env.reset(seed=np.int64(3))  # numpy integers are integers
