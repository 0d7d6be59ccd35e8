"""Reward terms: formulas on constructed states, their sum, the event terms, the presets and the end-of-episode info."""

from __future__ import annotations

import contextlib
import io
import math

import numpy as np
import pytest

import crowdnav.envs  # noqa: F401  (registers the environments until crowdnav/__init__ imports them)
from benchmarks import reward_calibration
from crowdnav.envs import REWARD_TERMS, CrowdNavEnv
from crowdnav.scenario import ScenarioError, load_scenario, reward_presets
from crowdnav.scenario.reward_presets import DEFAULT_PRESET, REWARD_PRESETS

PAPER = {"step": -5.0, "goal_progress": 10.0, "social": -100.0, "goal_reached": 500.0, "collision": -500.0}
"""The OpenSocInt paper's weights (its Section "Reward functions"), step read as a penalty."""


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


def test_paper_preset_pays_the_papers_step_penalty_and_progress_weight():
    env = CrowdNavEnv(constructed(), modalities=["goal"], reward_weights={"preset": "paper"})
    env.reset(seed=0)
    _, reward, _, _, info = env.step(np.array([1.0, 0.0]))
    terms = info["reward_terms"]
    assert terms["step"] == -5.0
    assert terms["social"] == 0.0  # no humans
    # the robot heads straight at the goal at 1 m/s for 0.2 s
    assert terms["goal_progress"] == pytest.approx(10.0 * 0.2, abs=0.02)
    assert reward == pytest.approx(-5.0 + terms["goal_progress"])


def test_goal_reached_pays_once_and_reports_success():
    env = CrowdNavEnv(constructed(goal=(1.0, 0.0)), modalities=["goal"], reward_weights={"preset": "paper"})
    env.reset(seed=1)
    for _ in range(20):
        _, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0]))
        if terminated:
            break
        assert info["reward_terms"]["goal_reached"] == 0.0 and info["outcome"] == "truncated" and info["is_success"] is False
    assert terminated and not truncated
    assert info["outcome"] == "success" and info["is_success"] is True
    assert info["reward_terms"]["goal_reached"] == 500.0 and info["reward_terms"]["collision"] == 0.0
    assert "collision_kind" not in info
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(2))


def test_collision_with_a_human_pays_once_and_names_the_human():
    env = CrowdNavEnv(constructed(humans=[(1.4, 0.0)]), modalities=["goal"], reward_weights={"preset": "paper"})
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


# ----------------------------------------------------------------------------- presets


def test_paper_preset_has_exactly_the_papers_five_weights():
    assert dict(REWARD_PRESETS["paper"].weights) == PAPER
    assert load_scenario(constructed(), {"reward.preset": "paper"}).reward.terms == PAPER


def test_every_preset_gives_every_term_in_order_with_a_one_line_doc():
    assert DEFAULT_PRESET == "default" and list(REWARD_PRESETS)[0] == DEFAULT_PRESET
    for name, preset in REWARD_PRESETS.items():
        assert preset.name == name and tuple(preset.weights) == REWARD_TERMS
        assert all(math.isfinite(weight) for weight in preset.weights.values())
        assert preset.doc and "\n" not in preset.doc


def test_default_preset_numbers_live_in_one_place_each():
    default = REWARD_PRESETS["default"].weights
    assert default == {"step": reward_presets.DEFAULT_STEP, "goal_progress": reward_presets.DEFAULT_GOAL_PROGRESS,
                       "social": reward_presets.DEFAULT_SOCIAL, "goal_reached": reward_presets.DEFAULT_GOAL_REACHED,
                       "collision": reward_presets.DEFAULT_COLLISION}
    assert default["step"] < 0 < default["goal_progress"] and default["social"] < 0 and default["collision"] < 0 < default["goal_reached"]


