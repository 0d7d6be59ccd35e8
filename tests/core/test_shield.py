"""The action-time safety shield (env option ``shield``): what it reads, what it changes, batched = single."""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav.envs import CrowdNavEnv
from crowdnav.envs.vector.env import CrowdNavVectorEnv
from crowdnav.planning.scripted import StraightToGoal
from crowdnav.planning.shield import shield_settings

FIGURE4 = {"humans.count": 5, "humans.preferred_speed": [0.5, 1.2]}


def _outcomes(shield, seeds):
    env = CrowdNavEnv(scenario="room_furniture", modalities=["goal"], overrides=FIGURE4, shield=shield)
    policy, out, replaced = StraightToGoal(), [], 0
    for seed in seeds:
        env.reset(seed=seed)
        while True:
            _, _, terminated, truncated, info = env.step(policy(env.simulator))
            replaced += int(info.get("shielded", False))
            if terminated or truncated:
                out.append(info["outcome"])
                break
    return out, replaced


def test_shield_turns_straight_to_goal_collisions_into_arrivals_and_says_when_it_acted():
    seeds = range(1000, 1010)
    bare, none_replaced = _outcomes(None, seeds)
    shielded, replaced = _outcomes(True, seeds)
    assert none_replaced == 0 and replaced > 0
    assert shielded.count("collision") < bare.count("collision")
    assert shielded.count("success") > bare.count("success")


def test_shielded_vector_env_steps_every_world_as_the_single_env_does():
    seeds = [1000, 1001, 1002]
    vector = CrowdNavVectorEnv("room_furniture", 3, modalities=["goal", "humans"], overrides=FIGURE4, shield=True,
                               autoreset_mode="Disabled")
    singles = [CrowdNavEnv(scenario="room_furniture", modalities=["goal", "humans"], overrides=FIGURE4, shield=True) for _ in seeds]
    obs, _ = vector.reset(seed=seeds)
    single_obs = [env.reset(seed=seed)[0] for env, seed in zip(singles, seeds, strict=True)]
    rng = np.random.default_rng(0)
    running = np.ones(3, dtype=bool)
    for _ in range(40):
        actions = rng.uniform(-1, 1, size=(3, 2)).astype(np.float32)
        obs, _, terminated, truncated, infos = vector.step(actions)
        for i, env in enumerate(singles):
            if not running[i]:
                continue
            single_obs[i], _, term, trunc, info = env.step(actions[i])
            assert infos["shielded"][i] == info["shielded"]
            for key in obs:
                assert np.array_equal(obs[key][i], single_obs[i][key])
            running[i] = not (term or trunc)
        if not running.any():
            break


@pytest.mark.parametrize("option, message", [
    ({"horizon": -1}, "shield: horizon must be a finite number >= 0"),
    ({"horizon": 1e9}, "planner settings: horizon 1e+09 s"),
    ({"lookahead": 2}, "unknown setting(s) ['lookahead']"),
    ("yes", "shield must be true, false or a mapping"),
])
def test_a_bad_shield_option_is_one_line(option, message):
    with pytest.raises(ValueError) as error:
        CrowdNavEnv(scenario="room_furniture", shield=option)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_shield_refuses_a_unicycle_robot_and_several_robots_in_one_line():
    with pytest.raises(ValueError, match="holonomic robot; this scenario's robot is unicycle"):
        CrowdNavEnv(scenario="room_furniture", overrides={"robot.kinematics": "unicycle", "robot.max_angular_speed": 2.0}, shield=True)
    with pytest.raises(ValueError, match="robots: is not supported"):
        CrowdNavEnv(scenario="robots_crossing_hall", shield=True)


def test_shield_settings_accept_true_false_and_a_mapping():
    assert shield_settings(False) is None and shield_settings(None) is None
    assert shield_settings(True).horizon == 2.0
    assert shield_settings({"horizon": 1.0}).horizon == 1.0
