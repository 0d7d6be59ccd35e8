"""Checkpoints: loadable as deterministic policies, resumable with the episode count carried on."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from crowdnav.agents import ConfigError, load_policy, train, train_seed

from tests.agents.agents_tiny import tiny_config


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


def test_resume_sets_aside_episodes_and_snapshots_saved_after_the_checkpoint(tmp_path):
    train(tiny_config(tmp_path, episodes=2, max_steps=20, checkpoint_every=2))
    # As if the process had logged episodes 2-3 and saved snapshot 4 before it was killed.
    log = tmp_path / "episodes.csv"
    stale = ["2,12,collision,-1.0,3,99,1.0", "3,13,success,1.0,3,102,1.5"]
    log.write_text(log.read_text() + "\n".join(stale) + "\n")
    shutil.copytree(tmp_path / "snapshots" / "episode_00002", tmp_path / "snapshots" / "episode_00004")
    train(tiny_config(tmp_path, episodes=4, max_steps=20, checkpoint_every=2), resume=True)
    rows = [line.split(",") for line in log.read_text().splitlines()[1:]]
    assert [int(row[0]) for row in rows] == [0, 1, 2, 3]
    assert [int(row[1]) for row in rows] == [train_seed(0, episode) for episode in range(4)]
    assert (tmp_path / "episodes.csv.discarded").read_text().splitlines()[1:] == stale
    assert json.loads((tmp_path / "snapshots_discarded" / "episode_00004" / "policy.json").read_text())["episodes"] == 2
    assert json.loads((tmp_path / "snapshots" / "episode_00004" / "policy.json").read_text())["episodes"] == 4


def test_the_snapshot_is_saved_before_the_checkpoint_and_a_missing_one_is_restored_on_resume(tmp_path, monkeypatch):
    import crowdnav.agents.sb3.session as training_module

    saved = []
    original = training_module.save_checkpoint
    monkeypatch.setattr(training_module, "save_checkpoint", lambda model, folder, *args, **kwargs: (
        saved.append(folder.relative_to(tmp_path).as_posix()), original(model, folder, *args, **kwargs))[1])
    train(tiny_config(tmp_path, episodes=2, max_steps=20, checkpoint_every=2))
    assert saved[:2] == ["snapshots/episode_00002", "checkpoint"]
    # A run from an older crowdnav killed between its checkpoint and its snapshot.
    shutil.rmtree(tmp_path / "snapshots" / "episode_00002")
    saved.clear()
    train(tiny_config(tmp_path, episodes=3, max_steps=20, checkpoint_every=2), resume=True)
    assert saved[0] == "snapshots/episode_00002"
    assert json.loads((tmp_path / "snapshots" / "episode_00002" / "policy.json").read_text())["episodes"] == 2


def test_models_saved_by_sb3s_own_classes_load_into_crowdnavs_and_the_other_way_round(tmp_path):
    import torch
    from crowdnav.agents.runs.checkpoint import load_model, save_checkpoint
    from crowdnav.agents.sb3.algorithms import CrowdNavSAC
    from crowdnav.agents.sb3.factory import make_env, make_model
    from crowdnav.agents.training.config import config_from_mapping
    from stable_baselines3 import SAC

    config = config_from_mapping(tiny_config(tmp_path, modalities=["leog", "goal"]))
    sb3_model = make_model(config, make_env(config), reference=True)  # as crowdnav built models before its speed-ups
    sb3_model.learn(60)
    save_checkpoint(sb3_model, tmp_path / "old", {"algo": "sac", "env": {}}, replay_buffer=True)
    loaded = load_model(tmp_path / "old", env=make_env(config))
    assert isinstance(loaded, CrowdNavSAC)
    observation = {key: space.sample() for key, space in sb3_model.observation_space.spaces.items()}
    np.testing.assert_array_equal(loaded.predict(observation, deterministic=True)[0], sb3_model.predict(observation, deterministic=True)[0])
    from crowdnav.agents.runs.resume_state import REPLAY_ARRAYS, load_replay_buffer

    load_replay_buffer(loaded.replay_buffer, tmp_path / "old" / REPLAY_ARRAYS)  # arrays, no pickle
    loaded.learn(20, reset_num_timesteps=False)  # resumes training
    new_model = make_model(config, make_env(config))
    new_model.learn(60)
    new_model.save(tmp_path / "new.zip")
    back = SAC.load(tmp_path / "new.zip")  # plain SB3 reads crowdnav's models too
    states = new_model.policy.state_dict(), back.policy.state_dict()
    assert all(torch.equal(states[0][key], states[1][key]) for key in states[0])
    np.testing.assert_array_equal(back.predict(observation, deterministic=True)[0], new_model.predict(observation, deterministic=True)[0])


def test_a_checkpoint_renders_as_a_video_with_the_env_options_it_was_trained_with(tmp_path):
    from crowdnav.agents.runs.render import render_policy

    train(tiny_config(tmp_path / "run", episodes=1, max_steps=10))
    paths = render_policy("open_space", str(tmp_path / "run" / "checkpoint"), episodes=1, seed=3, out=tmp_path / "videos",
                          video_format="gif", progress=False)
    assert len(paths) == 1 and paths[0].name.startswith("open_space_checkpoint_seed3_") and paths[0].stat().st_size > 0  # + outcome


@pytest.mark.parametrize(("algo", "modalities"), [("sac", ["leog", "lidar", "goal"]), ("td3", ["lidar", "goal"]),
                                                  ("a2c", ["goal", "closest_obstacle"]),
                                                  ("ppo", ["lidar", "goal"])])
def test_loading_only_parameters_acts_exactly_like_the_full_sb3_load(tmp_path, algo, modalities):
    train(tiny_config(tmp_path, algo=algo, modalities=modalities, episodes=2))
    safe, full = load_policy(tmp_path), load_policy(tmp_path, trusted=True)
    env = safe.make_env()
    observation, _ = env.reset(seed=2)
    for _ in range(10):
        action = safe(observation)
        np.testing.assert_array_equal(action, full(observation))
        observation, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            observation, _ = env.reset()


def test_parameters_only_loading_never_unpickles_the_models_data(tmp_path, monkeypatch):
    import cloudpickle

    train(tiny_config(tmp_path, episodes=2))

    def poisoned(*args, **kwargs):
        raise AssertionError("a pickle was loaded")

    monkeypatch.setattr(cloudpickle, "loads", poisoned)
    monkeypatch.setattr("pickle.loads", poisoned)
    policy = load_policy(tmp_path)  # would fail if SB3's data (cloudpickle) or any pickle were read
    observation, _ = policy.make_env().reset(seed=0)
    assert policy(observation).shape == (2,)


def test_a_checkpoint_without_its_config_needs_a_trusted_load(tmp_path):
    from crowdnav.agents.runs.checkpoint import UntrustedCheckpointError

    train(tiny_config(tmp_path, episodes=2))
    info_path = tmp_path / "checkpoint" / "policy.json"
    info = json.loads(info_path.read_text())
    del info["config"]
    info_path.write_text(json.dumps(info))
    with pytest.raises(UntrustedCheckpointError, match="trusted=True only if you trust where it came from"):
        load_policy(tmp_path)
    assert load_policy(tmp_path, trusted=True)(load_policy(tmp_path, trusted=True).make_env().reset(seed=0)[0]).shape == (2,)
