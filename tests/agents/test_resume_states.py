"""Checkpoints store their worlds mid-episode as world states, and old checkpoints still resume by replay.

A run's ``rollout_state.npz`` (format ``crowdnav-resume/2``, kind "states") holds every world's state as arrays and
JSON, no actions; resumed from it, the run is the uninterrupted run bit for bit (as the other resume tests, which
take this path too, check for every algorithm). A format-1 checkpoint (kind "vector", each world's actions since its
reset, written here by the recording session every run used to be) still resumes by replaying them, bit for bit. A
state that is damaged or does not fit the run is refused in one line naming what.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from crowdnav.agents import ConfigError, train
from crowdnav.agents.runs.folder import checkpoint_dir
from crowdnav.agents.runs.resume_state import RESUME_FORMAT, ROLLOUT_ARRAYS, ROLLOUT_FORMAT
from crowdnav.agents.sb3.session import TrainingSession
from crowdnav.agents.training.config import config_from_mapping

from tests.agents.format1 import RecordingSession, mid_episode, rollout_file, write_rollout_file
from tests.agents.test_training_batched import WORLDS, batched_config


class Stopped(Exception):
    """Stands for a kill right after a checkpoint."""


def _episodes(result) -> list[tuple]:
    return [(r.episode, r.seed, r.outcome, r.reward, r.length, r.timesteps) for r in result.records]


def _weights(result) -> list[bytes]:
    return [p.detach().numpy().tobytes() for p in result.model.policy.parameters()]


def _stopped(out: Path, session: type[TrainingSession] = TrainingSession) -> int:
    """Train PPO in 4 worlds into ``out`` until the first checkpoint that holds a world mid-episode; its episode count."""
    config = config_from_mapping(batched_config(out, "ppo", episodes=12))
    stopped_at = []

    def stop(episodes: int) -> None:
        if mid_episode(checkpoint_dir(out) / ROLLOUT_ARRAYS):
            stopped_at.append(episodes)
            raise Stopped

    with pytest.raises(Stopped):
        session(config, False, stop).run()
    return stopped_at[0]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The uninterrupted run, and the same run stopped after a checkpoint with worlds mid-episode (its folder, its count)."""
    root = tmp_path_factory.mktemp("states")
    whole = train(batched_config(root / "whole", "ppo", episodes=12))
    return whole, root / "stopped", _stopped(root / "stopped")


def test_a_checkpoint_stores_its_worlds_as_states_and_resumes_from_them_bit_for_bit(runs, tmp_path):
    whole, stopped, episodes = runs
    arrays, meta = rollout_file(checkpoint_dir(stopped) / ROLLOUT_ARRAYS)
    worlds = meta["worlds"]
    assert meta["format"] == ROLLOUT_FORMAT and worlds["kind"] == "states" and len(_description(arrays)) == WORLDS
    assert "worlds/actions" not in arrays and "worlds/lengths" not in arrays  # nothing recorded the steps
    assert arrays["worlds/0/world/episode/state/positions"].dtype == np.complex128
    assert arrays["worlds/episode_lengths"].max() > 0
    out = tmp_path / "run"
    shutil.copytree(stopped, out)
    resumed = train(batched_config(out, "ppo", episodes=12), resume=True)
    assert resumed.records and _episodes(resumed) == _episodes(whole)[episodes:]
    assert _weights(resumed) == _weights(whole)


def test_a_format_1_checkpoint_resumes_by_replaying_its_worlds_actions_bit_for_bit(runs, tmp_path):
    whole = runs[0]
    episodes = _stopped(tmp_path, RecordingSession)
    arrays, meta = rollout_file(checkpoint_dir(tmp_path) / ROLLOUT_ARRAYS)
    assert meta["format"] == RESUME_FORMAT and meta["worlds"]["kind"] == "vector" and "worlds/states.json" not in arrays
    assert arrays["worlds/lengths"].max() > 0 and arrays["worlds/actions"].shape[0] == WORLDS
    kinds = []

    def stored(_: int) -> None:  # the resumed run's own checkpoints store states (its final one keeps no worlds)
        path = checkpoint_dir(tmp_path) / ROLLOUT_ARRAYS
        if path.is_file():
            arrays, meta = rollout_file(path)
            kinds.append((meta["format"], meta["worlds"]["kind"], "worlds/actions" in arrays))

    resumed = train(batched_config(tmp_path, "ppo", episodes=12), resume=True, on_checkpoint=stored)  # today's session: replayed
    assert resumed.records and _episodes(resumed) == _episodes(whole)[episodes:]
    assert _weights(resumed) == _weights(whole)
    assert kinds and set(kinds) == {(ROLLOUT_FORMAT, "states", False)}


