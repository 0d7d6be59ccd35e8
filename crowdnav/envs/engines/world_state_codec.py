"""World states as arrays and JSON: how a checkpoint stores its worlds without pickle.

:func:`to_arrays` turns :class:`crowdnav.envs.engines.world_state.VectorWorldState` s into named arrays (for an ``.npz``
written with ``allow_pickle=False``) and :func:`from_arrays` builds them back, equal bit for bit
(tests/core/test_world_state_codec.py: every library scenario, both engines, the tracker profiles, ORCA, reacting
recorded crowds, several robots). World ``i``'s arrays are named ``<prefix>/<i>/<path>``, ``<path>`` the attribute
path inside its state (``world/episode/state/positions``, ``world/tracker/measured``,
``world/episode/crowd/replay/reacting``, ``world/env/observation/lidar``); ``<prefix>/states.json`` (UTF-8 bytes as
uint8) is the list of the worlds' descriptions (:func:`encode_states` / :func:`decode_states` give and take them
apart from the arrays), each the state's tree:

* a state's dataclass (:class:`~crowdnav.envs.engines.world_state.VectorWorldState`, ``WorldState``, ``EnvState``,
  :class:`~crowdnav.sim.episode_state.EpisodeState`, :class:`~crowdnav.sim.state.SimState`,
  :class:`~crowdnav.sim.robots.TeamState`): ``{"object": class name, "fields": {name: node}}``;
* a numpy array: ``{"array": path}``, a numpy scalar: ``{"numpy": path}`` (a 0-d array, read back as the same scalar
  type), both in the arrays with their dtype;
* a complex number: ``{"complex": [real, imag]}``; a dict (text keys): ``{"dict": {key: node}}``; a tuple or list:
  ``{"tuple": [...]}`` / ``{"list": [...]}``;
* None, a bool, an int (the generator's 128-bit state as it is), a float (written as its shortest repr: read back
  exactly) or a text: itself.

So whatever a world state holds is stored, and a part that is none of these (an object of a model's own) is refused
when written, naming it: a crowd model's :meth:`~crowdnav.crowd.base.CrowdModel.episode_state` holds arrays and JSON
scalars only. Reading checks what it builds: the classes and their fields, the episode state's arrays (``(n+1,)`` for
the agents, ``(n,)`` per human), and, given ``like`` (states of the worlds they will load into, e.g. just reset), every
part against it: the same classes, keys and scalar types, arrays of the same dtype and shape (the episode state's: the
same dtype, its crowd size its own), then the world key (:func:`crowdnav.envs.engines.world_state.check_state`: scenario,
settings, robots, version). A damaged or foreign description is a :class:`WorldStateFileError` in one line, naming
the world and the part.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from crowdnav.envs.engines.world_state import WORLD_STATE_VERSION, EnvState, VectorWorldState, WorldKey, WorldState, check_state
from crowdnav.errors import CrowdNavError
from crowdnav.sim.episode_state import EpisodeState
from crowdnav.sim.robots import TeamState
from crowdnav.sim.state import ONE_WORLD_SCALARS, SimState

CLASSES: dict[str, type] = {cls.__name__: cls for cls in (VectorWorldState, WorldState, EnvState, EpisodeState, SimState, TeamState)}
"""The dataclasses a world state is made of, by the name its description gives."""
_AGENT_FIELDS = frozenset({"positions", "velocities"})
"""The episode state's arrays with the robot first, (n+1,); its other arrays are per human, (n,)."""
_TAGS = ("object", "array", "numpy", "complex", "dict", "tuple", "list")


class WorldStateFileError(CrowdNavError, ValueError):
    """A stored world state that cannot be read back or does not fit the worlds it would load into; one line."""


DESCRIPTION = "states.json"
"""The name (after the prefix) of the array holding the worlds' descriptions, JSON as UTF-8 bytes."""


def to_arrays(states: Sequence[VectorWorldState], prefix: str = "worlds") -> dict[str, np.ndarray]:
    """Every world's arrays (:func:`encode_states`) and ``<prefix>/states.json``, their descriptions."""
    arrays, described = encode_states(states, prefix)
    text = json.dumps(described, separators=(",", ":"))
    arrays[f"{prefix}/{DESCRIPTION}"] = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
    return arrays


def from_arrays(arrays: Mapping[str, np.ndarray], prefix: str = "worlds", like: Sequence[VectorWorldState] | None = None
                ) -> list[VectorWorldState]:
    """The states :func:`to_arrays` wrote (``like``: as :func:`decode_states`); a WorldStateFileError in one line."""
    text = arrays.get(f"{prefix}/{DESCRIPTION}")
    if text is None or text.dtype != np.uint8 or text.ndim != 1:
        raise WorldStateFileError(f"{prefix}/{DESCRIPTION}: {'missing' if text is None else _describe(text)}, expected JSON as uint8 bytes")
    try:
        described = json.loads(text.tobytes().decode("utf-8"))
    except (ValueError, RecursionError) as error:  # (UnicodeDecodeError and JSONDecodeError are ValueErrors)
        raise WorldStateFileError(f"{prefix}/{DESCRIPTION}: not JSON ({str(error).splitlines()[0][:100]})") from None
    return decode_states(arrays, described, prefix, like)


