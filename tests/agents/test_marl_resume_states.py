"""Shared robot training (agents: robots) resumes by loading its worlds' states (robots_state.npz format 2): a run stopped
after a checkpoint, its worlds mid-episode, resumes with the weights and episodes of the run never stopped, bit for bit,
with either engine, no action replayed; a checkpoint of format 1 (each world's actions) still resumes by replaying them;
a world's state taken in one engine plays on in the other; a damaged or mismatched file is refused in one line."""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import pytest
from crowdnav.agents import train
from crowdnav.agents.marl import robots as robots_module
from crowdnav.agents.marl.resume import STATE_FILE, STATES_FORMAT
from crowdnav.agents.marl.vec_env import RobotsVecEnv, RobotsWorldState
from crowdnav.agents.runs.resume_state import ResumeStateError
from crowdnav.agents.training.config import config_from_mapping

from crowdnav.envs.engines.robots import SingleRobots
from crowdnav.envs.engines.stacked_robots import StackedRobots
from crowdnav.envs.engines.world_state import VectorWorldState
from crowdnav.envs.engines.world_state_codec import to_arrays
from tests.agents.test_marl import robots_config
from tests.agents.test_marl_resume import Stopped, _episodes, _log, _stop_at, _weights

FIELDS = {"timesteps": 384, "checkpoint_every_steps": 96, "overrides": {"max_steps": 30, "world.boundary_walls": False}}
"""2 worlds x 3 robots, rollouts of 16 world steps, episodes of at most 30 (no walls: a robot may leave the world and end
while its world goes on): the checkpoints fall mid-episode."""


def _read(path: Path) -> tuple[dict[str, np.ndarray], dict]:
    with np.load(path) as archive:
        arrays = dict(archive)
    return arrays, json.loads(str(arrays.pop("meta.json")))


def _write(path: Path, arrays: dict[str, np.ndarray], meta: dict) -> None:
    np.savez(path, **arrays, **{"meta.json": np.array(json.dumps(meta))})


def _as_format_1(path: Path, version: str | None) -> None:
    """The checkpoint's state file as format 1 wrote it: each world's counters and actions, no states (``version``: its meta's
    format field; None: written before the field existed)."""
    arrays, meta = _read(path)
    arrays = {key: value for key, value in arrays.items() if not key.startswith("worlds/") or key in ("worlds/actions", "worlds/lengths")}
    meta = {key: value for key, value in meta.items() if key not in ("format", "kind")}
    _write(path, arrays, meta if version is None else {"format": version, **meta})


def _engine_of_resume(monkeypatch, engine: str) -> None:
    """The resumed run's worlds on ``engine`` (a run builds the stacked one where the scenario stacks, as this one does)."""
    def make(config, first_episode=0):
        vec = RobotsVecEnv.make(config, first_episode, stacked=engine == "stacked")
        assert isinstance(vec.engine, StackedRobots if engine == "stacked" else SingleRobots)
        return vec
    monkeypatch.setattr(robots_module, "make_robots_vec_env", make)


def _replays(monkeypatch) -> list[int]:
    """The longest action replay of each restore_worlds call made from now on."""
    calls: list[int] = []
    restore = RobotsVecEnv.restore_worlds

    def counted(self, counters, actions, lengths):
        calls.append(int(np.max(lengths, initial=0)))
        return restore(self, counters, actions, lengths)
    monkeypatch.setattr(RobotsVecEnv, "restore_worlds", counted)
    return calls


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    out = tmp_path_factory.mktemp("whole") / "run"
    return out, train(robots_config(out, **FIELDS))


def _stopped(tmp_path: Path, after: int = 1) -> tuple[dict, Path]:
    config = robots_config(tmp_path / "stopped", **FIELDS)
    with pytest.raises(Stopped):
        train(config, on_checkpoint=_stop_at(after))
    return config, tmp_path / "stopped" / "checkpoint" / STATE_FILE


