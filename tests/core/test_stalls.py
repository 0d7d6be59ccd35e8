"""Stalled humans (``humans.stall``): a crowd that froze for good walks again, and what counts as a stall."""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav import Simulator
from crowdnav.envs import CrowdNavEnv
from crowdnav.scenario.errors import ScenarioError
from crowdnav.scenario.library import library_names

FROZEN_SQUARE = {"humans.count": 10, "humans.preferred_speed": [0.8, 1.2], "max_steps": 100_000}
"""open_space with 10 humans walking between random goals at the schema's default speeds: seed 0 froze for good
(every human stuck 0.5-0.8 m from its goal, outside the 0.3 m tolerance) before step 2,500 without the stall rule."""


def _speeds(sim: Simulator, steps: int) -> np.ndarray:
    out = np.empty((steps, sim.n_humans))
    for t in range(steps):
        sim.step(np.zeros(2))
        out[t] = np.abs(sim.human_velocities)
    return out


def test_open_square_crowd_that_freezes_without_the_stall_rule_keeps_walking_with_it():
    frozen = Simulator("open_space", {**FROZEN_SQUARE, "humans.stall.time": None})
    frozen.reset(seed=0)
    before = _speeds(frozen, 3000)
    assert np.median(before[-500:]) < 0.1 and frozen.human_stalls.sum() == 0  # the failure: the crowd stands still
    walking = Simulator("open_space", FROZEN_SQUARE)  # the default rule: a 60 s window
    walking.reset(seed=0)
    after = _speeds(walking, 3000)
    preferred = np.median(walking.human_preferred_speed)
    assert walking.human_stalls.sum() > 0
    assert np.median(after[-500:]) > 0.7 * preferred and np.median(after) > 0.7 * preferred


def _standing_still(overrides: dict[str, object], steps: int) -> Simulator:
    """One human held still by zero actions (it cannot progress) in open space for ``steps`` steps."""
    sim = Simulator("open_space", {"humans.count": 1, "humans.stall.time": 2.0, **overrides})
    sim.reset(seed=4)
    for _ in range(steps):
        sim.step(np.zeros(2), human_actions=np.zeros((1, 2)))
    return sim


def test_a_human_without_progress_for_a_window_takes_a_new_goal_and_starts_a_new_window():
    sim = Simulator("open_space", {"humans.count": 1, "humans.stall.time": 2.0})
    sim.reset(seed=4)
    goal = sim.human_goals.copy()
    for _ in range(9):  # checks every 10 steps (2 s at dt 0.2): the first at step 10
        sim.step(np.zeros(2), human_actions=np.zeros((1, 2)))
    assert sim.human_goals == goal and sim.human_stalls.sum() == 0
    sim.step(np.zeros(2), human_actions=np.zeros((1, 2)))
    assert sim.human_goals != goal and sim.human_stalls.tolist() == [1]
    assert sim.human_stall_mark.tolist() == [np.inf]  # the new goal's window starts at the next check
    for _ in range(10):  # the next check opens the window; it cannot judge a goal younger than a window
        sim.step(np.zeros(2), human_actions=np.zeros((1, 2)))
    assert sim.human_stalls.tolist() == [1] and np.isfinite(sim.human_stall_mark).all()
    for _ in range(10):
        sim.step(np.zeros(2), human_actions=np.zeros((1, 2)))
    assert sim.human_stalls.tolist() == [2]


def test_a_stalled_human_of_a_mirror_group_turns_back_and_one_of_a_stop_group_takes_a_new_goal():
    mirror = Simulator("open_space", {"humans.count": 1, "humans.stall.time": 2.0, "humans.goal_rule": "mirror"})
    mirror.reset(seed=4)
    goal = complex(mirror.human_goals[0])
    for _ in range(10):
        mirror.step(np.zeros(2), human_actions=np.zeros((1, 2)))
    assert complex(mirror.human_goals[0]) == -goal  # mirrored through the world's centre, (0, 0)
    stop = _standing_still({"humans.on_goal": "stop"}, 10)
    assert stop.human_stalls.tolist() == [1] and not stop.human_stopped.any()


def test_progress_of_the_set_distance_per_window_is_no_stall():
    sim = Simulator("open_space", {"humans.count": 1, "humans.stall.time": 2.0, "humans.stall.progress": 0.05})
    sim.reset(seed=4)
    goal = sim.human_goals.copy()
    for _ in range(30):  # toward its goal at 0.05 m/s: 0.1 m per 2 s window
        to_goal = sim.human_goals[0] - sim.human_positions[0]
        velocity = to_goal / abs(to_goal) * 0.05 / sim.human_max_speed[0]
        sim.step(np.zeros(2), human_actions=np.array([[velocity.real, velocity.imag]]))
    assert sim.human_stalls.sum() == 0 and sim.human_goals == goal


def test_standing_and_stopped_humans_never_stall():
    sim = Simulator("station_hall", {"humans.stall.time": 1.0})
    sim.reset(seed=2)
    standing = sim.human_stopped.copy()
    assert standing.any()
    sim.stop_humans(np.flatnonzero(~standing)[:2])  # as a multi-agent env lets humans leave
    for _ in range(60):
        sim.step(np.zeros(2))
    assert sim.human_stalls[standing].sum() == 0 and sim.human_stalls[np.flatnonzero(~standing)[:2]].sum() == 0


def test_stall_window_null_turns_the_rule_off_and_bad_values_are_one_line_errors():
    off = _standing_still({"humans.stall.time": None}, 40)
    assert off.stall_window == 0 and off.human_stalls.sum() == 0
    for field, value in (("humans.stall.time", 0), ("humans.stall.progress", -1), ("humans.stall.window", 3)):
        with pytest.raises(ScenarioError, match=field.replace(".", r"\.")) as error:
            Simulator("open_space", {field: value})
        assert "\n" not in str(error.value).strip()


@pytest.mark.parametrize("name", library_names())
def test_the_default_window_leaves_every_library_episode_as_it_was(name):
    """Episodes end within 40 s: the default 60 s window never checks inside one, so trajectories equal the rule off."""
    runs = []
    for overrides in ({}, {"humans.stall.time": None}):
        sim = Simulator(name, overrides)
        trajectory = []
        for seed in (0, 1):
            sim.reset(seed=seed)
            others = None if sim.team is None else np.zeros((sim.team.count - 1, 2))
            for _ in range(sim.scenario.max_steps):
                sim.step(np.array([0.3, 0.1]), other_robot_actions=others)
                trajectory.append(np.concatenate([sim.positions, sim.human_goals]))
            assert sim.human_stalls.sum() == 0
        runs.append(np.concatenate(trajectory))
    assert runs[0].tobytes() == runs[1].tobytes()


def test_env_info_counts_the_episode_s_stalls_every_step():
    env = CrowdNavEnv("open_space", modalities=["goal"], overrides={"humans.stall.time": 1.0, "humans.count": 8})
    env.reset(seed=3)
    stalls = []
    for _ in range(40):
        _, _, terminated, truncated, info = env.step(np.zeros(2))
        stalls.append(info["human_stalls"])
        if terminated or truncated:
            break
    assert stalls == sorted(stalls) and stalls[-1] == int(env.simulator.human_stalls.sum())
