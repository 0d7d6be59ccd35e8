"""``CrowdNavVectorEnv.restore_worlds``: the public way a training resume rebuilds its worlds mid-episode.

Each world reset with its seed and stepped through its own actions must be the world that played
them (observations and the reward that the next step pays), with the residual plan and the shield
applied as ``step`` applies them; worlds of different lengths step only through their own actions.
"""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav.envs.vector.env import CrowdNavVectorEnv

FIGURE4 = {"humans.count": 5, "humans.preferred_speed": [0.5, 1.2]}
SEEDS = [1000, 1001, 1002]


def _played(options: dict, lengths: list[int], steps: int = 12) -> tuple[np.ndarray, list[dict[str, np.ndarray]]]:
    """Random actions, and each world's observation after its first ``lengths[i]`` of them (played one world at a time)."""
    actions = np.random.default_rng(3).uniform(-1, 1, size=(len(SEEDS), steps, 2))
    observed = []
    for i, length in enumerate(lengths):
        single = CrowdNavVectorEnv(num_envs=1, autoreset_mode="Disabled", **options)
        obs, _ = single.reset(seed=[SEEDS[i]])
        for step in range(length):
            obs, *_ = single.step(actions[i : i + 1, step])
        observed.append({key: value[0] for key, value in obs.items()})
    return actions, observed


@pytest.mark.parametrize("options", [
    {"scenario": "room_furniture", "modalities": ["goal", "humans", "lidar"], "overrides": FIGURE4},
    {"scenario": "room_furniture", "modalities": ["goal", "plan"], "overrides": FIGURE4, "residual": True, "shield": True},
], ids=["plain", "residual_and_shield"])
def test_restored_worlds_are_the_worlds_that_played_their_own_actions_and_step_on_alike(options):
    lengths = [0, 7, 12]
    actions, observed = _played(options, lengths)
    vector = CrowdNavVectorEnv(num_envs=3, autoreset_mode="Disabled", **options)
    restored = vector.restore_worlds(SEEDS, actions, np.array(lengths))
    for i in range(3):
        for key in observed[i]:
            assert np.array_equal(restored[key][i], observed[i][key]), (i, key)
    # the next step pays the same reward as a world that never stopped (the kept goal distance included)
    following = np.random.default_rng(4).uniform(-1, 1, size=(3, 2))
    obs, reward, *_ = vector.step(following)
    for i in range(3):
        single_obs, single_reward = _step_world(options, SEEDS[i], actions[i, : lengths[i]], following[i])
        assert reward[i] == single_reward, i
        assert all(np.array_equal(obs[key][i], single_obs[key][0]) for key in obs), i


def _step_world(options: dict, seed: int, actions: np.ndarray, last: np.ndarray) -> tuple[dict[str, np.ndarray], float]:
    single = CrowdNavVectorEnv(num_envs=1, autoreset_mode="Disabled", **options)
    single.reset(seed=[seed])
    for action in actions:
        single.step(action[None])
    obs, reward, *_ = single.step(last[None])
    return obs, float(reward[0])


def test_restore_worlds_refuses_lengths_that_do_not_fit_the_worlds_or_the_actions_in_one_line():
    vector = CrowdNavVectorEnv("open_space", 2, modalities=["goal"])
    with pytest.raises(ValueError, match=r"restore_worlds: lengths must be \(2,\)"):
        vector.restore_worlds([1, 2], np.zeros((2, 4, 2)), np.array([1, 5]))
    with pytest.raises(ValueError, match=r"restore_worlds: lengths must be \(2,\)"):
        vector.restore_worlds([1, 2], np.zeros((2, 4, 2)), np.array([1.0, 2.0]))
