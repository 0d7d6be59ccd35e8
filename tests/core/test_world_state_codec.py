"""World states as arrays and JSON (crowdnav.envs.engines.world_state_codec): written, read back without pickle, equal bit for bit.

Over the cases of tests/core/test_engine_snapshot.py (every library scenario on both engines, the tracker profiles,
ORCA, reacting recorded crowds, several robots, the residual plan with the shield): every world's state goes through
an ``.npz`` read with ``allow_pickle=False`` and comes back equal to the snapshot, types and dtypes included; the
states loaded at once into a fresh env (``load_worlds``) play on as the env they came from. A part that is not plain
data is refused when written, a damaged or foreign description when read, each in one line naming the part.
"""

from __future__ import annotations

import dataclasses
import io
import json
from typing import Any

import numpy as np
import pytest

from crowdnav.envs.engines.world_state_codec import WorldStateFileError, decode_states, encode_states, from_arrays, to_arrays
from crowdnav.envs.vector.env import CrowdNavVectorEnv
from tests.core.test_engine_snapshot import WARM, WORLDS, _actions, _cases, _env, _options, _play, _same


def _through_npz(arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """What a checkpoint file gives back: the arrays through ``numpy.savez`` / ``numpy.load(allow_pickle=False)``."""
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    buffer.seek(0)
    with np.load(buffer, allow_pickle=False) as archive:
        return {name: archive[name] for name in archive.files}


@pytest.mark.parametrize(("name", "options", "engine"), _cases())
def test_every_world_state_comes_back_from_arrays_and_json_bit_for_bit_and_plays_on(name, options, engine, monkeypatch, tmp_path):
    options = _options(options, tmp_path)
    env = _env(name, options, engine, monkeypatch)
    env.reset(seed=7)
    _play(env, 1, _actions(1, WARM))
    states = [env.snapshot(world) for world in range(WORLDS)]
    read = from_arrays(_through_npz(to_arrays(states)), like=states)
    for world, (back, state) in enumerate(zip(read, states, strict=True)):
        assert _same(dataclasses.asdict(back), dataclasses.asdict(state)), f"world {world} came back otherwise"
    fresh = _env(name, options, engine, monkeypatch)
    observations = fresh.load_worlds(read)
    assert _same(observations, {key: values.copy() for key, values in env._observations.items()})
    for rows in _actions(2, 10):  # every world, every step
        assert _same(env.step(rows), fresh.step(rows))


@pytest.fixture
def states() -> list[Any]:
    env = CrowdNavVectorEnv("room_furniture", num_envs=2, modalities=["goal", "humans"], sensors={"tracker": "lidar_tracker"},
                            overrides={"humans.count": 3})
    env.reset(seed=1)
    env.step(np.zeros((2, 2)))
    return [env.snapshot(world) for world in range(2)]


def test_the_arrays_are_named_by_world_and_part_and_the_generator_state_is_json_as_it_is(states):
    arrays, described = encode_states(states, "worlds")
    assert to_arrays(states).keys() == {*arrays, "worlds/states.json"}
    assert json.loads(to_arrays(states)["worlds/states.json"].tobytes()) == described
    assert arrays["worlds/1/world/episode/state/positions"].dtype == np.complex128
    assert arrays["worlds/0/world/tracker/measured"].dtype == np.complex128
    assert arrays["worlds/0/world/tracker/key"].shape == () and arrays["worlds/0/world/tracker/key"].dtype == np.uint64
    rng = described[0]["fields"]["world"]["fields"]["episode"]["fields"]["rng"]["dict"]
    assert rng["state"]["dict"]["state"] == states[0].world.episode.rng["state"]["state"] > 2**64  # a 128-bit integer, exact
    assert json.loads(json.dumps(described)) == described


def _with_crowd_state(state: Any, value: Any) -> Any:
    episode = dataclasses.replace(state.world.episode, crowd={"social_force": {"memory": value}})
    return dataclasses.replace(state, world=dataclasses.replace(state.world, episode=episode))


def test_a_part_that_is_not_plain_data_is_refused_when_written_naming_it(states):
    with pytest.raises(TypeError, match=r"^world/episode/crowd/social_force/memory: a value of type object cannot be stored \(a world state holds"):
        encode_states([_with_crowd_state(states[0], object())])
    with pytest.raises(TypeError, match=r"^world/episode/crowd/social_force/memory: an array of object cannot be stored without pickle$"):
        encode_states([_with_crowd_state(states[0], np.array([None]))])
    with pytest.raises(TypeError, match=r"^world 0: expected a VectorWorldState"):
        encode_states([states[0].world])
    arrays, described = encode_states([_with_crowd_state(states[0], {"window": np.arange(3), "steps": (1, 2.5, None, 1 + 2j)})])
    back = decode_states(arrays, described)[0].world.episode.crowd["social_force"]["memory"]  # arrays and JSON scalars, nested
    assert _same(back, {"window": np.arange(3), "steps": (1, 2.5, None, 1 + 2j)})


def _refused(arrays: dict[str, np.ndarray], described: Any, like: Any = None) -> str:
    with pytest.raises(WorldStateFileError) as error:
        decode_states(arrays, described, like=like)
    assert "\n" not in str(error.value)
    return str(error.value)


def test_a_damaged_or_foreign_description_is_refused_in_one_line_naming_the_part(states):
    arrays, described = encode_states(states)
    assert _refused(arrays, {"states": described}) == "worlds: a dict stored, expected a list"
    tracker = dict(arrays)
    tracker["worlds/1/world/tracker/alive"] = tracker["worlds/1/world/tracker/alive"][:-1]
    assert _refused(tracker, described, like=states).startswith("worlds/1/world/tracker/alive: bool(")
    foreign = json.loads(json.dumps(described))
    foreign[0]["fields"]["world"]["object"] = "Simulator"
    assert _refused(arrays, foreign) == "worlds/0/world: 'Simulator' is not a part of a world state"
    extra = json.loads(json.dumps(described))
    extra[1]["fields"]["world"]["fields"]["episode"]["fields"]["state"]["fields"]["spare"] = 1
    assert _refused(arrays, extra).startswith("worlds/1/world/episode/state: a SimState of fields [")
    heading = json.loads(json.dumps(described))
    heading[0]["fields"]["world"]["fields"]["episode"]["fields"]["state"]["fields"]["robot_heading"] = "north"
    assert _refused(arrays, heading) == "worlds/0/world/episode/state/robot_heading: 'north' is not a number"
    robots = [dataclasses.replace(state, world=dataclasses.replace(state.world, robots=2)) for state in states]
    assert _refused(arrays, described, like=robots).startswith("worlds/0: a world state of 1 robot(s) cannot load into a world of 2")


def test_load_worlds_checks_every_state_before_it_loads_any(states):
    env = CrowdNavVectorEnv("room_furniture", num_envs=2, modalities=["goal", "humans"], sensors={"tracker": "lidar_tracker"},
                            overrides={"humans.count": 3})
    with pytest.raises(ValueError, match=r"^load_worlds: one state per world \(2\), got 1$"):
        env.load_worlds(states[:1])
    other = dataclasses.replace(states[1], world=dataclasses.replace(states[1].world, scenario="cafe"))
    with pytest.raises(ValueError, match="^a world state of scenario 'cafe' cannot load"):
        env.load_worlds([states[0], other])
    with pytest.raises(RuntimeError, match="has not been reset"):  # world 0 was not loaded either
        env.snapshot(0)
    observations = env.load_worlds(states)
    assert set(observations) == {"goal", "humans"} and observations["goal"].shape[0] == 2
