"""Gymnasium and PettingZoo conventions: max_episode_steps keeps the outcome, the AEC entry point passes api_test."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

import crowdnav
from crowdnav.planning.scripted import StraightToGoal


def test_time_limit_truncation_carries_outcome_and_is_success():
    env = gym.make("crowdnav/OpenSpace-v0", max_episode_steps=4, modalities=["goal"])
    env.reset(seed=0)
    for _ in range(4):
        _, _, terminated, truncated, info = env.step(np.zeros(2))
    assert truncated and not terminated  # the wrapper truncated: the scenario's own limit is 150
    assert info["outcome"] == "truncated" and info["is_success"] is False


def test_a_terminating_step_under_time_limit_keeps_its_own_outcome():
    env = gym.make("crowdnav/OpenSpace-v0", max_episode_steps=500, modalities=["goal"])
    env.reset(seed=0)
    policy = StraightToGoal()
    terminated = truncated = False
    while not (terminated or truncated):
        _, _, terminated, truncated, info = env.step(policy(env.unwrapped.simulator))
    assert terminated and info["outcome"] in ("success", "collision", "out_of_bounds")
    assert info["is_success"] is (info["outcome"] == "success")


def test_sb3_success_rate_counts_episodes_a_time_limit_cut():
    from stable_baselines3 import PPO

    env = gym.make("crowdnav/OpenSpace-v0", max_episode_steps=5, modalities=["goal"])
    model = PPO("MultiInputPolicy", env, n_steps=16, batch_size=16, n_epochs=1, policy_kwargs={"net_arch": [8]}, seed=0)
    model.learn(16)
    # 16 steps of 5-step episodes (none reaches the goal standing this close to the start): 3 ended
    assert len(model.ep_success_buffer) == len(model.ep_info_buffer) == 3
    assert list(model.ep_success_buffer) == [False] * 3


def test_make_vec_max_episode_steps_truncates_in_the_vector_env_with_its_outcome():
    envs = gym.make_vec("crowdnav/OpenSpace-v0", num_envs=2, vectorization_mode="vector_entry_point", max_episode_steps=3,
                        modalities=["goal"], autoreset_mode="Disabled")
    single = gym.make("crowdnav/OpenSpace-v0", max_episode_steps=3, modalities=["goal"])
    observations, _ = envs.reset(seed=[7, 8])
    first, _ = single.reset(seed=7)
    np.testing.assert_array_equal(observations["goal"][0], first["goal"])
    for _ in range(3):
        observations, _, terminated, truncated, infos = envs.step(np.zeros((2, 2)))
        one, *_ = single.step(np.zeros(2))
    np.testing.assert_array_equal(observations["goal"][0], one["goal"])  # the same episode as the single env's
    assert truncated.all() and not terminated.any()
    assert list(infos["outcome"]) == ["truncated"] * 2 and not infos["is_success"].any()
    longer = gym.make_vec("crowdnav/OpenSpace-v0", num_envs=1, vectorization_mode="vector_entry_point", max_episode_steps=10**6)
    assert longer.unwrapped.scenario.max_steps == 150  # a cap above the scenario's limit changes nothing, as TimeLimit


@pytest.mark.parametrize("steps", [0, -3, 2.5, True])
def test_make_vec_rejects_a_max_episode_steps_that_is_not_a_positive_integer(steps):
    with pytest.raises(ValueError, match="max_episode_steps must be a positive integer"):
        gym.make_vec("crowdnav/OpenSpace-v0", num_envs=1, vectorization_mode="vector_entry_point", max_episode_steps=steps)


@pytest.mark.parametrize(("scenario", "options"), [("open_space", {"modalities": ["goal"]}),
                                                   ("station_hall", {"modalities": ["goal"], "flat_observations": True,
                                                                     "fixed_agents": True})])
def test_aec_env_passes_pettingzoo_api_test(scenario, options):
    from pettingzoo.test import api_test

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Dict observations draw style recommendations, not failures
        api_test(crowdnav.env(scenario, **options), num_cycles=30)


def test_aec_env_steps_the_same_world_as_the_parallel_env():
    aec = crowdnav.env("open_space", modalities=["goal"])
    parallel = crowdnav.parallel_env("open_space", modalities=["goal"])
    aec.reset(seed=3)
    parallel.reset(seed=3)
    actions = {agent: np.array([0.5, 0.2], dtype=np.float32) for agent in parallel.agents}
    for _ in range(3):
        for agent in list(aec.agents):  # one cycle: every agent acts once, then the world steps
            assert aec.agent_selection == agent
            aec.step(actions[agent])
        observations, *_ = parallel.step(actions)
    np.testing.assert_array_equal(aec.observe("robot")["goal"], observations["robot"]["goal"])
    assert aec.agents[0] == "robot" and aec.possible_agents == parallel.possible_agents
