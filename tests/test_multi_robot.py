"""Several robots in one scenario (``robots:``): schema, simulator, both envs, rendering."""

from __future__ import annotations

import copy
import warnings

import numpy as np
import pytest

import crowdnav
from crowdnav.envs import CrowdNavEnv, parallel_env
from crowdnav.scenario.errors import ScenarioError
from crowdnav.scenario.loader import load_scenario
from crowdnav.simulator import Simulator

HALL = {
    "description": "Two robots swap sides of an empty hall.",
    "world": {"min": [-5, -5], "max": [5, 5]},
    "robots": [
        {"name": "east", "start": {"type": "rectangle", "min": [-4.5, -1], "max": [-3.5, 1]},
         "goal": {"type": "rectangle", "min": [3.5, -1], "max": [4.5, 1]}},
        {"name": "west", "start": {"type": "rectangle", "min": [3.5, -1], "max": [4.5, 1]},
         "goal": {"type": "rectangle", "min": [-4.5, -1], "max": [-3.5, 1]}},
    ],
    "humans": {"count": 4, "spawn": [{"type": "rectangle", "min": [-2, -4], "max": [2, -3]}],
               "goal": [{"type": "rectangle", "min": [-2, 3], "max": [2, 4]}]},
}


def hall(**changes):
    document = copy.deepcopy(HALL)
    document.update(changes)
    return document


def error_of(document) -> str:
    with pytest.raises(ScenarioError) as caught:
        load_scenario(document)
    return str(caught.value)


def test_robots_list_names_the_agents_and_its_first_entry_is_the_ego_robot():
    scenario = load_scenario(hall())
    assert scenario.robot_names == ["east", "west"]
    assert scenario.robot is scenario.robots[0]
    assert load_scenario(scenario.model_dump()).robot_names == ["east", "west"]  # a dump loads again: no robot written


def test_unnamed_robots_are_robot_i_and_one_robot_keeps_the_name_robot():
    document = hall()
    for robot in document["robots"]:
        del robot["name"]
    assert load_scenario(document).robot_names == ["robot_0", "robot_1"]
    assert load_scenario("room_furniture").robot_names == ["robot"]


def test_robot_and_robots_together_is_an_error_at_robots():
    one = {key: value for key, value in HALL["robots"][0].items() if key != "name"}
    assert error_of(hall(robot=one)).endswith("robots: give either robot (one robot) or robots (several), not both")


def test_a_single_entry_under_robots_asks_for_at_least_two():
    assert "robots: expected at least 2 items" in error_of(hall(robots=HALL["robots"][:1]))


def test_repeated_robot_names_are_an_error():
    robots = copy.deepcopy(HALL["robots"])
    robots[1]["name"] = "east"
    assert error_of(hall(robots=robots)).endswith("robots: expected unique robot names, got 'east' more than once")


@pytest.mark.parametrize("name", ["robot", "human_0", "East", "a-b"])
def test_a_robot_name_that_could_clash_with_agent_names_is_refused(name):
    robots = copy.deepcopy(HALL["robots"])
    robots[1]["name"] = name
    assert "robots.1.name: expected lowercase letters" in error_of(hall(robots=robots))


def test_cross_field_rules_name_the_robot_in_the_list():
    robots = copy.deepcopy(HALL["robots"])
    robots[1]["kinematics"] = "unicycle"
    assert "robots.1.max_angular_speed: expected a maximum angular speed" in error_of(hall(robots=robots))


def test_file_errors_carry_the_line_of_the_robot(tmp_path):
    path = tmp_path / "two.yaml"
    path.write_text(
        "description: two robots\n"
        "robots:\n"
        "  - start: {type: points, points: [[0, 0]]}\n"
        "    goal: {type: points, points: [[3, 0]]}\n"
        "  - start: {type: points, points: [[1, 1]]}\n"
        "    goal: {type: points, points: [[3, 3]]}\n"
        "    max_speed: -1\n",
        encoding="utf-8",
    )
    message = error_of(path)
    assert "two.yaml:7: robots.1.max_speed" in message, message


# ----------------------------------------------------------------------------- simulator

HEAD_ON = hall(
    robots=[
        {"name": "east", "start": {"type": "points", "points": [[-1.5, 0]]}, "goal": {"type": "points", "points": [[4, 0]]},
         "start_heading": "toward_goal"},
        {"name": "west", "start": {"type": "points", "points": [[1.5, 0]]}, "goal": {"type": "points", "points": [[-4, 0]]},
         "start_heading": "toward_goal"},
    ],
    humans={"count": 0},
)


def test_robots_driving_head_on_both_collide_with_each_other():
    sim = Simulator(HEAD_ON)
    sim.reset(seed=0)
    for _ in range(20):
        events = sim.step(np.array([1.0, 0.0]), other_robot_actions=np.array([[1.0, 0.0]]))
        if events.terminated:
            break
    east, west = sim.robot_events
    assert east.collision.kind == "robot" and east.collision.partner == "west"
    assert west.collision.kind == "robot" and west.collision.partner == "east"
    assert east.outcome == west.outcome == "collision"


