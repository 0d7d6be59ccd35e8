"""Several robots stacked (crowdnav.batch.team, crowdnav.batch.robot_policies): each world's other robots move, push the
humans, end and leave, and their scripted policies act, as a single simulator's and the single env's, bit for bit.

The vector env's episodes of a ``robots:`` scenario are compared with the single env's in
tests/core/test_vector_env_robots.py and across engines in tests/core/test_engine_snapshot.py; these check the parts.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from crowdnav.batch.robot_policies import _ATAN2, social_force_robots, straight_robots
from crowdnav.batch.scalar_math import cdiv_real
from crowdnav.batch.simulator import BatchSimulator
from crowdnav.planning.scripted import SocialForceRobot, StraightToGoal
from crowdnav.sim.simulator import Simulator
from tests.core.paired_worlds import WORLDS, paired_worlds


def _worlds(overrides: dict[str, object] | None = None) -> tuple[BatchSimulator, list[Simulator]]:
    return paired_worlds(overrides, first_seed=30)


def _ego(batch: BatchSimulator) -> np.ndarray:
    return np.array([bucket.state.positions[row, 0] for bucket, row in map(batch.locate, range(batch.num_worlds))])


@pytest.mark.parametrize("crowd", [10, [3, 8], 0], ids=["as_shipped", "crowd_sizes_3_to_8", "no_humans"])
def test_the_batched_simulator_moves_pushes_and_ends_other_robots_as_single_simulators_bit_for_bit(crowd):
    """Several crowd sizes: the worlds in several buckets (the team is indexed by world, its geometry kept per size)."""
    batch, singles = _worlds({"max_steps": 60, "humans.count": crowd})
    team = batch.team
    assert team is not None
    rng = np.random.default_rng(2)
    contacts = retired = ends = 0
    for _ in range(240):  # every robot ahead, noisy (they start facing their goals, across each other's paths: contacts)
        actions, others = rng.normal([0.9, 0.0], 0.4, (WORLDS, 2)), rng.normal([0.9, 0.0], 0.4, (WORLDS, 2, 2))
        result = batch.step(actions, None, others)
        leaving = np.zeros((WORLDS, 2), dtype=bool)
        for i, sim in enumerate(singles):
            events = sim.step(actions[i], None, others[i])
            bucket, row = batch.locate(i)
            assert bucket.state.positions[row].tobytes() == sim.positions.tobytes()
            assert bucket.state.velocities[row].tobytes() == sim.velocities.tobytes()
            assert bucket.repulsion[row].tobytes() == sim.geometry.repulsion.tobytes()  # the other robots' push included
            state = sim.team.state
            for name in ("positions", "velocities", "headings", "active", "left_at"):
                assert getattr(team, name)[i].tobytes() == getattr(state, name).tobytes(), name
            assert team.social[i].tobytes() == sim.team.social.tobytes()
            assert result.collisions.get(i) == events.collision and result.goal_reached[i] == events.goal_reached
            contacts += events.collision is not None and events.collision.kind == "robot"
            ended = [e is not None and e.terminated for e in sim.robot_events[1:]]
            assert team.ended[i].tolist() == ended
            assert team.outcome[i].tolist() == [e.outcome if end else None for e, end in zip(sim.robot_events[1:], ended, strict=True)]
            if events.terminated or events.truncated:
                ends += 1
                batch.reset([i], [None])
                sim.reset()
            elif any(ended):  # as the env: the robots that ended leave the world
                leaving[i] = ended
                sim.retire_robots([j + 1 for j in np.flatnonzero(ended)])
        if leaving.any():
            retired += int(leaving.sum())
            batch.retire(leaving)
            for i, sim in enumerate(singles):
                bucket, row = batch.locate(i)
                assert bucket.repulsion[row].tobytes() == sim.geometry.repulsion.tobytes()
    assert contacts > 0 and retired > 0 and ends > WORLDS  # robot-robot contacts, robots leaving, episodes restarting


@pytest.mark.parametrize(("batched", "scripted"), [(social_force_robots, SocialForceRobot), (straight_robots, StraightToGoal)])
def test_the_batched_robot_policies_act_as_the_scripted_policy_on_each_robots_view(batched, scripted):
    batch, singles = _worlds()
    policy = scripted()
    rng, mixed = np.random.default_rng(3), 0
    for step in range(120):
        acted = batched(batch.team, np.arange(WORLDS), _ego(batch))
        for i, sim in enumerate(singles):
            active = sim.robots_active
            expected = [np.asarray(policy(sim.robot_view(k)), dtype=float) if active[k] else np.zeros(2) for k in (1, 2)]
            assert acted[i].tobytes() == np.array(expected).tobytes()
        if step in (20, 45):  # robots leave, differently per world: the robots a view sees differ between worlds
            leaving = np.zeros((WORLDS, 2), dtype=bool)
            leaving[step % 3 :: 3, 0] = leaving[1::4, 1] = True
            batch.retire(leaving)
            for i, sim in enumerate(singles):
                sim.retire_robots([j + 1 for j in np.flatnonzero(leaving[i])])
        mixed += len({row.tobytes() for row in batch.team.active}) > 1
        actions = rng.uniform(-1, 1, (WORLDS, 2))
        batch.step(actions, None, acted)
        for i, sim in enumerate(singles):
            sim.step(actions[i], None, acted[i])
    assert mixed > 50


def test_the_robot_policies_scalar_division_and_phase_equal_pythons():
    rng = np.random.default_rng(5)
    re, im = rng.normal(0, 3, 2000), rng.normal(0, 3, 2000)
    re[:10], im[10:20] = 0.0, -0.0
    divisor = rng.uniform(0.1, 5, 2000)
    quotient = cdiv_real(re, im, divisor)
    expected = [complex(a, b) / d for a, b, d in zip(re.tolist(), im.tolist(), divisor.tolist(), strict=True)]
    assert quotient[0].tolist() == [z.real for z in expected] and quotient[1].tolist() == [z.imag for z in expected]
    phase = [math.atan2(b, a) for a, b in zip(re.tolist(), im.tolist(), strict=True)]
    assert _ATAN2(im, re).astype(float).tolist() == phase  # (numpy's own arctan2 differed in the last bit here: not used)
