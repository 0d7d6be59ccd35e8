"""The run-folder API: where a training run keeps its checkpoint, snapshots and episode log, as evaluation reads them."""

from __future__ import annotations

import json
import shutil

from crowdnav.agents import load_policy, train
from crowdnav.agents.runs.folder import (
    checkpoint_dir,
    checkpoint_episodes,
    checkpoint_info,
    episode_log,
    logged_episodes,
    policy_snapshots,
    replay_buffer_file,
    snapshot_dir,
)

from tests.agents.agents_tiny import tiny_config


def test_a_snapshot_newer_than_the_checkpoint_is_not_evaluated(tmp_path):
    train_dir = tmp_path / "train"
    for folder, episodes in (("checkpoint", 4), ("snapshots/episode_00002", 2), ("snapshots/episode_00004", 4),
                             ("snapshots/episode_00006", 6)):  # 6: saved, then killed before its checkpoint
        (train_dir / folder).mkdir(parents=True)
        (train_dir / folder / "policy.json").write_text(json.dumps({"episodes": episodes}))
    assert policy_snapshots(train_dir) == {2: train_dir / "snapshots/episode_00002", 4: train_dir / "snapshots/episode_00004"}
    shutil.rmtree(train_dir / "checkpoint")
    assert policy_snapshots(train_dir) == {}


def test_an_empty_folder_has_no_checkpoint_snapshots_or_logged_episodes(tmp_path):
    assert checkpoint_info(tmp_path) is None and checkpoint_episodes(tmp_path) == 0
    assert policy_snapshots(tmp_path) == {} and logged_episodes(tmp_path) == 0


def test_the_api_finds_what_training_wrote(tmp_path):
    train(tiny_config(tmp_path, episodes=2, max_steps=10, checkpoint_every=1))
    assert checkpoint_episodes(tmp_path) == 2 and checkpoint_info(tmp_path)["timesteps"] > 0
    assert policy_snapshots(tmp_path) == {1: snapshot_dir(tmp_path, 1), 2: snapshot_dir(tmp_path, 2)}
    assert episode_log(tmp_path).is_file() and logged_episodes(tmp_path) == 2
    assert replay_buffer_file(tmp_path).parent == checkpoint_dir(tmp_path)
    assert load_policy(snapshot_dir(tmp_path, 1)).env_options["scenario"] == "open_space"
