"""Reward terms: formulas on constructed states, their sum, the event terms and the end-of-episode info."""

from __future__ import annotations

import math

import numpy as np
import pytest

import crowdnav.envs  # noqa: F401  (registers the environments until crowdnav/__init__ imports them)
from crowdnav.envs import REWARD_TERMS, CrowdNavEnv


def constructed(humans: list[tuple[float, float]] = (), goal=(3.0, 0.0), walls=(), max_steps=100, see_robot=False) -> dict:
    """Robot at the origin heading +x; humans standing on their spawn points (goal there, on_goal stop)."""
    points = [list(p) for p in humans]
    crowd = {"count": 0}
    if points:
        crowd = {
            "count": len(points),
            "spawn": [{"type": "points", "points": points}],
            "goal": [{"type": "points", "points": points}],
            "on_goal": "stop",
            "see_robot": see_robot,
        }
    return {
        "name": "constructed",
        "description": "A constructed state for reward tests.",
        "walls": [{"points": list(map(list, wall)), "thickness": 0.1} for wall in walls],
        "robot": {
            "start": {"type": "points", "points": [[0.0, 0.0]]},
            "goal": {"type": "points", "points": [list(goal)]},
            "start_heading": 0.0,
        },
        "humans": crowd,
        "time_step": 0.2,
        "max_steps": max_steps,
    }


def expected_social(robot: complex, humans: np.ndarray, radius_sum: float, strength: float, decay: float) -> float:
    """|sum_j A exp((r_r + r_j - d_j) / B) (p_r - p_j) / d_j|, in real x/y arithmetic."""
    dx, dy = robot.real - humans.real, robot.imag - humans.imag
    d = np.hypot(dx, dy)
    magnitude = strength * np.exp((radius_sum - d) / decay)
    return math.hypot(float((magnitude * dx / d).sum()), float((magnitude * dy / d).sum()))


def test_reward_terms_follow_their_formulas_and_sum_to_the_reward():
    weights = {"step": -2.0, "goal_progress": 7.0, "social": -30.0, "goal_reached": 100.0, "collision": -200.0}
    env = CrowdNavEnv(constructed(humans=[(1.5, 0.9), (2.5, -1.0)]), modalities=["goal"], reward_weights=weights)
    env.reset(seed=3)
    sim, force = env.simulator, env.scenario.humans.social_force
    socials = []
    for _ in range(4):
        before = sim.robot_position
        _, reward, terminated, _, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
        assert not terminated
        terms = info["reward_terms"]
        assert tuple(terms) == REWARD_TERMS
        assert reward == sum(terms.values())
        after, goal = sim.robot_position, sim.robot_goal
        assert terms["step"] == -2.0
        assert terms["goal_progress"] == pytest.approx(7.0 * (abs(goal - before) - abs(goal - after)), abs=1e-12)
        social = expected_social(after, sim.human_positions, 0.6, force.human_strength, force.human_range)
        assert terms["social"] == pytest.approx(-30.0 * social, rel=1e-6)  # the model evaluates exp in float32
        assert terms["goal_reached"] == 0.0 and terms["collision"] == 0.0
        socials.append(terms["social"])
    assert all(s < 0 for s in socials)  # the humans are close enough for the term to matter


def test_default_weights_are_the_papers():
    env = CrowdNavEnv(constructed(), modalities=["goal"])
    env.reset(seed=0)
    _, reward, _, _, info = env.step(np.array([1.0, 0.0]))
    terms = info["reward_terms"]
    assert terms["step"] == -5.0
    assert terms["social"] == 0.0  # no humans
    # the robot heads straight at the goal at 1 m/s for 0.2 s
    assert terms["goal_progress"] == pytest.approx(10.0 * 0.2, abs=0.02)
    assert reward == pytest.approx(-5.0 + terms["goal_progress"])


def test_goal_reached_pays_once_and_reports_success():
    env = CrowdNavEnv(constructed(goal=(1.0, 0.0)), modalities=["goal"])
    env.reset(seed=1)
    for _ in range(20):
        _, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0]))
        if terminated:
            break
        assert info["reward_terms"]["goal_reached"] == 0.0 and "outcome" not in info
    assert terminated and not truncated
    assert info["outcome"] == "success" and info["is_success"] is True
    assert info["reward_terms"]["goal_reached"] == 500.0 and info["reward_terms"]["collision"] == 0.0
    assert "collision_kind" not in info
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(2))


def test_collision_with_a_human_pays_once_and_names_the_human():
    env = CrowdNavEnv(constructed(humans=[(1.4, 0.0)]), modalities=["goal"])
    env.reset(seed=2)
    for _ in range(20):
        _, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0]))
        if terminated:
            break
        assert info["reward_terms"]["collision"] == 0.0
    assert terminated and not truncated
    assert info["outcome"] == "collision" and info["is_success"] is False
    assert info["collision_kind"] == "human" and info["collision_partner"] == "human_0"
    assert info["reward_terms"]["collision"] == -500.0 and info["reward_terms"]["goal_reached"] == 0.0
    assert reward == sum(info["reward_terms"].values())


def test_collision_with_a_wall_is_static_and_names_the_wall():
    env = CrowdNavEnv(constructed(walls=[((1.0, -2.0), (1.0, 2.0))]), modalities=["goal"])
    env.reset(seed=0)
    for _ in range(20):
        _, _, terminated, _, info = env.step(np.array([1.0, 0.0]))
        if terminated:
            break
    assert info["outcome"] == "collision"
    assert info["collision_kind"] == "static" and info["collision_partner"].startswith("walls.0")


def test_time_limit_truncates_without_terminating():
    env = CrowdNavEnv(constructed(max_steps=3), modalities=["goal"])
    env.reset(seed=0)
    ends = [env.step(np.zeros(2))[2:] for _ in range(3)]
    assert [(terminated, truncated) for terminated, truncated, _ in ends] == [(False, False), (False, False), (False, True)]
    info = ends[-1][2]
    assert info["outcome"] == "truncated" and info["is_success"] is False and "collision_kind" not in info
