"""Stable-Baselines3 trains on a registered id (a smoke test of the Gymnasium contract, not of learning)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import crowdnav.envs  # noqa: F401  (registers the environments until crowdnav/__init__ imports them)

sb3 = pytest.importorskip("stable_baselines3")
torch = pytest.importorskip("torch")


pytestmark = pytest.mark.usefixtures("one_torch_thread")  # tests/conftest.py


def small() -> dict:
    """Small networks keep the test quick; a new dict each time because SB3 adds keys to it."""
    return {"net_arch": [64, 64]}


def test_sac_trains_on_lidar_and_goal():
    env = gym.make("crowdnav/RoomFurniture-v0", modalities=["lidar", "goal"])
    # one gradient step per 4 env steps keeps the 1,000-step run to a few seconds on a CPU
    model = sb3.SAC(
        "MultiInputPolicy", env, policy_kwargs=small(), learning_starts=200, batch_size=64, train_freq=4, seed=0, device="cpu"
    )
    model.learn(total_timesteps=1_000)
    assert model.num_timesteps == 1_000
    observation, _ = env.reset(seed=0)
    action, _ = model.predict(observation, deterministic=True)
    assert action.shape == (2,) and np.all(np.abs(action) <= 1.0)


@pytest.mark.slow  # 5 s; each modality trains in the default suite elsewhere (test_sac_trains_on_lidar_and_goal, the batched grids and lidar case)
def test_ppo_trains_with_all_modalities():
    env = gym.make("crowdnav/RoomFurniture-v0", modalities=["goal", "closest_obstacle", "lidar", "leog", "velocity"])
    model = sb3.PPO(
        "MultiInputPolicy", env, policy_kwargs=small(), n_steps=2_048, batch_size=256, n_epochs=2, seed=0, device="cpu"
    )
    model.learn(total_timesteps=2_048)
    assert model.num_timesteps == 2_048
    # the LEOG went through SB3's image pipeline (uint8 channel-first image -> CNN)
    assert "leog" in model.policy.features_extractor.extractors
