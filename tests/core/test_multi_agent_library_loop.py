"""The documented multi-agent loop (docs/environments.md) runs a full episode in every library scenario.

The humans are driven by ``SocialForcePolicy`` from their observations; the robot either heads
straight for its goal (short episodes, mostly collisions) or stands still (episodes mostly run
to the time limit, through arrivals, respawns and new goals). Every human action must be finite
(standing groups have max speed 0) and the episode must end for every agent at once.
"""

from __future__ import annotations

import numpy as np
import pytest

import crowdnav
from crowdnav.planning.scripted import StraightToGoal
from crowdnav.scenario.library import library_names
from crowdnav.sim.events import OUTCOMES

FAST = {"modalities": ["goal"]}
"""The loop is about the humans; the robot's sensors do not matter here."""


def still(sim) -> np.ndarray:
    return np.zeros(2, dtype=np.float32)


ROBOTS = {"straight": StraightToGoal(), "still": still}


def run_documented_loop(env, robot=still, seed: int = 0) -> tuple[int, dict]:
    """The docs' loop for one episode: (steps, each robot's last info); checks every action on the way.

    Every robot (one, ``robot``, or several: docs/environments.md#several-robots) follows ``robot``.
    """
    crowd = crowdnav.SocialForcePolicy(env.scenario)
    observations, infos = env.reset(seed=seed)
    steps, robot_info = 0, {}
    robots = [agent for agent in env.possible_agents if not agent.startswith("human_")]
    while env.agents:
        actions = crowd(observations)
        humans = [agent for agent in env.agents if agent.startswith("human_")]
        assert sorted(actions) == sorted(humans)
        stacked = np.stack([actions[name] for name in humans]) if humans else np.zeros((0, 2))
        assert np.isfinite(stacked).all(), {name: actions[name] for name in humans if not np.isfinite(actions[name]).all()}
        assert (np.abs(stacked) <= 1.0 + 1e-6).all()
        for k, name in enumerate(robots):
            if name in env.agents:
                actions[name] = robot(env.simulator.robot_view(k))
        observations, rewards, terminations, truncations, infos = env.step(actions)
        steps += 1
        robot_info.update((name, infos[name]) for name in robots if name in infos)
        assert steps <= env.scenario.max_steps
    return steps, robot_info


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("name", library_names())
def test_documented_loop_runs_a_full_episode_in_every_library_scenario(name, robot):
    env = crowdnav.parallel_env(name, **FAST)
    steps, infos = run_documented_loop(env, ROBOTS[robot])
    assert not env.agents and steps >= 1
    outcomes = [info["outcome"] for info in infos.values()]
    assert set(outcomes) <= set(OUTCOMES) and len(outcomes) == len(env.scenario.robot_names)
    assert ("truncated" in outcomes) == (steps == env.scenario.max_steps)


@pytest.mark.parametrize("name", ["station_hall", "hotel_lobby"])
def test_standing_group_members_get_zero_actions_and_stay_put(name):
    env = crowdnav.parallel_env(name, **FAST, overrides={"humans.see_robot": True})
    crowd = crowdnav.SocialForcePolicy(env.scenario)
    observations, _ = env.reset(seed=1)
    sim = env.simulator
    standing = np.flatnonzero(sim.human_max_speed == 0)
    assert len(standing) > 0
    start = sim.human_positions[standing].copy()
    for _ in range(20):
        actions = crowd(observations)
        assert all(np.array_equal(actions[f"human_{i}"], [0.0, 0.0]) for i in standing)
        actions["robot"] = np.zeros(2, dtype=np.float32)
        observations, *_ = env.step(actions)
    np.testing.assert_array_equal(sim.human_positions[standing], start)