# ------------------------------------------------------------------ writing

def encode_states(states: Sequence[VectorWorldState], prefix: str = "worlds") -> tuple[dict[str, np.ndarray], list[Any]]:
    """(arrays, descriptions): world ``i``'s arrays under ``<prefix>/<i>/``, its description (JSON-able) ``descriptions[i]``.

    The arrays are the states' own (not copied: write them before the states change). A part that is not plain data
    (module docstring) is a TypeError naming it.
    """
    arrays: dict[str, np.ndarray] = {}
    described = []
    for i, state in enumerate(states):
        if not isinstance(state, VectorWorldState):
            raise TypeError(f"world {i}: expected a VectorWorldState (CrowdNavVectorEnv.snapshot), got {type(state).__name__}")
        own: dict[str, np.ndarray] = {}
        described.append(_encode(state, "", own))
        arrays.update({f"{prefix}/{i}/{path}": values for path, values in own.items()})
    return arrays, described


def _encode(value: Any, path: str, arrays: dict[str, np.ndarray]) -> Any:
    if dataclasses.is_dataclass(value) and CLASSES.get(type(value).__name__) is type(value):
        return {"object": type(value).__name__,
                "fields": {field.name: _encode(getattr(value, field.name), _join(path, field.name), arrays)
                           for field in dataclasses.fields(value)}}
    if isinstance(value, (np.ndarray, np.generic)):
        values = np.asarray(value)
        if values.dtype.hasobject or values.dtype.kind not in "biufcSU":
            raise TypeError(f"{path}: an array of {values.dtype} cannot be stored without pickle")
        if path in arrays:
            raise TypeError(f"{path}: two parts of the state have this name")
        arrays[path] = value if isinstance(value, np.ndarray) else values
        return {"array" if isinstance(value, np.ndarray) else "numpy": path}
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, complex):
        return {"complex": [value.real, value.imag]}
    if isinstance(value, dict):
        if not all(isinstance(key, str) for key in value):
            raise TypeError(f"{path or 'the state'}: a dict's keys must be texts to be stored")
        return {"dict": {key: _encode(item, _join(path, key), arrays) for key, item in value.items()}}
    if isinstance(value, (tuple, list)):
        return {"tuple" if isinstance(value, tuple) else "list": [_encode(item, _join(path, str(j)), arrays) for j, item in enumerate(value)]}
    raise TypeError(f"{path or 'the state'}: a value of type {type(value).__name__} cannot be stored (a world state holds arrays, numbers, "
                    "texts, None, dicts and tuples: a crowd model's episode_state too)")


def _join(path: str, name: str) -> str:
    return f"{path}/{name}" if path else name


# ------------------------------------------------------------------ reading

def decode_states(arrays: Mapping[str, np.ndarray], described: object, prefix: str = "worlds",
                  like: Sequence[VectorWorldState] | None = None) -> list[VectorWorldState]:
    """The states :func:`encode_states` wrote (``like``: the states of the worlds they will load into, checked against;
    module docstring). A WorldStateFileError in one line names what does not fit."""
    if not isinstance(described, list) or (like is not None and len(described) != len(like)):
        count = f"{len(described)} worlds" if isinstance(described, list) else f"a {type(described).__name__}"
        raise WorldStateFileError(f"{prefix}: {count} stored, expected {'a list' if like is None else f'{len(like)} worlds'}")
    states = []
    for i, node in enumerate(described):
        where = f"{prefix}/{i}"
        version = _peek_version(node)
        if version != WORLD_STATE_VERSION:
            raise WorldStateFileError(f"{where}: a world state of version {str(version)[:20]} cannot load: this crowdnav's world "
                                      f"states are version {WORLD_STATE_VERSION}")
        state = _decode(node, where, where, arrays)
        if not isinstance(state, VectorWorldState):
            raise WorldStateFileError(f"{where}: a {type(state).__name__}, not a VectorWorldState")
        _check_episode(state.world.episode.state, f"{where}/world/episode/state")
        if like is not None:
            target = like[i].world
            try:
                check_state(state.world, WorldKey(target.scenario, target.settings, target.robots))
            except ValueError as error:
                raise WorldStateFileError(f"{where}: {error}") from None
            _compare(state, like[i], where, loose=False)
        states.append(state)
    return states


def _peek_version(node: Any) -> object:
    """The ``version`` a VectorWorldState's description gives its WorldState (read before anything else is built)."""
    try:
        return node["fields"]["world"]["fields"]["version"]
    except (KeyError, TypeError):
        return "none"


