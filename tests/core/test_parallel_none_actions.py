"""``None`` as an action in the PettingZoo env (issue 36): refused for an active robot (several robots
or one) and for a human, in one line naming the agent, before anything moves; a robot that left
(``fixed_agents``) still takes any action, None included, and ignores it."""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav.envs import parallel_env
from crowdnav.scenario.loader import load_scenario
from tests.core.multi_robot_scenes import HALL, LANES


def _still(env) -> dict:
    return {agent: np.zeros(2, dtype=np.float32) for agent in env.agents}


@pytest.mark.parametrize("options", [{}, {"humans_as_agents": False}, {"humans_as_agents": False, "fixed_agents": True}])
def test_an_active_robots_none_action_is_a_one_line_error_naming_it_and_nothing_moves(options):
    env = parallel_env(HALL, modalities=["goal"], **options)
    env.reset(seed=0)
    before = env.simulator.robot_positions.copy(), env.simulator.step_count
    actions = {**_still(env), "west": None}
    with pytest.raises(ValueError, match=r"^the action of west is None; an active robot needs 2 numbers in \[-1, 1\] \(to stand still: \[0, 0\]\)$"):
        env.step(actions)
    assert np.array_equal(env.simulator.robot_positions, before[0]) and env.simulator.step_count == before[1]
    env.step(_still(env))  # the episode goes on


def test_a_bad_robot_action_names_the_robot():
    env = parallel_env(HALL, modalities=["goal"], humans_as_agents=False)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"^the action of east: the robot action must be finite \(no NaN or inf\)"):
        env.step({**_still(env), "east": np.array([np.nan, 0.0])})


def test_the_one_robot_parallel_env_refuses_none_for_the_robot_and_for_a_human():
    env = parallel_env("open_space", modalities=["goal"])
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"^the robot action must be 2 numbers \(real, not Python objects\), got None$"):
        env.step({**_still(env), "robot": None})
    human = next(agent for agent in env.agents if agent.startswith("human_"))
    with pytest.raises(ValueError, match=rf"^the action of {human} must be 2 numbers \(real, not Python objects\), got None$"):
        env.step({**_still(env), human: None})


def test_a_robot_that_left_under_fixed_agents_ignores_its_action_none_included():
    assert load_scenario(LANES).robots is not None
    env = parallel_env(LANES, humans_as_agents=False, fixed_agents=True)
    env.reset(seed=0)
    forward = np.array([1.0, 0.0])
    infos = {"east": {"active": True}}
    steps = 0
    while env.agents and infos["east"]["active"]:
        _, _, _, _, infos = env.step({agent: forward for agent in env.agents})
        steps += 1
    assert env.agents and not infos["east"]["active"] and steps < 40  # east reached its goal and left, west still runs
    _, _, _, _, infos = env.step({"east": None, "west": forward})
    assert infos["east"] == {"active": False}
