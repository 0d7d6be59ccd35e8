"""Several robots in the envs (``robots:``): PettingZoo (each robot an agent, robots only, SuperSuit), Gymnasium
(scripted others), rendering and trajectories."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import crowdnav
from crowdnav.envs import CrowdNavEnv, parallel_env
from tests.core.multi_robot_scenes import HALL, LANES, hall

# ----------------------------------------------------------------------------- PettingZoo env

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", message="The old environment creation API", category=DeprecationWarning)
    from pettingzoo.test import parallel_api_test

PARALLEL_MODES = {
    "humans_as_agents": {},
    "humans_as_agents_fixed": {"fixed_agents": True},
    "robots_only": {"humans_as_agents": False},
    "robots_only_fixed_flat": {"humans_as_agents": False, "fixed_agents": True, "flat_observations": True},
}


@pytest.mark.parametrize("mode", PARALLEL_MODES)
def test_parallel_api_test_passes_with_several_robots_without_any_warning(mode):
    env = parallel_env(HALL, modalities=["goal", "lidar"], sensors={"lidar": {"beams": 16}}, **PARALLEL_MODES[mode])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        parallel_api_test(env, num_cycles=300)


def test_each_robot_is_an_agent_with_its_own_modalities_and_the_humans_follow_the_crowd_model():
    env = parallel_env(LANES, humans_as_agents=False)
    assert env.possible_agents == ["east", "west"]
    assert list(env.observation_space("east").spaces) == ["goal", "lidar"]
    assert list(env.observation_space("west").spaces) == ["goal", "humans", "velocity"]
    assert env.state_space.shape == (2 * 8,)


def test_a_robot_that_reached_its_goal_leaves_and_the_other_goes_on():
    env = parallel_env(LANES, humans_as_agents=False)
    env.reset(seed=0)
    forward = np.array([1.0, 0.0])
    ended = {}
    for _ in range(40):
        observations, rewards, terminations, truncations, infos = env.step({agent: forward for agent in env.agents})
        assert set(observations) == set(rewards) == set(terminations) == set(infos)
        for agent, done in terminations.items():
            if done:
                ended[agent] = (infos[agent]["outcome"], len(ended))
        if not env.agents:
            break
    assert ended == {"east": ("success", 0), "west": ("success", 1)}
    assert infos["west"]["reward_terms"]["goal_reached"] > 0


def test_under_fixed_agents_a_robot_that_ended_stays_an_inactive_agent():
    env = parallel_env(LANES, humans_as_agents=False, fixed_agents=True)
    env.reset(seed=0)
    seen_inactive = False
    while env.agents:
        assert env.agents == ["east", "west"]
        observations, rewards, terminations, truncations, infos = env.step({agent: np.array([1.0, 0.0]) for agent in env.agents})
        if not infos["east"]["active"]:
            seen_inactive = True
            assert rewards["east"] == 0.0 and not any(value.any() for value in observations["east"].values())
            assert env.agents == [] or not terminations["east"]
    assert seen_inactive and terminations == {"east": True, "west": True}


def test_robots_only_fixed_agents_go_through_supersuit_to_sb3_ppo():
    ss = pytest.importorskip("supersuit")
    sb3 = pytest.importorskip("stable_baselines3")
    torch = pytest.importorskip("torch")
    torch.set_num_threads(1)
    env = parallel_env(hall(max_steps=30), modalities=["goal", "closest_obstacle"], humans_as_agents=False, fixed_agents=True,
                       flat_observations=True)
    vec = ss.pettingzoo_env_to_vec_env_v1(env)
    vec = ss.concat_vec_envs_v1(vec, 2, num_cpus=0, base_class="stable_baselines3")
    assert vec.num_envs == 2 * 2
    vec.venv.reset(seed=0)
    sb3.common.utils.set_random_seed(0)
    model = sb3.PPO("MlpPolicy", vec, n_steps=16, batch_size=32, n_epochs=1, device="cpu")
    model.learn(total_timesteps=200)
    observations, ends = vec.reset(), 0
    for _ in range(80):
        actions, _ = model.predict(observations, deterministic=True)
        observations, rewards, dones, infos = vec.step(actions)
        assert np.isfinite(observations).all() and np.isfinite(rewards).all()
        ends += int(dones.reshape(2, 2).all(axis=1).sum())
    assert ends >= 2


# ----------------------------------------------------------------------------- Gymnasium env


@pytest.mark.parametrize("other_robots", ["social-force", "straight"])
def test_gym_env_learns_the_first_robot_and_passes_check_env_with_scripted_others(other_robots):
    from gymnasium.utils.env_checker import check_env

    env = CrowdNavEnv(HALL, other_robots=other_robots)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env, skip_render_check=True)


def test_gym_env_reports_the_other_robots_outcomes_and_a_callable_drives_them():
    calls = []

    def forward(view):
        calls.append(view.robot_position)
        return np.array([1.0, 0.0])

    env = CrowdNavEnv(LANES, other_robots=forward)
    env.reset(seed=0)
    for _ in range(40):
        _, _, terminated, truncated, info = env.step(np.zeros(2))  # the first robot waits
        if info["other_robots"]["west"] is not None:
            break
    assert info["other_robots"] == {"west": "success"} and not terminated
    assert not env.simulator.robots_active[1] and len(calls) >= 1
    env.step(np.zeros(2))
    assert len(calls) == len(set(calls))  # no call after it left


def test_an_unknown_other_robot_policy_is_a_one_line_error():
    with pytest.raises(ValueError, match="other_robots='wander' is not a scripted robot policy"):
        CrowdNavEnv(HALL, other_robots="wander")


# ----------------------------------------------------------------------------- rendering


def test_rgb_frames_draw_every_robot_in_its_own_colour_and_name_it_in_the_legend():
    pytest.importorskip("pygame")
    from crowdnav.rendering.renderer import Overlays, Palette

    env = CrowdNavEnv("robots_crossing_hall", render_mode="rgb_array", other_robots="straight")
    env.reset(seed=0)
    env.step(np.array([1.0, 0.0]))
    frame = env.render()
    colours = Palette().robots[:3]
    assert len(set(colours)) == 3
    counts = [int((frame == np.array(colour, dtype=np.uint8)).all(-1).sum()) for colour in colours]
    assert min(counts) > 100, counts  # each robot's disc (and goal ring) in its colour
    names = [name for _, name, _ in env.core.view.renderer._legend_entries(Overlays())]
    assert names[:3] == ["east_bound", "west_bound", "north_bound"]


def test_a_robot_that_left_is_no_longer_drawn():
    pytest.importorskip("pygame")
    from crowdnav.rendering.renderer import Palette

    env = CrowdNavEnv("robots_crossing_hall", render_mode="rgb_array", other_robots="straight")
    env.reset(seed=0)
    env.simulator.retire_robots([2])
    env.step(np.zeros(2))
    north = np.array(Palette().robots[2], dtype=np.uint8)
    frame = env.render()
    legend_swatch = 200  # the legend keeps the robot's entry; the map has no disc of its colour left
    assert 0 < int((frame == north).all(-1).sum()) < legend_swatch


def test_humans_as_agents_see_the_nearest_robot_when_they_see_robots():
    env = parallel_env(hall(humans={**HALL["humans"], "see_robot": True}), modalities=["goal"])
    observations, _ = env.reset(seed=0)
    sim = env.simulator
    human = sim.human_positions[0]
    nearest = sim.robot_positions[np.argmin(np.abs(sim.robot_positions - human))]
    np.testing.assert_allclose(observations["human_0"]["robot_offset"], [(nearest - human).real, (nearest - human).imag], rtol=1e-6)
    assert all(env.observation_space(name).contains(observations[name]) for name in observations)


# ----------------------------------------------------------------------------- trajectories


def test_trajectories_have_one_track_per_robot_under_its_name_until_it_leaves():
    from crowdnav.evaluation.trajectories import record_policy, tidy_table, trajnet_lines

    episodes = record_policy("baseline:straight", "robots_crossing_hall", episodes=2)
    table = tidy_table(episodes)
    robots = table[table.group == "robot"]
    assert set(robots.agent) == {"east_bound", "west_bound", "north_bound"}
    assert robots.groupby(["test_episode", "agent"]).track.nunique().eq(1).all()
    assert not table[table.agent == "east_bound"][["x", "y"]].isna().any().any()  # the learned robot ends the episode
    for line in trajnet_lines(episodes):
        assert "NaN" not in line


@pytest.mark.parametrize("options", [{}, {"flat_observations": True, "fixed_agents": True, "humans_as_agents": False}])
def test_the_aec_env_of_a_multi_robot_scenario_passes_pettingzoo_api_test(options):
    from pettingzoo.test import api_test

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Dict observations draw style recommendations, not failures
        api_test(crowdnav.env("robots_crossing_hall", modalities=["goal"], **options), num_cycles=100)


@pytest.mark.filterwarnings("error")
def test_parallel_seed_test_passes_for_robots_only_fixed_agents():
    from pettingzoo.test import parallel_seed_test

    parallel_seed_test(lambda: parallel_env("robots_crossing_hall", modalities=["goal"], humans_as_agents=False, fixed_agents=True),
                       num_cycles=50)


def test_robots_only_parallel_env_plays_the_gym_envs_episode_when_the_others_follow_the_same_policy():
    from crowdnav.planning.scripted import StraightToGoal

    gym_env, par_env = CrowdNavEnv(HALL, other_robots="straight"), parallel_env(HALL, humans_as_agents=False)
    gym_observation, _ = gym_env.reset(seed=4)
    par_observations, _ = par_env.reset(seed=4)
    straight, action = StraightToGoal(), np.array([0.6, 0.3])
    for _ in range(HALL.get("max_steps", 150)):
        actions = {"east": action}
        if "west" in par_env.agents:
            actions["west"] = straight(par_env.simulator.robot_view(1))
        gym_observation, reward, terminated, truncated, _ = gym_env.step(action)
        par_observations, rewards, terminations, truncations, _ = par_env.step(actions)
        assert all(np.array_equal(gym_observation[key], par_observations["east"][key]) for key in gym_observation)
        assert reward == rewards["east"] and terminated == terminations["east"]
        if terminated or truncated:
            break
    assert np.array_equal(gym_env.simulator.positions, par_env.simulator.positions)


def test_one_robot_robots_only_mode_is_the_gym_env_as_a_parallel_env():
    gym_env, par_env = CrowdNavEnv("open_space", modalities=["goal"]), parallel_env("open_space", modalities=["goal"], humans_as_agents=False)
    gym_observation, _ = gym_env.reset(seed=3)
    par_env.reset(seed=3)
    assert par_env.possible_agents == ["robot"]
    for _ in range(40):
        gym_observation, reward, terminated, truncated, _ = gym_env.step(np.array([0.5, 0.2]))
        observations, rewards, *_ = par_env.step({"robot": np.array([0.5, 0.2])})
        assert np.array_equal(gym_observation["goal"], observations["robot"]["goal"]) and reward == rewards["robot"]
        if terminated or truncated:
            break