def _same_run(resumed, whole, run: Path) -> None:
    out, result = whole
    done = len(_episodes(result)) - len(_episodes(resumed))
    assert 0 <= done < len(_episodes(result)) and _episodes(resumed) == _episodes(result)[done:]
    assert _weights(resumed) == _weights(result)
    assert resumed.model._n_updates == result.model._n_updates and resumed.timesteps == result.timesteps
    assert _log(run) == _log(out)


@pytest.mark.parametrize("engine", ["stacked", "single"])
@pytest.mark.parametrize("after", [1, 3])
def test_a_run_stopped_mid_episode_resumes_from_its_worlds_states_bit_for_bit_on_either_engine(tmp_path, whole, after, engine,
                                                                                                 monkeypatch):
    config, path = _stopped(tmp_path, after)
    arrays, meta = _read(path)
    assert meta["format"] == STATES_FORMAT and meta["kind"] == "states" and "worlds/states.json" in arrays
    assert arrays["worlds/lengths"].min() > 0  # mid-episode
    assert after != 1 or not arrays["worlds/active"].all()  # a robot had ended there, its world going on
    _engine_of_resume(monkeypatch, engine)
    replays = _replays(monkeypatch)
    resumed = train(config, resume=True)
    assert replays == []  # loaded, not replayed
    _same_run(resumed, whole, tmp_path / "stopped")


@pytest.mark.parametrize("version", ["crowdnav-resume/1", None])
def test_a_format_1_checkpoint_still_resumes_by_replaying_its_worlds_bit_for_bit(tmp_path, whole, version, monkeypatch):
    config, path = _stopped(tmp_path)
    _as_format_1(path, version)
    replays = _replays(monkeypatch)
    resumed = train(config, resume=True)
    assert len(replays) == 1 and replays[0] > 0
    _same_run(resumed, whole, tmp_path / "stopped")


@pytest.mark.parametrize(("source", "target"), [("stacked", "single"), ("single", "stacked"), ("stacked", "stacked")])
def test_worlds_snapshot_in_one_engine_play_on_loaded_into_the_other_bit_for_bit(tmp_path, source, target):
    config = config_from_mapping(robots_config(tmp_path / "run", num_envs=3, robot_actions="goal_velocity", overrides={"max_steps": 80}))
    playing, loaded = RobotsVecEnv.make(config, stacked=source == "stacked"), RobotsVecEnv.make(config, 50, stacked=target == "stacked")
    playing.reset()
    loaded.reset()  # other episodes
    rng = np.random.default_rng(2)
    for _ in range(300):  # toward the goals, noisily, past the first episodes, to a step where a robot ended and its world
        # goes on (it leaves the world after this observation) and another robot had left before (its row inactive)
        last, _, dones, infos = playing.step(rng.normal([1.0, 0.0], 0.3, (playing.num_envs, 2)).astype(np.float32))
        going = [info for info, done in zip(infos, dones, strict=True) if not done]
        if min(played for _, played in playing.episode_counters()) >= 2 and any("outcome" in info for info in going) \
                and any(not info["active"] for info in going):
            break
    else:
        pytest.fail("no robot ended while its world went on, another one out already")
    states = pickle.loads(pickle.dumps([playing.snapshot(world) for world in range(playing.num_worlds)]))
    assert len({len(state.actions) for state in states}) > 1
    assert np.array_equal(loaded.load_worlds(states), last)
    for world, state in enumerate(states):  # a snapshot right after the load is the state loaded
        again = loaded.snapshot(world)
        assert (again.first_episode, again.played) == (state.first_episode, state.played)
        assert again.active.tobytes() == state.active.tobytes() and again.actions.tobytes() == state.actions.tobytes()
        assert _bytes(again.world) == _bytes(state.world)
    for _ in range(40):
        move = rng.uniform(-1.0, 1.0, (playing.num_envs, 2)).astype(np.float32)
        expected, got = playing.step(move), loaded.step(move)
        assert all(np.array_equal(mine, theirs) for mine, theirs in zip(got[:3], expected[:3], strict=True))
        assert [sorted(info) for info in got[3]] == [sorted(info) for info in expected[3]]
        assert [info["episode_seed"] for info in got[3]] == [info["episode_seed"] for info in expected[3]]
    assert loaded.episode_counters() == playing.episode_counters()
    assert all(np.array_equal(mine, theirs) for mine, theirs in zip(loaded.episode_actions(), playing.episode_actions(), strict=True))


