"""The robots' vector env (agents: robots collects through it): one row per robot per world, each world's rows what
stepping that world's robots-only env gives, autoresets included, bit for bit, whichever engine plays the worlds
(stacked in one batch, or one env per world); what SuperSuit's chain gave; restorable."""

from __future__ import annotations

import numpy as np
import pytest
from crowdnav.agents.marl.env import RobotsTrainingEnv
from crowdnav.agents.marl.vec_env import RobotsVecEnv
from crowdnav.agents.sb3.factory import env_options
from crowdnav.agents.training.config import TrainConfig, config_from_mapping

from crowdnav.envs.engines.robots import SingleRobots
from crowdnav.envs.engines.stacked_robots import StackedRobots
from tests.agents.test_marl import robots_config


def _config(tmp_path, **fields) -> TrainConfig:
    return config_from_mapping(robots_config(tmp_path / "run", **fields))


def _vec(tmp_path, engine: str = "stacked", **fields) -> RobotsVecEnv:
    # "single": the same worlds, one robots-only env each (what a scenario that does not stack gets)
    vec = RobotsVecEnv.make(_config(tmp_path, **fields), stacked=engine == "stacked")
    assert isinstance(vec.engine, StackedRobots if engine == "stacked" else SingleRobots)
    return vec


def _alone(tmp_path, **fields) -> list[RobotsTrainingEnv]:
    """The run's worlds as plain robots-only envs, each told its place (the per-world path, the reference)."""
    config = _config(tmp_path, **fields)
    worlds = [RobotsTrainingEnv(env_options(config), normalize=config.normalize_observations, identity=config.agent_identity,
                                run_seed=config.seed, actions=config.robot_actions) for _ in range(config.num_envs)]
    for world, env in enumerate(worlds):
        env.assign_world(world, config.num_envs)
    return worlds


def _actions(rng: np.random.Generator, rows: int) -> np.ndarray:
    return rng.uniform(-1.0, 1.0, size=(rows, 2)).astype(np.float32)


def _info(info: dict) -> dict:
    """An info with its arrays as bytes, to compare exactly."""
    return {key: value.tobytes() if isinstance(value, np.ndarray) else value for key, value in info.items()}


@pytest.mark.parametrize("engine", ["stacked", "single"])
@pytest.mark.parametrize("fields", [{}, {"num_envs": 1, "robot_actions": "goal_velocity"}, {"num_envs": 3, "robot_actions": "velocity"},
                                    {"num_envs": 4, "robot_actions": "goal_velocity", "overrides": {"max_steps": 24, "humans.count": [0, 6]}}],
                         ids=["two-worlds", "one-world-goal-frame", "three-worlds-velocity", "four-worlds-crowd-sizes-goal-frame"])
def test_each_worlds_rows_are_its_robots_env_stepped_alone_resets_included(tmp_path, fields, engine):
    vec = _vec(tmp_path, engine, **fields)
    alone = _alone(tmp_path, **fields)
    robots = len(vec.robots)
    observation = vec.reset()
    expected = [world.reset()[0] for world in alone]
    assert observation.dtype == np.float32 and observation.shape == (len(alone) * robots, *vec.observation_space.shape)
    rng, ends = np.random.default_rng(0), 0
    for _ in range(70):  # episodes of at most 20 (24) steps: every world resets a few times
        assert np.array_equal(observation, np.stack([world[name] for world in expected for name in vec.robots]))
        actions = _actions(rng, vec.num_envs)
        observation, rewards, dones, infos = vec.step(actions)
        assert rewards.dtype == np.float32 and dones.dtype == np.bool_ and len(infos) == vec.num_envs
        for w, world in enumerate(alone):
            rows = slice(w * robots, (w + 1) * robots)
            seen, earned, terminated, truncated, told = world.step({name: actions[rows][k] for k, name in enumerate(vec.robots)})
            ended = all(terminated[name] or truncated[name] for name in vec.robots)
            assert np.array_equal(rewards[rows], np.array([earned[name] for name in vec.robots], np.float32))
            assert dones[rows].tolist() == [ended] * robots  # a robot's row is done when its world's episode is
            for k, name in enumerate(vec.robots):
                info = infos[w * robots + k]
                if ended:  # the last observation kept, the new episode's first returned, the reset's infos on top
                    assert np.array_equal(info.pop("terminal_observation"), seen[name]) and info["active"] is True
                assert _info(info) == _info({**told[name], **({"active": True} if ended else {})})
            expected[w] = world.reset()[0] if ended else seen
            ends += ended
    assert ends >= 2 * len(alone)


