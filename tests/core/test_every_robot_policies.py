"""The scripted robot policies for every robot of a stack (crowdnav.batch.robot_policies.every_robot_actions): each robot's
action, the first robot's included, equals the single policy called with that robot's view of a single simulator
(``policy(sim.robot_view(k))``) bit for bit, over many states: worlds of several crowd sizes, robots leaving (the first
one too) differently per world, a holonomic and a unicycle first robot.

The rollouts that play these actions are compared with one env per seed in tests/evaluation/test_robot_rollout_engine.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav.batch.robot_policies import every_robot_actions
from crowdnav.batch.simulator import BatchSimulator
from crowdnav.planning.scripted import SocialForceRobot, StraightToGoal
from crowdnav.sim.simulator import Simulator
from tests.core.paired_worlds import WORLDS, paired_worlds
from tests.core.robot_placement_shapes import EAST_DOOR, WEST_DOOR

UNICYCLE = {"robots.0.kinematics": "unicycle", "robots.0.max_angular_speed": 2.0}


def _worlds(overrides: dict[str, object] | None) -> tuple[BatchSimulator, list[Simulator]]:
    return paired_worlds(overrides, first_seed=50)


def _expected(policy, sim: Simulator) -> np.ndarray:
    """Each robot's action as the single policy gives it on the robot's view (0 for a robot that left)."""
    return np.array([np.asarray(policy(sim.robot_view(k)), dtype=float) if here else np.zeros(2)
                     for k, here in enumerate(sim.robots_active)])


@pytest.mark.parametrize("overrides", [{"humans.count": [3, 8]}, {"humans.count": [0, 4], **UNICYCLE}],
                         ids=["crowd_sizes_3_to_8", "unicycle_first_robot_crowd_sizes_0_to_4"])
@pytest.mark.parametrize(("name", "scripted"), [("social-force", SocialForceRobot), ("straight", StraightToGoal)])
def test_every_robot_acts_as_the_scripted_policy_on_its_view_the_first_robot_included(name, scripted, overrides):
    batch, singles = _worlds(overrides)
    team = batch.team
    assert team is not None
    policy, rng = scripted(), np.random.default_rng(4)
    odd = np.arange(1, WORLDS, 2)
    first_gone = mixed = 0
    for step in range(150):
        acted = every_robot_actions(name, batch, np.arange(WORLDS))
        for i, sim in enumerate(singles):
            assert acted[i].tobytes() == _expected(policy, sim).tobytes(), (step, i)
        assert every_robot_actions(name, batch, odd).tobytes() == acted[odd].tobytes()  # some worlds only: their own rows
        if step in (25, 60, 95):  # robots leave, the first one too, differently per world: views list other robots
            leaving = np.zeros((WORLDS, 3), dtype=bool)
            leaving[step % 4 :: 4, 0] = leaving[1::3, 1 + step % 2] = True
            leaving &= team.active
            batch.retire(leaving[:, 1:], leaving[:, 0])
            for i, sim in enumerate(singles):
                if leaving[i].any():
                    sim.retire_robots(np.flatnonzero(leaving[i]).tolist())
        first_gone += int((~team.active[:, 0] & team.active[:, 1:].any(1)).sum())
        mixed += len({row.tobytes() for row in team.active}) > 1
        actions = np.clip(acted + rng.normal(0.0, 0.3, acted.shape), -1.0, 1.0)  # toward the goals, noisy: robots meet
        batch.step(actions[:, 0], None, actions[:, 1:])
        for i, sim in enumerate(singles):
            sim.step(actions[i, 0], None, actions[i, 1:])
    assert first_gone > 0 and mixed > 50


def test_the_first_robots_social_force_action_feels_a_robot_beside_it():
    """The robot term reaches the first robot (the other-robots-only twin never computed it): two robots in one door."""
    batch, _ = _worlds({"humans.count": 0, "robots.1.start": WEST_DOOR, "robots.1.goal": EAST_DOOR})
    beside = every_robot_actions("social-force", batch, np.arange(WORLDS))[:, 0]
    batch.retire(np.array([[True, True]] * WORLDS))
    alone = every_robot_actions("social-force", batch, np.arange(WORLDS))[:, 0]
    assert (beside != alone).any(axis=1).all()