def _decode(node: Any, where: str, base: str, arrays: Mapping[str, np.ndarray]) -> Any:
    """The part ``node`` describes (``where``: its name in messages; ``base``: its world's array prefix)."""
    if node is None or isinstance(node, (bool, int, float, str)):
        return node
    if not isinstance(node, dict) or len(node) != (2 if "object" in node else 1) or not any(tag in node for tag in _TAGS):
        raise WorldStateFileError(f"{where}: {str(node)[:60]!r} is not a part of a world state")
    if "object" in node:
        cls, fields = CLASSES.get(node["object"]), node.get("fields")
        if cls is None or not isinstance(fields, dict):
            raise WorldStateFileError(f"{where}: {str(node['object'])[:40]!r} is not a part of a world state")
        names = [field.name for field in dataclasses.fields(cls)]
        if sorted(fields) != sorted(names):
            raise WorldStateFileError(f"{where}: a {cls.__name__} of fields {sorted(fields)}, expected {sorted(names)}")
        return cls(**{name: _decode(fields[name], f"{where}/{name}", base, arrays) for name in names})
    (tag, value), = node.items()
    if tag in ("array", "numpy"):
        stored = arrays.get(f"{base}/{value}") if isinstance(value, str) else None
        if stored is None or (tag == "numpy" and stored.ndim != 0):
            raise WorldStateFileError(f"{where}: its array is missing{' or not 0-d' if tag == 'numpy' else ''}")
        return stored if tag == "array" else stored[()]
    if tag == "complex":
        if not (isinstance(value, list) and len(value) == 2 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
            raise WorldStateFileError(f"{where}: {str(value)[:40]!r} is not a complex number")
        return complex(value[0], value[1])
    if tag == "dict":
        if not isinstance(value, dict):
            raise WorldStateFileError(f"{where}: a dict that is a {type(value).__name__}")
        return {key: _decode(item, f"{where}/{key}", base, arrays) for key, item in value.items()}
    if not isinstance(value, list):
        raise WorldStateFileError(f"{where}: a {tag} that is a {type(value).__name__}")
    items = [_decode(item, f"{where}/{j}", base, arrays) for j, item in enumerate(value)]
    return tuple(items) if tag == "tuple" else items


def _check_episode(state: Any, where: str) -> None:
    """The episode state's arrays: one dimension, (n+1,) for the agents and (n,) per human; its scalars numbers."""
    if not isinstance(state, SimState):
        raise WorldStateFileError(f"{where}: a {type(state).__name__}, not a SimState")
    n = np.shape(state.positions)[0] - 1 if np.ndim(state.positions) == 1 else -1
    for field in dataclasses.fields(state):
        value = getattr(state, field.name)
        if field.name in ONE_WORLD_SCALARS:
            if isinstance(value, bool) or not isinstance(value, (int, float, complex, np.number)):
                raise WorldStateFileError(f"{where}/{field.name}: {str(value)[:40]!r} is not a number")
            continue
        size = n + 1 if field.name in _AGENT_FIELDS else n
        if n < 0 or not isinstance(value, np.ndarray) or value.shape != (size,):
            raise WorldStateFileError(f"{where}/{field.name}: {_describe(value)}, expected ({max(size, 0)},) for "
                                      f"{max(n, 0)} humans")


def _compare(got: Any, like: Any, where: str, loose: bool) -> None:
    """``got`` has ``like``'s structure (``loose``: arrays of the same dtype and dimensions, their sizes their own)."""
    if like is None or got is None:
        return
    if dataclasses.is_dataclass(like):
        _expect(type(got) is type(like), where, got, like)
        for field in dataclasses.fields(like):
            _compare(getattr(got, field.name), getattr(like, field.name), f"{where}/{field.name}", loose or isinstance(like, SimState))
    elif isinstance(like, (np.ndarray, np.generic)):
        fits = type(got) is type(like) and got.dtype == like.dtype and (got.ndim == like.ndim if loose else got.shape == like.shape)
        _expect(fits, where, got, like)
    elif isinstance(like, dict):
        _expect(isinstance(got, dict) and got.keys() == like.keys(), where, got, like)
        for key in like:
            _compare(got[key], like[key], f"{where}/{key}", loose)
    elif isinstance(like, (tuple, list)):
        _expect(type(got) is type(like) and len(got) == len(like), where, got, like)
        for j, (a, b) in enumerate(zip(got, like, strict=True)):
            _compare(a, b, f"{where}/{j}", loose)
    else:
        _expect(type(got) is type(like), where, got, like)


def _expect(fits: bool, where: str, got: Any, like: Any) -> None:
    if not fits:
        raise WorldStateFileError(f"{where}: {_describe(got)} stored, the world it loads into has {_describe(like)}")


def _describe(value: Any) -> str:
    if isinstance(value, (np.ndarray, np.generic)):
        return f"{value.dtype}{value.shape}" if isinstance(value, np.ndarray) else f"a {value.dtype} scalar"
    if isinstance(value, dict):
        return f"keys {sorted(value)[:8]}"
    if isinstance(value, (tuple, list)):
        return f"a {type(value).__name__} of {len(value)}"
    return f"a {type(value).__name__}"
