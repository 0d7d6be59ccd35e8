"""LEOG datasets (collection, file format) and autoencoder pre-training."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from crowdnav.agents import GridDataset, collect_grids, load_dataset, load_encoder, pretrain_encoder, save_dataset, train_seed
from crowdnav.agents.training.wrappers import TRAIN_SEED_BASE, dataset_seed


@pytest.mark.slow  # 19 s of pre-training
def test_pretraining_cuts_the_held_out_reconstruction_loss_at_least_5x_on_the_furniture_room(tmp_path):
    torch.set_num_threads(1)
    grids = collect_grids("room_furniture", 2_000, seed=0)
    result = pretrain_encoder(grids, tmp_path, epochs=30, seed=0)
    assert result.initial_val_loss == pytest.approx(np.log(2), abs=1e-6)  # the untrained decoder predicts p = 0.5
    assert result.final_val_loss * 5 <= result.initial_val_loss, result.val_loss
    assert len(result.val_loss) == 31 and len(result.train_loss) == 30
    assert (tmp_path / "loss.png").stat().st_size > 0
    summary = json.loads((tmp_path / "encoder.json").read_text())
    assert summary["val_loss"] == pytest.approx(result.val_loss) and summary["architecture"]["grid_shape"] == [1, 60, 60]
    encoder, saved = load_encoder(tmp_path)
    assert encoder.latent == 64 and saved["metadata"]["grids"] == 2_000


def test_collected_grids_are_the_wandering_robots_leog_observations():
    dataset = collect_grids("room_furniture", 50, seed=3, every=3)
    again = collect_grids("room_furniture", 50, seed=3, every=3)
    assert dataset.grids.shape == (50, 1, 60, 60) and dataset.grids.dtype == np.uint8
    assert set(np.unique(dataset.grids)) <= {0, 255} and dataset.grids.any()
    np.testing.assert_array_equal(dataset.grids, again.grids)  # seeded
    assert dataset.metadata["scenario"] == "room_furniture" and dataset.metadata["resolution"] == 0.1
    assert not np.array_equal(dataset.grids[0], dataset.grids[-1])  # the robot moved


def test_dataset_round_trips_through_its_npz_file(tmp_path):
    dataset = collect_grids("room_furniture", 20, seed=0)
    path = save_dataset(dataset, tmp_path / "grids")
    assert path.name == "grids.npz"
    loaded = load_dataset(path)
    np.testing.assert_array_equal(loaded.grids, dataset.grids)
    assert loaded.metadata["format"] == "crowdnav-leog-dataset/1" and loaded.metadata["seed"] == 0
    with np.load(path, allow_pickle=False) as archive:  # readable without crowdnav
        assert archive["grids"].dtype == np.uint8 and archive["grids"].shape == (20, 1, 60, 60)


def test_a_foreign_dataset_needs_only_a_grids_array(tmp_path):
    occupied = np.random.default_rng(0).random((5, 12, 12)) < 0.2  # (N, H, W) booleans, no metadata
    np.savez(tmp_path / "other.npz", grids=occupied)
    loaded = load_dataset(tmp_path / "other.npz")
    assert loaded.grids.shape == (5, 1, 12, 12) and loaded.metadata == {}
    np.testing.assert_array_equal(loaded.grids[:, 0] > 0, occupied)


def test_bad_dataset_files_are_clear_errors(tmp_path):
    np.savez(tmp_path / "nogrids.npz", images=np.zeros((2, 1, 4, 4)))
    with pytest.raises(ValueError, match="no 'grids' array"):
        load_dataset(tmp_path / "nogrids.npz")
    np.savez(tmp_path / "shape.npz", grids=np.zeros((2, 3, 4, 4), dtype=np.uint8))
    with pytest.raises(ValueError, match=r"expected grids of shape \(N, 1, H, W\)"):
        load_dataset(tmp_path / "shape.npz")
    with pytest.raises(ValueError, match="cannot read"):
        load_dataset(tmp_path / "missing.npz")
    with pytest.raises(FileNotFoundError, match="pretrain-encoder"):
        load_encoder(tmp_path)


def test_pretraining_accepts_a_plain_array_and_skips_saving_without_an_output_folder():
    grids = (np.random.default_rng(1).random((40, 1, 30, 30)) < 0.1).astype(np.uint8)
    result = pretrain_encoder(GridDataset(grids).grids, None, channels=[4], kernels=[5], strides=[5], latent=4, epochs=1)
    assert result.encoder_path is None and result.architecture["grid_shape"] == [1, 30, 30]


def test_grid_collection_never_uses_a_test_or_training_episode_seed(monkeypatch):
    from crowdnav.envs import CrowdNavEnv

    seeds = []
    original = CrowdNavEnv.reset
    monkeypatch.setattr(CrowdNavEnv, "reset", lambda self, *, seed=None, options=None: (
        seeds.append(seed), original(self, seed=seed, options=options))[1])
    collect_grids("room_furniture", 300, seed=0, every=1, overrides={"max_steps": 20})
    assert len(seeds) >= 10 and seeds == [dataset_seed(0, episode) for episode in range(len(seeds))]
    held_out = set(range(TRAIN_SEED_BASE))  # what the evaluation protocol may use
    training = {train_seed(run, episode) for run in range(5) for episode in range(10_000)}
    assert not (set(seeds) & held_out) and not (set(seeds) & training)
    assert not ({dataset_seed(run, 0) for run in range(5)} & training)
