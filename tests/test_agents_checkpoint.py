"""Checkpoints: loadable as deterministic policies, resumable with the episode count carried on."""

from __future__ import annotations

import json

import numpy as np
import pytest
from agents_tiny import tiny_config

from agents import ConfigError, load_policy, train, train_seed


def test_saved_checkpoint_loads_as_a_deterministic_policy_that_acts(tmp_path):
    config = tiny_config(tmp_path, modalities=["leog", "lidar", "goal"], episodes=2)
    train(config)
    info = json.loads((tmp_path / "checkpoint" / "policy.json").read_text())
    assert info["algo"] == "sac" and info["episodes"] == 2 and info["leog_encoder"] is None
    policy = load_policy(tmp_path)  # the run folder; the checkpoint folder works too
    assert policy.env_options == {"scenario": "open_space", "modalities": ["leog", "lidar", "goal"], "sensors": config["sensors"],
                                  "overrides": config["overrides"], "reward_weights": {}}
    env = policy.make_env()
    observation, _ = env.reset(seed=5)
    action = policy(observation)
    assert action.shape == (2,) and action.dtype == np.float32 and np.all(np.abs(action) <= 1.0)
    np.testing.assert_array_equal(policy(observation), action)
    env.step(action)  # the env accepts it
    batch = {key: np.stack([value, value]) for key, value in observation.items()}
    np.testing.assert_allclose(policy(batch), [action, action], atol=1e-6)
    snapshot = load_policy(tmp_path / "snapshots" / "episode_00002" / "policy.json")
    np.testing.assert_allclose(snapshot(observation), action, atol=1e-6)


def test_resuming_continues_the_episode_count_and_seeds(tmp_path):
    train(tiny_config(tmp_path, episodes=2, max_steps=20))
    result = train(tiny_config(tmp_path, episodes=4, max_steps=20), resume=True)
    assert result.episodes == 4 and [r.episode for r in result.records] == [2, 3]
    rows = [line.split(",") for line in (tmp_path / "episodes.csv").read_text().splitlines()[1:]]
    assert [int(row[0]) for row in rows] == [0, 1, 2, 3]
    assert [int(row[1]) for row in rows] == [train_seed(0, episode) for episode in range(4)]
    assert json.loads((tmp_path / "checkpoint" / "policy.json").read_text())["episodes"] == 4
    assert result.model.replay_buffer.size() >= sum(int(row[4]) for row in rows[:2])  # the saved buffer came back


def test_a_finished_run_is_not_overwritten_and_resume_needs_a_checkpoint(tmp_path):
    train(tiny_config(tmp_path, episodes=1, max_steps=10))
    with pytest.raises(ConfigError, match="already holds a run"):
        train(tiny_config(tmp_path, episodes=1, max_steps=10))
    with pytest.raises(ConfigError, match="holds no checkpoint"):
        train(tiny_config(tmp_path / "other", episodes=1), resume=True)
    with pytest.raises(ConfigError, match="trained with algo sac"):
        train(tiny_config(tmp_path, algo="td3", episodes=2, max_steps=10), resume=True)


def test_load_policy_names_what_is_missing(tmp_path):
    with pytest.raises(FileNotFoundError, match="no crowdnav checkpoint"):
        load_policy(tmp_path)