def test_the_rows_are_what_supersuits_chain_made_of_the_same_worlds_bit_for_bit(tmp_path):
    """SuperSuit's concat_vec_envs_v1 over pettingzoo_env_to_vec_env_v1 collected for agents: robots before; the runs
    published then reproduce through RobotsVecEnv only if it lays out and resets the rows as that chain did."""
    ss = pytest.importorskip("supersuit")
    vec = _vec(tmp_path, robot_actions="velocity")
    base = _alone(tmp_path, num_envs=1, robot_actions="velocity")[0]
    chain = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(base), 2, base_class="stable_baselines3")
    for world, markov in enumerate(chain.venv.vec_envs):
        markov.par_env.assign_world(world, 2)
    assert np.array_equal(vec.reset(), chain.reset())
    rng = np.random.default_rng(1)
    for _ in range(60):
        actions = _actions(rng, vec.num_envs)
        ours, theirs = vec.step(actions), chain.step(actions)
        for mine, other in zip(ours[:3], theirs[:3], strict=True):  # dones: bool here, SuperSuit's uint8
            assert np.array_equal(mine, other)
        assert ours[0].dtype == theirs[0].dtype and ours[1].dtype == theirs[1].dtype
        assert [_info(info) for info in ours[3]] == [_info(info) for info in theirs[3]]


@pytest.mark.parametrize("engine", ["stacked", "single"])
def test_restored_worlds_continue_as_the_worlds_that_played_on(tmp_path, engine):
    fields = {"num_envs": 3, "robot_actions": "goal_velocity", "overrides": {"max_steps": 80}}
    vec, restored = _vec(tmp_path, engine, **fields), _vec(tmp_path, engine, **fields)
    last = vec.reset()
    restored.reset()
    rng = np.random.default_rng(2)
    for _ in range(45):  # at the goals, noisily: the first episodes end at different steps, the worlds are in their second
        last = vec.step(rng.normal([1.0, 0.0], 0.3, (vec.num_envs, 2)).astype(np.float32))[0]
    counters = vec.episode_counters()
    actions, lengths = vec.episode_actions()
    assert counters[0][1] >= 2 and lengths.max() > 0 and len(set(lengths.tolist())) > 1
    assert np.array_equal(restored.restore_worlds(counters, actions, lengths), last)
    for _ in range(30):
        move = _actions(rng, vec.num_envs)
        expected, rewards, dones, infos = vec.step(move)
        observation, again, ended, told = restored.step(move)
        assert np.array_equal(observation, expected) and np.array_equal(again, rewards) and np.array_equal(ended, dones)
        assert [_info(info) for info in told] == [_info(info) for info in infos]
    assert restored.episode_counters() == vec.episode_counters()
    assert all(np.array_equal(mine, theirs) for mine, theirs in zip(restored.episode_actions(), vec.episode_actions(), strict=True))


def test_a_restore_with_another_world_count_is_refused(tmp_path):
    vec = _vec(tmp_path)
    with pytest.raises(ValueError, match="one counter pair, action array and length per world"):
        vec.restore_worlds([(0, 1)], np.zeros((1, 0, 3, 2), np.float32), np.zeros(1, np.int64))
