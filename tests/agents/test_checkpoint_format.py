"""Checkpoint files carry a format version; a newer one (or another format) is refused in one line, an older-layout file still loads."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from crowdnav.agents.runs.checkpoint import POLICY_FORMAT, read_policy_info, save_checkpoint
from crowdnav.agents.runs.resume_state import (
    REPLAY_ARRAYS,
    RESUME_FORMAT,
    ROLLOUT_FORMAT,
    STATE_FILE,
    ResumeStateError,
    _read_npz,
    _write_npz,
    check_format,
    restore_training_state,
)


def _newer(expected: str) -> str:
    name, _, version = expected.rpartition("/")
    return f"{name}/{int(version) + 1}"


def test_check_format_accepts_its_own_and_names_a_newer_version() -> None:
    check_format(RESUME_FORMAT, RESUME_FORMAT)
    with pytest.raises(ValueError, match="newer crowdnav") as newer:
        check_format(_newer(RESUME_FORMAT), RESUME_FORMAT)
    assert "\n" not in str(newer.value) and "upgrade crowdnav" in str(newer.value)
    for other in (None, 3, "crowdnav-policy/1", "crowdnav-resume/x", "crowdnav-resume/0"):
        with pytest.raises(ValueError, match="expected 'crowdnav-resume/1'"):
            check_format(other, RESUME_FORMAT)


def test_policy_json_of_a_newer_format_is_refused_in_one_line(tmp_path: Path) -> None:
    (tmp_path / "policy.json").write_text(json.dumps({"format": _newer(POLICY_FORMAT), "algo": "sac"}), encoding="utf-8")
    with pytest.raises(ValueError, match="newer crowdnav") as error:
        read_policy_info(tmp_path)
    assert str(error.value).count("\n") == 0 and str(tmp_path) in str(error.value)


def test_training_state_of_a_newer_format_is_refused_in_one_line(tmp_path: Path) -> None:
    path = tmp_path / STATE_FILE
    path.write_text(json.dumps({"format": _newer(RESUME_FORMAT), "algorithm": {}, "rng": {}}), encoding="utf-8")
    with pytest.raises(ResumeStateError, match="newer crowdnav") as error:
        restore_training_state(None, path)  # refused before the model is touched
    assert "\n" not in str(error.value)


def test_npz_meta_carries_the_format_and_files_without_one_still_load(tmp_path: Path) -> None:
    path = tmp_path / "state.npz"
    _write_npz(path, {"a": np.arange(3)}, {"pos": 2})
    with np.load(path) as archive:
        assert json.loads(str(archive["meta.json"]))["format"] == RESUME_FORMAT
    arrays, meta = _read_npz(path)
    assert meta == {"pos": 2} and list(arrays) == ["a"]
    older = tmp_path / "older.npz"  # written before the field existed
    np.savez(older, a=np.arange(3), **{"meta.json": np.array(json.dumps({"pos": 2}))})
    assert _read_npz(older)[1] == {"pos": 2}
    newer = tmp_path / "newer.npz"
    np.savez(newer, a=np.arange(3), **{"meta.json": np.array(json.dumps({"format": _newer(RESUME_FORMAT), "pos": 2}))})
    with pytest.raises(ResumeStateError, match="newer crowdnav"):
        _read_npz(newer)


def test_a_rollout_file_storing_world_states_is_version_2_refused_by_a_reader_of_version_1_and_both_read_by_this_one(tmp_path: Path) -> None:
    assert ROLLOUT_FORMAT == _newer(RESUME_FORMAT)  # its worlds as states (tests/agents/test_resume_states.py)
    states, actions = tmp_path / "states.npz", tmp_path / "actions.npz"
    _write_npz(states, {"a": np.arange(3)}, {"pos": 2}, ROLLOUT_FORMAT)
    _write_npz(actions, {"a": np.arange(3)}, {"pos": 1})
    with pytest.raises(ResumeStateError, match=r"format 'crowdnav-resume/2' is a newer crowdnav's .*: upgrade crowdnav") as older:
        _read_npz(states)  # what crowdnav before world states reads every .npz with
    assert "\n" not in str(older.value)
    assert _read_npz(states, ROLLOUT_FORMAT)[1] == {"pos": 2} and _read_npz(actions, ROLLOUT_FORMAT)[1] == {"pos": 1}
    with pytest.raises(ValueError, match=r"^format 'crowdnav-resume/0', expected 'crowdnav-resume/1' to 'crowdnav-resume/2'$"):
        check_format("crowdnav-resume/0", ROLLOUT_FORMAT, oldest=1)


def test_a_saved_checkpoint_writes_the_format_into_every_file_that_has_one(tmp_path: Path) -> None:
    import gymnasium as gym
    from stable_baselines3 import SAC

    class TinyDictEnv(gym.Env):  # a Dict observation, as crowdnav's: the replay buffer stores it per key
        observation_space = gym.spaces.Dict({"state": gym.spaces.Box(-1.0, 1.0, (3,), np.float32)})
        action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

    model = SAC("MultiInputPolicy", TinyDictEnv(), buffer_size=8, learning_starts=0, policy_kwargs={"net_arch": [4]}, device="cpu")
    folder = save_checkpoint(model, tmp_path / "checkpoint", {"algo": "sac", "env": {}}, replay_buffer=True, rng_state=True)
    assert read_policy_info(folder)["format"] == POLICY_FORMAT
    assert json.loads((folder / STATE_FILE).read_text(encoding="utf-8"))["format"] == RESUME_FORMAT
    with np.load(folder / REPLAY_ARRAYS) as archive:
        assert json.loads(str(archive["meta.json"]))["format"] == RESUME_FORMAT