def test_a_scenario_without_reward_section_gets_the_default_preset():
    env = CrowdNavEnv(constructed(), modalities=["goal"])
    assert "reward" not in constructed()
    reward = env.scenario.reward
    assert reward.preset == "default" and reward.terms == dict(REWARD_PRESETS["default"].weights)
    env.reset(seed=0)
    _, reward_value, _, _, info = env.step(np.array([1.0, 0.0]))
    assert info["reward_terms"]["step"] == reward_presets.DEFAULT_STEP
    assert info["reward_terms"]["goal_progress"] == pytest.approx(reward_presets.DEFAULT_GOAL_PROGRESS * 0.2, abs=1e-9)


@pytest.mark.parametrize("name", ["open_space", "room_furniture", "corridor"])
def test_library_scenarios_use_the_default_preset(name):
    assert load_scenario(name).reward.terms == dict(REWARD_PRESETS["default"].weights)


def test_a_single_term_override_on_top_of_a_preset_keeps_the_other_preset_weights():
    expected = {**PAPER, "social": -50.0}
    in_the_file = load_scenario({**constructed(), "reward": {"preset": "paper", "social": -50}}).reward
    as_overrides = load_scenario(constructed(), {"reward.preset": "paper", "reward.social": -50}).reward
    as_env_option = CrowdNavEnv(constructed(), modalities=["goal"], reward_weights={"preset": "paper", "social": -50}).scenario.reward
    for reward in (in_the_file, as_overrides, as_env_option):
        assert reward.preset == "paper" and reward.terms == expected
    on_the_default = load_scenario(constructed(), {"reward.social": -1.5}).reward
    assert on_the_default.terms == {**REWARD_PRESETS["default"].weights, "social": -1.5}


def test_explicit_terms_win_over_a_preset_given_later_also_from_a_loaded_scenario():
    scenario = load_scenario({**constructed(), "reward": {"social": -1.0}})
    assert scenario.reward.model_dump() == {"preset": "default", "social": -1.0}  # what was written, not the resolved numbers
    env = CrowdNavEnv(scenario, modalities=["goal"], reward_weights={"preset": "paper"})
    assert env.scenario.reward.terms == {**PAPER, "social": -1.0}
    scenario.reward.preset = "paper"  # assignment re-resolves the terms that were not given
    assert scenario.reward.terms == {**PAPER, "social": -1.0}


def test_unknown_preset_or_term_in_an_env_option_names_the_valid_ones():
    with pytest.raises(ScenarioError) as caught:
        CrowdNavEnv(constructed(), reward_weights={"preset": "papr"})
    assert "reward.preset: unknown reward preset 'papr'; did you mean 'paper'? expected one of: default, paper" in str(caught.value)
    with pytest.raises(ScenarioError) as caught:
        CrowdNavEnv(constructed(), reward_weights={"socal": -50})
    message = str(caught.value)
    assert "reward.socal: unknown key 'socal'; did you mean 'social'?" in message
    assert all(name in message for name in ("preset", *REWARD_TERMS))


# ---------------------------------------------------------------------- calibration


def test_reward_calibration_script_prints_both_tables_for_every_preset():
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert reward_calibration.main(["--gammas", "0.99", "--reward", "paper", "--reward-weight", "social=0"]) == 0
    text = out.getvalue()
    assert "(a) Social term" in text and "(b) Discounted return" in text
    for name in (*REWARD_PRESETS, "custom"):
        assert f"{name}: sum per pass" in text
        assert f"{name}: gamma 0.99" in text
    rows = {line.split(" | ")[0].lstrip("| "): line.split(" | ") for line in text.splitlines() if line.startswith("| ")}
    # peak |F_social| at a 0.5 m surface gap is A exp(-gap / B) = 2 exp(-0.5 / 0.3)
    walking = next(cells for line in text.splitlines() if line.startswith("| walking") and (cells := line.split(" | "))[1] == "0.5")
    assert float(walking[3].split(" / ")[0]) == pytest.approx(2 * math.exp(-0.5 / 0.3), rel=1e-2)
    assert rows["reach: straight to the goal 6 m away"][1] == "success"
    assert rows["collide: a wall, after 3 m of progress"][1:3] == ["collision", "15"]