def _bytes(state) -> dict[str, bytes]:
    return {key: values.tobytes() for key, values in to_arrays([VectorWorldState(state, False, False, False)]).items()}


def _scale(prefix: str):
    def damage(arrays: dict, meta: dict) -> None:
        for key in [key for key in arrays if key.startswith(prefix)]:
            arrays[key] = arrays[key] * 0.5
    return damage


def _cut(key: str):
    def damage(arrays: dict, meta: dict) -> None:
        arrays[key] = arrays[key][:-1]
    return damage


def _drop(key: str):
    def damage(arrays: dict, meta: dict) -> None:
        del arrays[key]
    return damage


def _garble(arrays: dict, meta: dict) -> None:
    arrays["worlds/states.json"] = np.frombuffer(b'[{"object": "WorldState"', dtype=np.uint8)


def _rename(arrays: dict, meta: dict) -> None:
    text = arrays["worlds/states.json"].tobytes()
    arrays["worlds/states.json"] = np.frombuffer(text.replace(b'"robots_crossing_hall"', b'"open_space"'), dtype=np.uint8)


@pytest.mark.parametrize(("damage", "message"), [
    (_scale("worlds/1/world/env/observation/"), "world 1 loaded to another observation than the one stored"),
    (_rename, "cannot load its worlds .worlds/0: a world state of scenario 'open_space' cannot load"),
    (_garble, "cannot load its worlds .worlds/states.json: not JSON"),
    (_cut("worlds/1/world/episode/team/positions"), "cannot load its worlds .worlds/1/world/episode/team/positions"),
    (_drop("worlds/active"), "its worlds do not fit this run's 2 worlds of 3 robots"),
    ("format-1", "world 0 replayed to another observation than the one stored"),
], ids=["observation", "scenario", "description", "team-shape", "no-active", "format-1-actions"])
def test_a_damaged_or_mismatched_state_file_is_refused_in_one_line_naming_it(tmp_path, damage, message):
    config, path = _stopped(tmp_path)
    if damage == "format-1":
        _as_format_1(path, "crowdnav-resume/1")
        damage = _scale("worlds/actions")  # other actions: another world than the stored observation
    arrays, meta = _read(path)
    damage(arrays, meta)
    _write(path, arrays, meta)
    with pytest.raises(ResumeStateError, match=message) as error:
        train(config, resume=True)
    assert "\n" not in str(error.value) and str(path) in str(error.value)


NOT_STATE = "not state"
ATTRIBUTES = {"engine": "world", "first_episode": "first_episode", "played": "played", "episode_seeds": "first_episode, played",
              "_active": "active", "_history": "actions", "_began": "actions (their lengths)", "_steps": "actions (their lengths)",
              "_raw": "world (its observation)", "_actions": "made by each step_async before step_wait reads it",
              **dict.fromkeys(["inputs", "commands", "scenario", "robots", "render_mode", "run_seed", "num_envs", "observation_space",
                               "action_space", "metadata", "reset_infos", "_seeds", "_options"], NOT_STATE)}


def test_every_attribute_of_the_robots_vec_env_is_in_a_world_state_or_said_not_to_be(tmp_path):
    vec = RobotsVecEnv.make(config_from_mapping(robots_config(tmp_path / "run")))
    vec.reset()
    vec.step(np.zeros((vec.num_envs, 2), np.float32))
    assert isinstance(vec.snapshot(0), RobotsWorldState)
    unknown = sorted(set(vars(vec)) - set(ATTRIBUTES))
    assert unknown == [], f"RobotsVecEnv: say whether a RobotsWorldState holds {unknown} (tests/agents/test_marl_resume_states.py)"
