"""Bounds before allocation (issue 49 item 3) from the command line: each probe is refused in one line, in a fresh process
whose peak memory (``ru_maxrss``) stays under 1 GiB.

Recordings (a span of two billion frames, 64 MiB of comment lines), a replay episode's state,
a model zip's unused members, ``--timesteps`` and a shield horizon. No wall-time asserts (a loaded
machine would make them flaky; memory is what a late refusal costs).
"""

from __future__ import annotations

import zipfile

import pytest
from crowdnav.agents.sb3.model_zip import ModelZipError, read_model_zip

from tests.agents.test_bounded_totals import _refused, _sb3_zip


def test_from_recording_refuses_frames_two_billion_apart_in_one_line_under_1_gib(tmp_path):
    (tmp_path / "far.txt").write_text("0 1 0 0\n10 1 1 0\n20 1 2 0\n30 1 3 0\n2000000010 1 4 0\n")
    error = _refused("scenario", "from-recording", str(tmp_path / "far.txt"))
    assert "far.txt: spans 8e+07 s, 400,000,003 time steps of 0.2 s, more than 20,000,000" in error


def test_from_recording_refuses_64_mib_of_comment_lines_in_one_line_under_1_gib(tmp_path):
    path = tmp_path / "comments.txt"
    with path.open("wb") as out:
        for _ in range(64):
            out.write(b"#\n" * (1 << 19))  # 1 MiB of comment lines at a time: 64 MiB in all, the byte bound itself
    error = _refused("scenario", "from-recording", str(path))
    assert "comments.txt:3000001: more than 3,000,000 lines" in error


def test_validate_refuses_a_replay_episode_of_2000_places_over_20000_steps_in_one_line(tmp_path):
    from tests.core.test_bounds_before_allocation import write_big_replay

    scenario = write_big_replay(tmp_path, flow=True)
    error = _refused("render", str(scenario), "--episodes", "1", "--out", str(tmp_path / "video"))
    assert "big_replay.yaml:4" in error and "40,002,000 (place, step) positions" in error


def _with_members(path, names, mib: int = 500):
    """``path`` (an SB3 zip) with members ``names`` added, ``mib`` MiB of zeros each: about 1 MB on disk."""
    chunk = bytes(1 << 20)
    with zipfile.ZipFile(path, "a", zipfile.ZIP_DEFLATED, compresslevel=1) as archive:
        for name in names:
            with archive.open(name, "w", force_zip64=True) as member:
                for _ in range(mib):
                    member.write(chunk)
    return path


def test_evaluate_refuses_a_zip_with_two_500_mib_members_sb3_never_writes_before_reading_them(tmp_path):
    path = _with_members(_sb3_zip(tmp_path / "model.zip", lambda data: None), ["junk_a.pth", "junk_b.pth"])
    assert path.stat().st_size < 10 << 20
    error = _refused("evaluate", str(path), "--scenario", "open_space", "--modalities", "goal", "--out", str(tmp_path / "out"))
    assert "entry 'junk_a.pth' is not one an SB3 model zip holds" in error and "refused before anything is read" in error


def test_a_policy_read_from_a_zip_never_decompresses_its_unused_members(tmp_path, monkeypatch):
    path = _with_members(_sb3_zip(tmp_path / "model.zip", lambda data: None), ["actor.optimizer.pth"], mib=8)
    opened: list[str] = []
    real_read = zipfile.ZipFile.read
    monkeypatch.setattr(zipfile.ZipFile, "read", lambda self, name, pwd=None: opened.append(name) or real_read(self, name, pwd))
    model = read_model_zip(path, read=("policy",))
    assert sorted(opened) == ["data", "policy.pth"] and set(model.parameters) == {"policy"}
    with pytest.raises(ModelZipError, match=r"actor.optimizer.pth holds more than tensors"):  # read when asked: zeros
        read_model_zip(path)


def test_train_refuses_timesteps_beyond_the_bound_in_one_line(tmp_path):
    error = _refused("train", "--timesteps", "100000000000", "--out", str(tmp_path / "run"))
    assert "timesteps: expected an integer <= 1000000000, got 100000000000" in error
    assert not (tmp_path / "run").exists()


def test_train_refuses_a_shield_horizon_of_1e300_in_one_line_naming_the_config(tmp_path):
    config = tmp_path / "shield.yaml"
    config.write_text("shield: {horizon: 1e300}\nepisodes: 1\nnum_envs: 1\n")
    error = _refused("train", "--config", str(config), "--out", str(tmp_path / "run"))
    assert "shield.yaml:1: shield: horizon 1e+300 s" in error and "over the limit of 4,000,000 cells" in error
    assert not (tmp_path / "run").exists()


def test_a_trusted_load_checks_the_zip_members_before_sb3_decompresses_them(tmp_path, monkeypatch):
    from crowdnav.agents.runs import checkpoint

    path = _with_members(_sb3_zip(tmp_path / "model.zip", lambda data: None), ["junk.pth"], mib=1)
    checkpoint.check_model_zip(_sb3_zip(tmp_path / "clean.zip", lambda data: None))  # what SB3 writes passes
    monkeypatch.setattr(checkpoint, "find_checkpoint", lambda _: tmp_path)
    monkeypatch.setattr(checkpoint, "MODEL_FILE", path.name)
    monkeypatch.setattr(checkpoint, "read_policy_info", lambda _: {"algo": "ppo"})
    with pytest.raises(ModelZipError, match=r"entry 'junk.pth' is not one an SB3 model zip holds"):
        checkpoint.load_model(tmp_path)