def test_a_retired_robot_leaves_the_world_and_no_longer_collides():
    sim = Simulator(HEAD_ON)
    sim.reset(seed=0)
    sim.retire_robots([1])
    for _ in range(30):
        events = sim.step(np.array([1.0, 0.0]), other_robot_actions=np.array([[1.0, 0.0]]))
        assert sim.robot_events[1] is None
        if events.terminated:
            break
    assert events.outcome == "success"
    assert not sim.robots_active[1] and sim.team.state.left_at[1] == 1.5 + 0j


def _human_pushed_by_other_robot(see_robot: bool, model: str = "social_force") -> complex:
    document = hall(humans={"count": 1, "see_robot": see_robot, "model": model, "spawn": [{"type": "points", "points": [[1.5, 0.8]]}],
                            "goal": [{"type": "points", "points": [[1.5, 4]]}]})
    document["robots"] = copy.deepcopy(HEAD_ON["robots"])
    document["robots"][1]["start"] = {"type": "points", "points": [[1.5, 1.6]]}  # right in the human's way
    sim = Simulator(document)
    sim.reset(seed=0)
    return complex(sim.crowd_commands()[0])


def test_humans_are_repelled_by_every_robot_they_see():
    seen, unseen = _human_pushed_by_other_robot(True), _human_pushed_by_other_robot(False)
    assert unseen.imag > 0.0  # toward its goal, up
    assert seen.imag < unseen.imag  # the second robot above it pushes it back down


def test_an_orca_crowd_avoids_every_robot_it_sees():
    pytest.importorskip("pyrvo")
    seen, unseen = _human_pushed_by_other_robot(True, "orca"), _human_pushed_by_other_robot(False, "orca")
    assert seen != unseen


def test_every_robot_is_drawn_clear_of_the_others_and_the_crowd():
    sim = Simulator(hall(humans={**HALL["humans"], "count": 8}))
    for seed in range(20):
        sim.reset(seed=seed)
        robots = sim.robot_positions
        assert abs(robots[0] - robots[1]) > 0.6
        assert (np.abs(sim.human_positions[:, None] - robots[None, :]) > 0.6).all()


def test_same_seed_gives_the_same_multi_robot_episode_bit_for_bit():
    def run():
        sim = Simulator(hall(humans={**HALL["humans"], "count": 6, "see_robot": True}))
        sim.reset(seed=5)
        trace = []
        for _ in range(40):
            sim.step(np.array([0.8, 0.1]), other_robot_actions=np.array([[0.5, -0.2]]))
            trace.append(np.concatenate([sim.positions, sim.robot_positions]))
        return np.array(trace)

    assert np.array_equal(run(), run())


def test_one_robot_scenarios_have_no_team_and_see_themselves_as_the_view():
    sim = Simulator("room_furniture")
    sim.reset(seed=0)
    assert sim.team is None and sim.robot_count == 1 and sim.robot_view(0) is sim
    events = sim.step(np.zeros(2))
    assert sim.robot_events == [events]


# ----------------------------------------------------------------------------- PettingZoo env

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", message="The old environment creation API", category=DeprecationWarning)
    from pettingzoo.test import parallel_api_test

LANES = hall(
    robots=[
        {"name": "east", "start": {"type": "points", "points": [[-1, 2]]}, "goal": {"type": "points", "points": [[0.5, 2]]},
         "start_heading": "toward_goal"},
        {"name": "west", "start": {"type": "points", "points": [[3, -2]]}, "goal": {"type": "points", "points": [[-3, -2]]},
         "start_heading": "toward_goal", "modalities": ["goal", "humans", "velocity"]},
    ],
    humans={"count": 0},
)
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


def test_bad_other_robot_actions_and_indices_are_one_line_errors():
    sim = Simulator(HEAD_ON)
    sim.reset(seed=0)
    before = sim.robot_positions
    with pytest.raises(ValueError, match=r"other_robot_actions must be 1 finite rows of 2 values .* got shape \(2, 2\)"):
        sim.step(np.zeros(2), other_robot_actions=np.zeros((2, 2)))
    with pytest.raises(ValueError, match="other_robot_actions must be"):
        sim.step(np.ones(2), other_robot_actions=np.array([[np.nan, 0.0]]))
    assert np.array_equal(sim.robot_positions, before) and sim.step_count == 0  # nothing moved
    with pytest.raises(ValueError, match=r"robot indices must be in \[0, 1\], got \[2\]"):
        sim.retire_robots([2])
    with pytest.raises(ValueError, match="retire_robots needs a scenario with robots:"):
        Simulator("open_space").retire_robots([0])


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
    from crowdnav.policies import StraightToGoal

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


def test_a_robot_view_offers_the_pair_tables_a_custom_modality_reads():
    sim = Simulator(HALL)
    sim.reset(seed=1)
    view = sim.robot_view(1)
    assert view.n_humans == sim.n_humans + 1 and view.pair_offset.shape == (view.n_humans + 1,) * 2
    np.testing.assert_allclose(view.pair_offset[0, 1:], view.human_positions - view.robot_position)
    assert view.pair_distance[0, -1] == abs(sim.robot_positions[0] - sim.robot_positions[1])  # the other robot, last
    people = sim.robot_view(1, with_robots=False)
    assert people.n_humans == sim.n_humans
