"""The ``plan`` modality (the predictive planner from the robot's own sensing) and the ``residual`` env option."""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav.envs import CrowdNavEnv
from crowdnav.envs.vector.env import CrowdNavVectorEnv
from crowdnav.planning.predictive import CrowdEstimate, PredictivePlanner

FIGURE4 = {"humans.count": 5, "humans.preferred_speed": [0.5, 1.2]}


def test_plan_is_the_predictive_planners_move_when_the_tracker_sees_every_human():
    env = CrowdNavEnv(scenario="room_furniture", modalities=["plan"], overrides=FIGURE4)
    observation, _ = env.reset(seed=4)
    sim = env.simulator
    move = PredictivePlanner().plan(sim.world, sim.dt, CrowdEstimate.from_sim(sim))[0]
    expected = move / (sim.scenario.robot.max_speed * sim.dt) * np.exp(-1j * sim.robot_heading)
    assert observation["plan"] == pytest.approx([expected.real, expected.imag], abs=1e-5)


def test_plan_ignores_humans_beyond_the_trackers_range():
    far = CrowdNavEnv(scenario="room_furniture", modalities=["plan"], overrides=FIGURE4, sensors={"humans": {"max_range": 0.01}})
    far.reset(seed=4)
    planner = PredictivePlanner()
    sim = far.simulator
    empty = CrowdEstimate(np.array([sim.robot_position]), np.array([sim.robot_goal]), np.zeros((1, 0), complex),
                          np.zeros((1, 0), complex), np.zeros((1, 0)), np.zeros((1, 0), bool))
    move = planner.plan(sim.world, sim.dt, empty)[0] / (sim.scenario.robot.max_speed * sim.dt) * np.exp(-1j * sim.robot_heading)
    assert far.core.observe()["plan"] == pytest.approx([move.real, move.imag], abs=1e-5)


def test_residual_with_zero_actions_follows_the_plan_to_the_goal():
    env = CrowdNavEnv(scenario="room_furniture", modalities=["goal", "plan"], overrides=FIGURE4, residual=True)
    outcomes = []
    for seed in range(1000, 1006):
        env.reset(seed=seed)
        while True:
            _, _, terminated, truncated, info = env.step(np.zeros(2, dtype=np.float32))
            if terminated or truncated:
                outcomes.append(info["outcome"])
                break
    assert outcomes == ["success"] * 6


def test_residual_vector_env_observes_and_steps_as_the_single_env():
    seeds = [1000, 1001]
    options = dict(modalities=["goal", "plan"], overrides=FIGURE4, residual=True)
    vector = CrowdNavVectorEnv("room_furniture", 2, autoreset_mode="Disabled", **options)
    singles = [CrowdNavEnv(scenario="room_furniture", **options) for _ in seeds]
    obs, _ = vector.reset(seed=seeds)
    single = [env.reset(seed=seed)[0] for env, seed in zip(singles, seeds, strict=True)]
    rng = np.random.default_rng(1)
    alive = [True, True]
    for _ in range(30):
        actions = rng.normal(0, 0.3, size=(2, 2)).astype(np.float32)
        obs, _, _, _, _ = vector.step(actions)
        for i, env in enumerate(singles):
            if alive[i]:
                single[i], _, term, trunc, _ = env.step(actions[i])
                assert np.array_equal(obs["plan"][i], single[i]["plan"]) and np.array_equal(obs["goal"][i], single[i]["goal"])
                alive[i] = not (term or trunc)


def test_residual_without_the_plan_key_and_plan_on_a_unicycle_are_one_line_errors():
    with pytest.raises(ValueError, match="observation keys must include plan"):
        CrowdNavEnv(scenario="room_furniture", modalities=["goal"], residual=True)
    with pytest.raises(ValueError, match="residual must be true or false"):
        CrowdNavVectorEnv("room_furniture", 2, modalities=["goal", "plan"], residual="yes")
    with pytest.raises(Exception, match="holonomic") as error:
        CrowdNavEnv(scenario="room_furniture", modalities=["plan"], overrides={"robot.kinematics": "unicycle", "robot.max_angular_speed": 2.0})
    assert "\n" not in str(error.value)
