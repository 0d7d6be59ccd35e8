"""Every robot driven by the caller (crowdnav.envs.engines.robots): the stacked engine plays each world's robots as the
robots-only PettingZoo env does (one per world: SingleRobots), bit for bit: observations, rewards and terms, outcomes
with their named contacts, the first robot leaving (parked) while the others go on, the time limit, partial steps, and
the frames evaluation records (where everyone is, the humans' force on each robot)."""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav.envs.engines.protocol import RobotsStep
from crowdnav.envs.engines.robots import SingleRobots, robots_engine, robots_world, stacks_robots
from crowdnav.envs.engines.stacked_robots import StackedRobots

HALL = "robots_crossing_hall"
WORLDS = 5


def _same(stacked: RobotsStep, single: RobotsStep) -> None:
    for name in ("stepped", "rewards", "truncated", "over"):
        assert getattr(stacked, name).tobytes() == getattr(single, name).tobytes(), name
    assert stacked.outcome.tolist() == single.outcome.tolist()
    assert stacked.collisions == single.collisions  # kind, partner and depth
    for term, values in single.terms.items():
        assert np.where(stacked.stepped, stacked.terms[term], 0.0).tobytes() == values.tobytes(), term


def _same_frame(stacked: StackedRobots, single: SingleRobots, running: np.ndarray) -> None:
    """Both engines' frames (what evaluation records) the same bits: every human, goal and stall count; the position of
    and force on every ``running`` robot (one that just ended leaves the stack's world only when the next step starts)."""
    a, b = stacked.frame(), single.frame()
    for name in ("goals", "humans", "crowd", "stalls"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name
    for name in ("robots", "social_force"):
        assert getattr(a, name)[running].tobytes() == getattr(b, name)[running].tobytes(), name
    for world in range(stacked.num_worlds):
        assert all(x.tobytes() == y.tobytes() for x, y in zip(stacked.radii(world), single.radii(world), strict=True))


OPEN = {"max_steps": 80, "world.boundary_walls": False}
"""No walls around the hall: a robot may leave the world (out_of_bounds), and a parked first robot is outside it."""


@pytest.mark.parametrize("overrides", [OPEN,  # the default suite's case (the others: 10-17 s each, marked slow)
                                       pytest.param({"max_steps": 60, "humans.count": [0, 7]}, marks=pytest.mark.slow),
                                       pytest.param({**OPEN, "humans.count": 0, "world.min": [-6.8, -5], "world.max": [6.8, 5]},
                                                    marks=pytest.mark.slow)],
                         ids=["open_hall", "crowd_sizes_0_to_7", "no_humans_narrow_open_hall"])
def test_stacked_robots_play_each_world_as_the_robots_only_env_bit_for_bit(overrides):
    modalities = ["goal", "lidar", "velocity", "obstacles", "humans"]  # the last two see no robots: a view of the humans alone
    options = {"scenario": HALL, "overrides": overrides, "sensors": {"lidar": {"beams": 24}}, "modalities": modalities}
    stacked, single = robots_engine(options, WORLDS), SingleRobots(options, WORLDS)
    assert isinstance(stacked, StackedRobots)
    seeds = [40 + i for i in range(WORLDS)]
    stacked.reset(range(WORLDS), seeds)
    single.reset(range(WORLDS), seeds)
    rng = np.random.default_rng(4)
    first_left = 0
    kinds: set[str] = set()
    ends: set[str] = set()
    for t in range(300):
        assert stacked.observe().tobytes() == single.observe().tobytes()
        actions = rng.normal([0.9, 0.0], 0.5, (WORLDS, 3, 2))
        actions[:, 0] = rng.normal([1.0, 0.0], 0.1, (WORLDS, 2))  # the first robot ahead: it often ends first
        actions[rng.random((WORLDS, 3)) < 0.05] = np.nan  # a robot that left ignores its action unchecked: NaN only there
        actions[stacked.team.active] = np.nan_to_num(actions[stacked.team.active])
        active = None if t % 3 else rng.random(WORLDS) < 0.6  # some steps step some worlds only
        step = stacked.step(actions, active)
        _same(step, single.step(actions, active))
        _same_frame(stacked, single, step.stepped & (step.outcome == None))  # noqa: E711  (entry by entry)
        first_left += int((~step.stepped[:, 0] & step.stepped[:, 1:].any(1)).sum())
        ends |= set(step.outcome.ravel().tolist())
        kinds |= {contact.kind for contact in step.collisions.values()}
        over = np.flatnonzero(step.over)
        stacked.reset(over, [None] * len(over))
        single.reset(over, [None] * len(over))
    assert first_left > 0 and "robot" in kinds and {"collision", "truncated"} <= ends
    assert {"success", "out_of_bounds"} <= ends or overrides.get("world.boundary_walls") is not False


def test_a_non_finite_action_of_a_robot_in_the_world_is_refused_naming_it_before_anything_moves():
    engine = robots_engine({"scenario": HALL}, 2)
    engine.reset([0, 1], [0, 1])
    before = engine.observe()
    actions = np.zeros((2, 3, 2))
    actions[1, 2, 0] = np.inf
    with pytest.raises(ValueError, match="north_bound in world 1"):
        engine.step(actions)
    assert engine.observe().tobytes() == before.tobytes()


def test_what_does_not_stack_is_played_by_one_env_per_world():
    orca = {"scenario": HALL, "overrides": {"humans.model": "orca"}}
    assert not stacks_robots(robots_world(orca), orca)
    assert not stacks_robots(robots_world({"scenario": HALL}), {"scenario": HALL, "shield": True})
    assert isinstance(robots_engine(orca, 2), SingleRobots)