def _description(arrays: dict) -> list:
    return json.loads(arrays["worlds/states.json"].tobytes().decode("utf-8"))


def _describe(arrays: dict, change) -> None:
    """Change the worlds' description (``change(described)``) and store it again."""
    described = _description(arrays)
    change(described)
    arrays["worlds/states.json"] = np.frombuffer(json.dumps(described).encode("utf-8"), dtype=np.uint8)


def _state_of(described: list, world: int) -> dict:
    return described[world]["fields"]["world"]["fields"]


def _shorter_goals(arrays, meta):
    arrays["worlds/1/world/episode/state/human_goals"] = arrays["worlds/1/world/episode/state/human_goals"][:-1]


def _single_precision(arrays, meta):
    arrays["worlds/0/world/episode/state/positions"] = arrays["worlds/0/world/episode/state/positions"].astype(np.complex64)


def _robot_moved(arrays, meta):
    positions = arrays["worlds/2/world/episode/state/positions"]
    positions[0] += 0.25


def _missing(arrays, meta):
    del arrays["worlds/3/world/episode/state/velocities"]


def _other_scenario(arrays, meta):
    _describe(arrays, lambda described: _state_of(described, 0).update(scenario="cafe"))


def _newer_version(arrays, meta):
    _describe(arrays, lambda described: _state_of(described, 2).update(version=2))


def _one_world_less(arrays, meta):
    _describe(arrays, lambda described: described.pop())


def _not_a_state(arrays, meta):
    _describe(arrays, lambda described: _state_of(described, 1).update(rewards={"pickle": "..."}))


def _not_json(arrays, meta):
    arrays["worlds/states.json"] = arrays["worlds/states.json"][:-3]


@pytest.mark.parametrize(("damage", "refusal"), [
    (_shorter_goals, r"worlds/1/world/episode/state/human_goals: complex128\(2,\), expected \(3,\) for 3 humans"),
    (_single_precision, r"worlds/0/world/episode/state/positions: complex64\(4,\) stored, the world it loads into has complex128\(4,\)"),
    (_robot_moved, r"loading its worlds' states does not give the observation it holds"),
    (_missing, r"worlds/3/world/episode/state/velocities: its array is missing"),
    (_other_scenario, r"worlds/0: a world state of scenario 'cafe' cannot load into a world of scenario 'open_space'"),
    (_newer_version, r"worlds/2: a world state of version 2 cannot load: this crowdnav's world states are version 1"),
    (_one_world_less, r"worlds: 3 worlds stored, expected 4 worlds"),
    (_not_a_state, r"worlds/1/world/rewards: \"\{'pickle': '...'\}\" is not a part of a world state"),
    (_not_json, r"worlds/states\.json: not JSON \("),
], ids=["shape", "dtype", "value", "missing", "scenario", "version", "count", "foreign", "cut"])
def test_a_damaged_or_mismatched_world_state_is_refused_in_one_line(runs, tmp_path, damage, refusal):
    out = tmp_path / "run"
    shutil.copytree(runs[1], out)
    path = checkpoint_dir(out) / ROLLOUT_ARRAYS
    arrays, meta = rollout_file(path)
    damage(arrays, meta)
    write_rollout_file(path, arrays, meta)
    with pytest.raises(ConfigError, match=r"^cannot resume: .*rollout_state\.npz: .*" + refusal) as refused:
        train(batched_config(out, "ppo", episodes=12), resume=True)
    assert "\n" not in str(refused.value) and str(refused.value).endswith("to resume with new episodes in every world")
