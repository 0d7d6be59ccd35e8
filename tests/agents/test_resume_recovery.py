"""A kill at any point of a checkpoint swap or a results write loses nothing: resume starts from the newest complete state."""

from __future__ import annotations

import json
import shutil
import tarfile
from io import BytesIO

import pytest
from crowdnav.agents import train
from crowdnav.agents.runs.folder import checkpoint_episodes, recover_checkpoint
from crowdnav.evaluation.storage import clean_temporaries
from crowdnav.evaluation.transfer import pack_folder

from crowdnav.files import temporary_beside
from tests.agents.agents_tiny import tiny_config


def _fake_checkpoint(folder, episodes, complete=True):
    folder.mkdir(parents=True)
    (folder / "model.zip").write_bytes(b"zip")
    if complete:
        (folder / "policy.json").write_text(json.dumps({"episodes": episodes}))


@pytest.mark.parametrize(
    ("present", "expected"),
    [
        ({"checkpoint": 4, "checkpoint.partial": None}, 4),         # killed while writing the new one
        ({"checkpoint": 4, "checkpoint.partial": 6}, 6),            # killed after writing it, before the swap
        ({"checkpoint.old": 4, "checkpoint.partial": 6}, 6),        # killed between the two renames
        ({"checkpoint.old": 4, "checkpoint.partial": None}, 4),     # ... with the new one incomplete
        ({"checkpoint": 6, "checkpoint.old": 4}, 6),                # killed before removing the old one
        ({"checkpoint.partial": None}, 0),                          # killed while writing the first one
    ],
)
def test_the_newest_complete_checkpoint_becomes_the_checkpoint_and_leftovers_go(tmp_path, present, expected):
    for name, episodes in present.items():
        _fake_checkpoint(tmp_path / name, episodes or 0, complete=episodes is not None)
    assert recover_checkpoint(tmp_path) == expected == checkpoint_episodes(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == (["checkpoint"] if expected else [])


def test_a_run_killed_between_the_checkpoint_renames_resumes_from_the_complete_partial(tmp_path):
    config = tiny_config(tmp_path, episodes=4)
    train({**config, "episodes": 2})
    checkpoint = tmp_path / "checkpoint"
    shutil.copytree(checkpoint, tmp_path / "checkpoint.partial")  # the complete new checkpoint, never swapped in
    checkpoint.rename(tmp_path / "checkpoint.old")
    result = train(config, resume=True)
    assert result.episodes == 4 and not (tmp_path / "checkpoint.old").exists() and not (tmp_path / "checkpoint.partial").exists()
    rows = (tmp_path / "episodes.csv").read_text().strip().splitlines()[1:]
    assert len(rows) == 4  # episodes 0-1 kept, 2-3 trained after the resume: nothing lost, nothing twice


def test_orphaned_temporaries_are_removed_and_real_files_kept(tmp_path):
    (tmp_path / "evaluations").mkdir()
    orphan = tmp_path / "evaluations" / ".evaluation_003.csv.123.abcd1234.tmp"
    orphan.write_text("half")
    log_orphan = tmp_path / "episodes.csv.tmp"
    log_orphan.write_text("half")
    keep = tmp_path / "evaluations" / "evaluation_002.csv"
    keep.write_text("whole")
    assert sorted(clean_temporaries(tmp_path)) == sorted([orphan, log_orphan])
    assert keep.exists() and not orphan.exists() and not log_orphan.exists()


@pytest.mark.parametrize("suffix", [".mp4", ".gif", ".npz", ".png"])
def test_a_temporary_the_file_helpers_name_with_a_suffix_is_an_orphan_to_the_clean_up_and_the_transfer(tmp_path, suffix):
    destination = tmp_path / "videos" / f"episode_000{suffix}"
    orphan = temporary_beside(destination, suffix)  # the name a writer killed before its rename leaves (a video: ``.tmp.mp4``)
    orphan.write_bytes(b"half")
    keep = [tmp_path / "videos" / f"episode_001{suffix}", tmp_path / "videos" / f".hidden.tmp{suffix}.notes"]
    for path in keep:
        path.write_bytes(b"whole")
    with tarfile.open(fileobj=BytesIO(pack_folder(tmp_path))) as packed:
        assert sorted(packed.getnames()) == sorted(str(path.relative_to(tmp_path)) for path in keep)
    assert clean_temporaries(tmp_path) == [orphan]
    assert not orphan.exists() and all(path.exists() for path in keep)


def test_every_checkpoint_is_announced_so_the_runner_can_save_its_timing(tmp_path):
    saved = []
    train(tiny_config(tmp_path, episodes=4, checkpoint_every=2), on_checkpoint=saved.append)
    assert saved[:2] == [2, 4] and set(saved) == {2, 4}


def test_a_checkpoint_carries_the_random_streams_and_a_resume_restores_them(tmp_path):
    import random

    import numpy as np
    import torch
    from crowdnav.agents.runs.checkpoint import load_policy
    from crowdnav.agents.runs.resume_state import STATE_FILE, restore_training_state

    train(tiny_config(tmp_path, episodes=2, checkpoint_every=2))
    path = tmp_path / "checkpoint" / STATE_FILE
    assert path.is_file() and not (tmp_path / "checkpoint" / "rng_state.pkl").exists()  # JSON, no pickle
    model = load_policy(tmp_path).model  # building a model re-seeds every stream ...
    assert restore_training_state(model, path)  # ... and these are the ones the run had reached
    draws = (torch.rand(3).tolist(), np.random.rand(3).tolist(), random.random(), model.action_space.sample().tolist())
    restore_training_state(model, path)
    assert draws == (torch.rand(3).tolist(), np.random.rand(3).tolist(), random.random(), model.action_space.sample().tolist())
