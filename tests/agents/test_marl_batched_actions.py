"""The shared network's actions turned into every robot's env action for many worlds at once (RobotActions.batch): each
row the bits the per-robot adapter (RobotActions.__call__, what a world's robots-only env applies) gives it."""

from __future__ import annotations

import numpy as np
import pytest
from crowdnav.agents.marl.actions import RobotActions
from crowdnav.agents.marl.env import robots_env

HALL = "robots_crossing_hall"  # two holonomic robots and a unicycle


@pytest.mark.parametrize("mode", ["native", "velocity", "goal_velocity"])
@pytest.mark.parametrize("frame", ["polar", "cartesian"])
def test_batched_actions_equal_each_robots_own_adapter_bit_for_bit(mode, frame):
    env = robots_env({"scenario": HALL, "modalities": ["lidar", "goal"], "sensors": {"lidar": {"beams": 8}, "goal": {"frame": frame}}})
    commands = RobotActions.for_env(mode, env)
    rng = np.random.default_rng(7)
    worlds, robots, size = 400, len(env.possible_agents), env.observation_space(env.possible_agents[0]).shape[0]
    actions = rng.normal(0.0, 1.2, (worlds, robots, 2)).astype(np.float32)  # norms over 1, negative speeds, backward commands
    actions[:20] = 0.0  # no command: no bearing
    actions[20:25, :, 0] = -0.0
    actions[25:30, 1] = np.nan  # passes as it is (the env refuses it in its own words)
    observations = rng.normal(0.0, 3.0, (worlds, robots, size)).astype(np.float32)
    observations[30:40] = 0.0  # at the goal: straight ahead
    batched = commands.batch(actions, observations)
    assert batched.dtype == np.float32 and batched.shape == actions.shape
    for w in range(worlds):
        names = env.possible_agents
        one = commands({name: actions[w, k] for k, name in enumerate(names)}, names,
                       {name: observations[w, k] for k, name in enumerate(names)})
        expected = np.stack([np.asarray(one[name], np.float32) for name in names])
        assert batched[w].tobytes() == expected.tobytes(), w
    env.close()
