"""The native vector env on a several-robot scenario (robots:): world i plays the single env's episodes, bit for bit.

The first robot is the agent, the others follow their scripted policy (``other_robots``), as in
:class:`crowdnav.envs.CrowdNavEnv`; the worlds are a group of single simulators stepped in one call
(:class:`crowdnav.envs.engines.per_world.TeamWorlds`).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import crowdnav  # noqa: F401  (registers the ids)
from crowdnav.envs import CrowdNavEnv
from crowdnav.envs.vector.env import CrowdNavVectorEnv
from tests.core.test_vector_env import _same

SCENARIO = "robots_crossing_hall"
K = 3


def test_k_worlds_equal_k_single_envs_over_several_episodes_with_autoreset():
    """Observations, rewards, flags, outcomes and the other robots' outcomes of K worlds vs K CrowdNavEnv, across episode ends."""
    vector = CrowdNavVectorEnv(SCENARIO, K)
    singles = [CrowdNavEnv(SCENARIO) for _ in range(K)]
    assert vector.single_observation_space == singles[0].observation_space
    observation, _ = vector.reset(seed=40)
    firsts = [env.reset(seed=40 + i)[0] for i, env in enumerate(singles)]
    assert all(_same({key: values[i] for key, values in observation.items()}, firsts[i]) for i in range(K))
    rng = np.random.default_rng(4)
    ended = [0] * K
    restart = [False] * K  # NEXT_STEP: the step after an end resets that world (its action ignored)
    for _ in range(400):
        actions = rng.uniform(-1, 1, (K, 2))
        observation, rewards, terminated, truncated, infos = vector.step(actions)
        for i, env in enumerate(singles):
            if restart[i]:
                single_obs, _ = env.reset()  # no seed: the world's generator goes on, as the vector env's autoreset
                assert rewards[i] == 0.0 and not terminated[i] and not truncated[i] and not infos.get("_outcome", np.zeros(K, bool))[i]
                restart[i] = False
            else:
                single_obs, reward, term, trunc, info = env.step(actions[i])
                assert rewards[i].tobytes() == np.float64(reward).tobytes()
                assert (bool(terminated[i]), bool(truncated[i])) == (term, trunc)
                assert infos["outcome"][i] == info["outcome"] and infos["is_success"][i] == info["is_success"]
                assert {name: values[i] for name, values in infos["other_robots"].items() if not name.startswith("_")} \
                    == info["other_robots"]
                assert all(infos["reward_terms"][term][i] == value for term, value in info["reward_terms"].items())
                if term or trunc:
                    ended[i] += 1
                    restart[i] = True
            assert _same({key: values[i] for key, values in observation.items()}, single_obs)
    assert min(ended) >= 2  # several episodes in every world: the autoreset was compared too


@pytest.mark.parametrize("mode", [AutoresetMode.SAME_STEP, AutoresetMode.DISABLED])
def test_native_equals_sync_vector_env_on_robots_crossing_hall(mode):
    """Every output, infos included (final_obs / final_info in SAME_STEP), equals gymnasium's SyncVectorEnv of single envs."""
    options = {"num_envs": K, "other_robots": "straight"}
    native = gym.make_vec("crowdnav/RobotsCrossingHall-v0", vectorization_mode="vector_entry_point", autoreset_mode=mode, **options)
    sync = gym.make_vec("crowdnav/RobotsCrossingHall-v0", vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}, **options)
    assert isinstance(native.unwrapped, CrowdNavVectorEnv)
    assert _same(native.reset(seed=9)[0], sync.reset(seed=9)[0])
    rng, ends = np.random.default_rng(9), 0
    for _ in range(200):
        actions = rng.uniform(-1, 1, (K, 2)).astype(np.float32)
        mine, theirs = native.step(actions), sync.step(actions)
        assert all(_same(a, b) for a, b in zip(mine, theirs, strict=True))
        done = mine[2] | mine[3]
        ends += int(done.sum())
        if mode is AutoresetMode.DISABLED and done.any():  # both reset the ended worlds on request
            mask = done.copy()
            assert _same(native.reset(options={"reset_mask": mask})[0], sync.reset(options={"reset_mask": mask})[0])
    assert ends > 0


def test_world_accessors_and_snapshots_read_each_worlds_first_robot():
    vector = CrowdNavVectorEnv(SCENARIO, 2, modalities=["goal", "humans"])
    single = CrowdNavEnv(SCENARIO, modalities=["goal", "humans"])
    vector.reset(seed=3)
    single.reset(seed=4)
    assert vector.positions(1).tobytes() == single.simulator.positions.tobytes()
    assert vector.robot_goal(1) == single.simulator.robot_goal
    snapshot = vector.simulator(1)
    snapshot.step(np.ones(2), other_robot_actions=np.zeros((2, 2)))  # the world itself does not move
    assert vector.positions(1).tobytes() == single.simulator.positions.tobytes()
    assert vector.robot_social_force()[1] == single.simulator.robot_social_force


def test_the_shield_is_refused_in_one_line_for_several_robots():
    with pytest.raises(ValueError, match=r"^shield: shields one robot; a scenario with robots: is not supported$"):
        CrowdNavVectorEnv(SCENARIO, 2, shield=True)


def test_held_out_episodes_of_a_robots_scenario_batched_equal_one_env_per_seed_with_the_other_robots_recorded():
    from crowdnav.evaluation.rollout import HeldOutEpisodes

    def policy(batch):  # towards the goal (polar goal: distance, sin, cos)
        goal = batch["goal"]
        return np.stack([goal[:, 2], goal[:, 1]], axis=1)

    episodes = HeldOutEpisodes({"scenario": SCENARIO}, seeds=range(200, 204))
    batched, single = episodes.run(policy, record=True), episodes.run(policy, record=True, batched=False)
    for a, b in zip(batched, single, strict=True):
        frames_a, frames_b = a.pop("frames"), b.pop("frames")
        assert a.keys() == b.keys() and all(a[k] == b[k] or (a[k] != a[k] and b[k] != b[k]) for k in a)  # NaN: no time to goal
        assert frames_a["positions"].shape[1] == 1 + 10 + 2  # the first robot, the humans, the other robots (NaN once gone)
        assert all(np.array_equal(frames_a[k], frames_b[k], equal_nan=True) for k in ("positions", "velocities", "goals"))


def test_batched_lidar_of_worlds_with_different_robots_left_equals_single_envs():
    """The first robots' LIDAR, made in one batched raycast per set of robots left in the world, equals each single env's scan bit for bit."""
    k = 6
    vector = CrowdNavVectorEnv(SCENARIO, k, modalities=["lidar", "goal"])
    singles = [CrowdNavEnv(SCENARIO, modalities=["lidar", "goal"]) for _ in range(k)]
    observation, _ = vector.reset(seed=3)
    for i, env in enumerate(singles):
        env.reset(seed=3 + i)
    rng, restart, mixed = np.random.default_rng(1), [False] * k, 0
    for _ in range(300):
        actions = rng.uniform(-1, 1, (k, 2))
        observation, *_ = vector.step(actions)
        mixed += len({sim.robots_active.tobytes() for sim in vector.engine.simulators()}) > 1
        for i, env in enumerate(singles):
            if restart[i]:
                single_obs, _ = env.reset()
                restart[i] = False
            else:
                single_obs, _, term, trunc, _ = env.step(actions[i])
                restart[i] = term or trunc
            assert observation["lidar"][i].tobytes() == single_obs["lidar"].tobytes()
    assert mixed > 50  # many steps had worlds with different robots left: several groups were scanned
