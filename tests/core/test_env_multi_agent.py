"""Multi-agent plumbing: global state, flat observations (SuperSuit), human rewards and exits."""

from __future__ import annotations

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from crowdnav.envs import SocialForcePolicy, parallel_env
from crowdnav.envs.multi_agent import STATE_COLUMNS, exit_at_goal, goal_reward


def _still(env) -> dict:
    return {agent: np.zeros(2, dtype=np.float32) for agent in env.agents}


def test_state_is_a_table_of_robot_and_human_rows_matching_the_simulator():
    env = parallel_env("room_furniture")
    env.reset(seed=3)
    env.step(_still(env))
    state = env.state()
    assert env.state_space.contains(state)
    table = state.reshape(1 + env.scenario.humans.max_count, len(STATE_COLUMNS))
    sim = env.simulator
    n = sim.n_humans
    np.testing.assert_allclose(table[: 1 + n, 0] + 1j * table[: 1 + n, 1], sim.positions, atol=1e-5)
    np.testing.assert_allclose(table[1 : 1 + n, 4] + 1j * table[1 : 1 + n, 5], sim.human_goals, atol=1e-5)
    assert table[0, 4] + 1j * table[0, 5] == pytest.approx(sim.robot_goal, abs=1e-5)
    assert (table[: 1 + n, 7] == 1).all() and not table[1 + n :].any()


def test_flat_observations_pass_the_parallel_api_test_and_hold_the_dict_values():
    parallel_api_test(parallel_env("room_furniture", flat_observations=True), num_cycles=30)
    flat, nested = parallel_env("room_furniture", flat_observations=True), parallel_env("room_furniture")
    flat_obs, _ = flat.reset(seed=1)
    dict_obs, _ = nested.reset(seed=1)
    from gymnasium import spaces

    for agent in flat.agents:
        assert flat.observation_space(agent).contains(flat_obs[agent])
        np.testing.assert_array_equal(flat_obs[agent], spaces.flatten(nested.observation_space(agent), dict_obs[agent]))


def test_supersuit_pads_flattens_and_vectorises_the_flat_env():
    ss = pytest.importorskip("supersuit")
    env = parallel_env("open_space", flat_observations=True)
    env = ss.pad_observations_v0(ss.pad_action_space_v0(env))
    env = ss.flatten_v0(env)
    vec = ss.pettingzoo_env_to_vec_env_v1(env)
    observations, _ = vec.reset(seed=0)
    assert observations.shape[0] == vec.num_envs == len(env.possible_agents)
    observations, rewards, terminations, truncations, infos = vec.step(np.zeros((vec.num_envs, 2), dtype=np.float32))
    assert observations.shape[0] == rewards.shape[0] == vec.num_envs and np.isfinite(observations).all()


def _walk(env, steps: int):
    """Humans by the social-force policy, the robot still; resets when the episode ends; yields step results."""
    policy = SocialForcePolicy(env.scenario)
    observations, _ = env.reset(seed=0)
    for step in range(steps):
        if not env.agents:
            observations, _ = env.reset(seed=step)
        before = list(env.agents)
        # a human that left is in the last observations (PettingZoo's rule), not in agents
        humans = {agent: action for agent, action in policy(observations).items() if agent in env.agents}
        actions = {"robot": np.zeros(2, dtype=np.float32), **humans}
        observations, *result = env.step(actions)
        yield before, result


def test_goal_reward_pays_humans_on_arrival_and_infos_say_so():
    env = parallel_env("open_space", human_reward=goal_reward, overrides={"max_steps": 400})
    paid = arrivals = 0
    for _, (rewards, _, _, infos) in _walk(env, 600):
        for agent in rewards:
            if agent.startswith("human_"):
                assert rewards[agent] == float(infos[agent]["goal_reached"])
                paid += rewards[agent]
                arrivals += infos[agent]["goal_reached"]
    assert paid == arrivals > 0


def test_humans_that_exit_leave_agents_alone_and_stand_still():
    env = parallel_env("open_space", human_exit=exit_at_goal, overrides={"max_steps": 400})
    exits = 0
    for before, (_, terminations, _, _) in _walk(env, 600):
        if not env.agents:  # the episode ended for everyone
            continue
        gone = [agent for agent in before if agent not in env.agents]
        assert env.agents[0] == "robot" and all(terminations[agent] for agent in gone)
        exits += len(gone)
        stopped = np.flatnonzero(env.simulator.human_stopped)
        assert (env.simulator.velocities[1 + stopped] == 0).all()
        assert {f"human_{i}" for i in stopped}.isdisjoint(env.agents)
    assert exits > 0, "no human reached its goal"
