"""Worlds the native vector env holds as single envs (:func:`crowdnav.envs.vector.env.stacks` False): one world, and crowds of
``Simulator.grid_from`` humans or more. They must play the single env's episodes bit for bit, with the vector env's own
autoreset modes, infos, shield and residual plan, as stacked worlds do (tests/core/test_vector_env.py)."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import crowdnav  # noqa: F401  (registers the ids)
from crowdnav import Simulator
from crowdnav.batch.simulator import BatchSimulator
from crowdnav.envs import CrowdNavEnv
from crowdnav.envs.engines.per_world import TeamWorlds
from crowdnav.envs.engines.stacked import StackedWorlds
from crowdnav.envs.engines.stacked_team import StackedTeamWorlds
from crowdnav.envs.vector.env import CrowdNavVectorEnv, stacks
from crowdnav.worlds.compiled import load_world
from tests.core.test_vector_env import ALL, _compare_with_sync

FIGURE4 = {"humans.count": 5, "humans.preferred_speed": [0.5, 1.2]}


def test_the_vector_env_stacks_several_worlds_of_small_crowds_and_robot_teams_whose_policy_and_crowd_it_batches(monkeypatch):
    world, robots = load_world("room_furniture"), load_world("robots_crossing_hall")
    assert stacks(world, 2) and not stacks(world, 1)
    assert stacks(robots, 2) and stacks(robots, 2, "straight") and not stacks(robots, 1)
    assert not stacks(robots, 2, "orca") and not stacks(robots, 2, lambda view: np.zeros(2))  # no batched twin: single envs
    assert not stacks(load_world("robots_crossing_hall", {"humans.model": "orca"}), 2)  # the stacked crowd view lists one robot
    monkeypatch.setattr(Simulator, "grid_from", world.scenario.humans.max_count)  # (no library scenario holds 200 humans)
    assert not stacks(world, 2)
    monkeypatch.undo()
    assert isinstance(CrowdNavVectorEnv("room_furniture", 1, modalities=["goal"]).engine, TeamWorlds)
    assert isinstance(CrowdNavVectorEnv("room_furniture", 2, modalities=["goal"]).engine, StackedWorlds)
    assert isinstance(CrowdNavVectorEnv("robots_crossing_hall", 2).engine, StackedTeamWorlds)
    assert isinstance(CrowdNavVectorEnv("robots_crossing_hall", 2, other_robots=lambda view: np.zeros(2)).engine, TeamWorlds)


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_one_world_equals_the_sync_vector_env_bit_for_bit_through_autoresets(mode):
    assert _compare_with_sync("RoomFurniture", mode, 150, num_envs=1, modalities=ALL) > 0


def test_crowds_of_the_neighbour_grid_run_as_single_envs_and_equal_sync_bit_for_bit(monkeypatch):
    monkeypatch.setattr(Simulator, "grid_from", 4)  # 5 to 6 humans: the single simulator's neighbour grid
    with pytest.raises(ValueError, match="handles crowds below 4 humans"):  # the stacked batch measures all pairs only
        BatchSimulator(load_world("open_space", {"humans.count": 5}), 2)
    env = CrowdNavVectorEnv("open_space", 3, modalities=["goal"], overrides={"humans.count": [5, 6]})
    env.reset(seed=0)
    assert isinstance(env.engine, TeamWorlds) and all(sim.geometry.grid is not None for sim in env.engine.simulators())
    assert _compare_with_sync("OpenSpace", AutoresetMode.SAME_STEP, 120, num_envs=3, modalities=["goal", "lidar", "closest_obstacle"],
                              overrides={"humans.count": [5, 6]}) > 0


@pytest.mark.parametrize("options", [
    {"modalities": ["goal", "humans"], "shield": True},
    {"modalities": ["goal", "plan"], "shield": True, "residual": True},
], ids=["shield", "residual_and_shield"])
def test_one_shielded_world_steps_as_the_single_env_does(options):
    overrides = {**FIGURE4, "max_steps": 30}  # episodes end within the test, by the time limit at the latest
    vector = CrowdNavVectorEnv("room_furniture", 1, overrides=overrides, autoreset_mode="SameStep", **options)
    single = CrowdNavEnv(scenario="room_furniture", overrides=overrides, **options)
    obs, _ = vector.reset(seed=[1000])
    single_obs, _ = single.reset(seed=1000)
    rng, shielded, ends = np.random.default_rng(0), 0, 0
    for _ in range(120):
        actions = rng.uniform(-1, 1, size=(1, 2)).astype(np.float32)
        obs, reward, terminated, truncated, infos = vector.step(actions)
        single_obs, single_reward, term, trunc, info = single.step(actions[0])
        assert (terminated[0], truncated[0]) == (term, trunc) and reward[0] == single_reward
        step_infos = infos["final_info"] if term or trunc else infos  # an ended episode's info moves to final_info
        assert step_infos["shielded"][0] == info["shielded"] and step_infos["outcome"][0] == info["outcome"]
        if term or trunc:
            assert all(np.array_equal(infos["final_obs"][0][key], single_obs[key]) for key in obs)
            single_obs, _ = single.reset()
            ends += 1
        assert all(np.array_equal(obs[key][0], single_obs[key]) for key in obs)
        shielded += int(info["shielded"])
    assert shielded > 0 and ends > 0
