"""SocialForcePolicy reproduces the simulator's built-in crowd, and humans can be replaced."""

from __future__ import annotations

import numpy as np
import pytest

import crowdnav.envs  # noqa: F401  (registers the environments until crowdnav/__init__ imports them)
from crowdnav.envs import SocialForcePolicy, parallel_env

FAST = {"modalities": ["goal"]}

CASES = {
    "room_furniture": ("room_furniture", {}),  # polygons and a round table
    "room_furniture_see_robot": ("room_furniture", {"humans.see_robot": True}),
    "corridor_see_robot": ("corridor", {"humans.see_robot": True}),  # respawn and mirror goals
    "crowd_range": ("cafe", {"humans.count": [1, 6]}),
    # members with max speed 0: action 0, never 0 / 0; the friends walk alone here: the policy reads no group mates, so it
    # has no group terms (docs/simulator.md#walking-groups)
    "standing_groups": ("station_hall", {"humans.groups.4.walk_together": False}),
}


def builtin_actions(env) -> np.ndarray:
    """The simulator's commands / max speed; 0 for standing members (max speed 0), whom the simulator holds still."""
    sim = env.simulator
    command = np.divide(sim.social_force_commands(), sim.human_max_speed, out=np.zeros(sim.n_humans, complex), where=sim.human_max_speed > 0)
    return np.stack([command.real, command.imag], axis=-1)


@pytest.mark.parametrize("case", CASES)
def test_policy_actions_equal_the_simulators_social_force_commands(case):
    scenario, overrides = CASES[case]
    env = parallel_env(scenario, **FAST, overrides=overrides)
    policy = SocialForcePolicy(env.scenario)
    robot_rng = np.random.default_rng(1)
    compared = 0
    for seed in (0, 1):
        observations, _ = env.reset(seed=seed)
        for _ in range(40):
            actions = policy(observations)
            humans = env.agents[1:]
            assert list(actions) == humans
            if humans:
                got = np.stack([actions[name] for name in humans])
                assert got.dtype == np.float32
                np.testing.assert_allclose(got, builtin_actions(env), rtol=0, atol=2e-6)
                compared += len(humans)
            actions["robot"] = robot_rng.uniform(-1, 1, 2).astype(np.float32)
            observations, _, terminations, truncations, _ = env.step(actions)
            if not env.agents:
                break
    assert compared > 100


def test_see_robot_changes_the_policy_near_the_robot():
    """With see_robot the policy must add the robot's repulsion, so the two settings differ."""
    env = parallel_env("room_furniture", **FAST, overrides={"humans.see_robot": True})
    policy = SocialForcePolicy(env.scenario)
    observations, _ = env.reset(seed=5)
    sim = env.simulator
    closest = int(np.argmin(np.abs(sim.human_positions - sim.robot_position)))
    name = f"human_{closest}"
    blind = {k: v for k, v in observations[name].items() if not k.startswith("robot_")}
    seeing = policy({name: observations[name]})[name]
    not_seeing = policy({name: blind})[name]
    assert not np.allclose(seeing, not_seeing, atol=1e-6)
    np.testing.assert_allclose(seeing, builtin_actions(env)[closest], atol=2e-6)


def test_some_humans_can_be_replaced_by_another_policy():
    env = parallel_env("room_furniture", **FAST)
    crowd = SocialForcePolicy(env.scenario)
    observations, _ = env.reset(seed=3)
    sim = env.simulator
    for _ in range(10):
        expected = builtin_actions(env)
        actions = crowd(observations)
        actions["human_0"] = np.zeros(2, dtype=np.float32)  # a scripted human that stands still
        actions["robot"] = np.zeros(2, dtype=np.float32)
        observations, *_ = env.step(actions)
        assert sim.velocities[1] == 0
        commanded = sim.velocities[2:] / sim.human_max_speed[1:]
        np.testing.assert_allclose(np.stack([commanded.real, commanded.imag], -1), expected[1:], atol=2e-6)


def test_policy_ignores_the_robot_and_handles_no_humans():
    env = parallel_env("room_furniture", **FAST, overrides={"humans.count": 0})
    observations, _ = env.reset(seed=0)
    assert SocialForcePolicy(env.scenario)(observations) == {}
