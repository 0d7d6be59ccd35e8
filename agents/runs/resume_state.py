"""A resumable checkpoint's training state, stored without pickle: JSON, ``.npz`` arrays and SB3's tensors.

Resuming a run someone else wrote is then as safe as evaluating it: nothing read here can run
code. The checkpoint folder (:mod:`crowdnav.agents.runs.checkpoint`) holds, next to ``model.zip`` (whose
tensors, optimizers included, are read as in :mod:`crowdnav.agents.sb3.model_zip`):

* ``training_state.json``: the algorithm's counters (steps, updates, episodes, progress, the
  recent episode statistics SB3 logs) and every random stream: torch (its state tensor in
  base64), numpy's global generator, Python's ``random``, the action space's bit generator;
* ``replay_buffer.npz`` (off-policy, ``save_replay_buffer``): the buffer's arrays and its
  write position;
* ``rollout_state.npz`` (on-policy, and batched runs): the collected rollout, the last
  observation, a recurrent policy's LSTM states, and the worlds mid-episode, each as its world
  state (:mod:`crowdnav.envs.engines.world_state`, stored as arrays and JSON by
  :mod:`crowdnav.envs.engines.world_state_codec`), loaded back as it was; files of format 1 stored each
  world as its episode's index (hence its seed) and the actions it had taken since, replayed on
  resume (:mod:`crowdnav.agents.runs.resume_worlds`). Either way the rebuilt observation must
  equal the stored one, or the resume is refused.

Arrays are read with ``numpy.load(..., allow_pickle=False)`` and must have the shapes and
dtypes of the buffers the run's config builds.
"""

from __future__ import annotations

import base64
import json
import random
import zipfile
from collections import deque
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from crowdnav.agents.training.space_checks import action_box
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from crowdnav.errors import CrowdNavError

RESUME_FORMAT = "crowdnav-resume/1"
"""Format of ``training_state.json`` and of the ``.npz`` files' ``meta.json``: a name and a version, raised on a change."""
ROLLOUT_FORMAT = "crowdnav-resume/2"
"""Format of ``rollout_state.npz`` since its worlds are stored as states (version 2; version 1 files, their worlds as actions
to replay, still resume): an older crowdnav refuses it in one line, saying to upgrade."""
STATE_FILE = "training_state.json"
REPLAY_ARRAYS = "replay_buffer.npz"
ROLLOUT_ARRAYS = "rollout_state.npz"
_COUNTERS = ("num_timesteps", "_episode_num", "_n_updates", "_current_progress_remaining")


class ResumeStateError(CrowdNavError, ValueError):
    """A checkpoint's resume files that are missing, damaged or do not fit the run's config; one line."""


def check_format(found: object, expected: str, oldest: int | None = None) -> None:
    """ValueError (one line) unless ``found`` is the ``expected`` format ("name/version"), or (``oldest``) one of its versions
    from ``oldest`` on.

    A newer version of the same format is named as such: the file was written by a newer crowdnav.
    """
    name, _, version = expected.rpartition("/")
    if found == expected:
        return
    if isinstance(found, str) and found.startswith(name + "/"):
        written = found.removeprefix(name + "/")
        if written.isdigit() and int(written) > int(version):
            raise ValueError(f"format {found!r} is a newer crowdnav's (this one reads {expected!r}): upgrade crowdnav to read it")
        if oldest is not None and written.isdigit() and written == str(int(written)) and oldest <= int(written):
            return
    readable = repr(expected) if oldest is None or oldest >= int(version) else f"{f'{name}/{oldest}'!r} to {expected!r}"
    raise ValueError(f"format {str(found)[:80]!r}, expected {readable}")


# ------------------------------------------------------------------ random streams and counters

def rng_state(model: Any) -> dict[str, Any]:
    """The random streams training draws from (torch, numpy, Python, the action space's), as JSON values."""
    import torch

    legacy = np.random.get_state()
    if isinstance(legacy, dict):  # legacy=True (the default) gives the tuple of the global MT19937 stream
        raise TypeError("numpy's global random state is not the legacy tuple")
    kind, keys, position, has_gauss, gauss = legacy
    version, internal, gauss_next = random.getstate()
    space = getattr(model, "action_space", None)
    return {"torch": base64.b64encode(torch.get_rng_state().numpy().tobytes()).decode("ascii"),
            "numpy": [kind, keys.tolist(), int(position), int(has_gauss), float(gauss)],
            "random": [version, list(internal), gauss_next],
            "action_space": space.np_random.bit_generator.state if space is not None and space._np_random is not None else None}


def set_rng_state(model: Any, state: Mapping[str, Any]) -> None:
    """Put back what :func:`rng_state` returned."""
    import torch

    kind, keys, position, has_gauss, gauss = state["numpy"]
    torch.set_rng_state(torch.frombuffer(bytearray(base64.b64decode(state["torch"], validate=True)), dtype=torch.uint8))
    np.random.set_state((str(kind), np.asarray(keys, dtype=np.uint32), int(position), int(has_gauss), float(gauss)))
    version, internal, gauss_next = state["random"]
    random.setstate((int(version), tuple(int(v) for v in internal), None if gauss_next is None else float(gauss_next)))
    if state.get("action_space") is not None:
        model.action_space.np_random.bit_generator.state = state["action_space"]


def save_training_state(model: Any, path: Path, rng: Mapping[str, Any]) -> None:
    """``training_state.json``: the counters a freshly built model lacks, and ``rng`` (plus any extra keys in it)."""
    counters = {name: getattr(model, name) for name in _COUNTERS}
    counters["ep_info_buffer"] = list(model.ep_info_buffer or [])
    counters["ep_success_buffer"] = [bool(value) for value in model.ep_success_buffer or []]
    document = {"format": RESUME_FORMAT, "algorithm": counters, "rng": dict(rng)}
    path.write_text(json.dumps(document), encoding="utf-8")


def restore_training_state(model: Any, path: Path) -> dict[str, Any]:
    """Set the counters and random streams :func:`save_training_state` wrote; returns the rng dict (extra keys included)."""
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
        check_format(document.get("format"), RESUME_FORMAT)
        counters, rng = document["algorithm"], document["rng"]
        for name in _COUNTERS:
            setattr(model, name, type(getattr(model, name))(counters[name]))
        window = model._stats_window_size
        model.ep_info_buffer = deque(({"r": float(e["r"]), "l": int(e["l"]), "t": float(e["t"])} for e in counters["ep_info_buffer"]), maxlen=window)
        model.ep_success_buffer = deque((bool(value) for value in counters["ep_success_buffer"]), maxlen=window)
        set_rng_state(model, rng)
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError, IndexError, RecursionError) as error:
        raise ResumeStateError(f"{path}: cannot resume from it ({str(error).splitlines()[0][:200]})") from None
    return rng


# ------------------------------------------------------------------ arrays

def _write_npz(path: Path, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any], file_format: str = RESUME_FORMAT) -> None:
    # typed as savez's keyword arguments: a dict of arrays alone would be matched against allow_pickle too
    contents: dict[str, Any] = {**arrays, "meta.json": np.array(json.dumps({"format": file_format, **meta}))}
    np.savez(path, **contents)


def _read_npz(path: Path, newest: str = RESUME_FORMAT) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The arrays and ``meta.json`` of a file of format ``newest`` or an older version of it (``meta`` without ``format``)."""
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files}
        meta = json.loads(str(arrays.pop("meta.json")))
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as error:  # BadZipFile: a file cut short
        raise ResumeStateError(f"{path}: cannot read it as arrays ({str(error).splitlines()[0][:200]})") from None
    if not isinstance(meta, dict):
        raise ResumeStateError(f"{path}: its meta.json is not an object")
    try:  # files written before the field existed have none: the first version
        check_format(meta.pop("format", RESUME_FORMAT), newest, oldest=1)
    except ValueError as error:
        raise ResumeStateError(f"{path}: cannot resume from it ({error})") from None
    return arrays, meta


def _fill(path: Path, target: Any, name: str, arrays: Mapping[str, np.ndarray], key: str) -> None:
    """``target.name = arrays[key]`` (or a dict item), refusing another shape or dtype than the built buffer's."""
    is_dict = isinstance(target, dict)
    current = target[name] if is_dict else getattr(target, name)
    value = arrays.get(key)
    if value is None or value.shape != current.shape or value.dtype != current.dtype:
        found = "nothing" if value is None else f"{value.dtype}{value.shape}"
        raise ResumeStateError(f"{path}: {key} is {found}, the run's config builds {current.dtype}{current.shape}")
    if is_dict:
        target[name] = value
    else:
        setattr(target, name, value)


_REPLAY = ("actions", "rewards", "dones", "timeouts")
_ROLLOUT = ("actions", "rewards", "returns", "episode_starts", "values", "log_probs", "advantages")


def save_replay_buffer(buffer: Any, path: Path) -> None:
    """The replay buffer's arrays and write position as ``.npz``."""
    arrays = {f"observations/{key}": value for key, value in buffer.observations.items()}
    arrays.update({f"next_observations/{key}": value for key, value in buffer.next_observations.items()})
    arrays.update({name: getattr(buffer, name) for name in _REPLAY})
    _write_npz(path, arrays, {"pos": int(buffer.pos), "full": bool(buffer.full)})


def load_replay_buffer(buffer: Any, path: Path) -> None:
    """Fill the run's (freshly built) replay buffer from :func:`save_replay_buffer`'s file."""
    arrays, meta = _read_npz(path)
    for store in ("observations", "next_observations"):
        for key in getattr(buffer, store):
            _fill(path, getattr(buffer, store), key, arrays, f"{store}/{key}")
    for name in _REPLAY:
        _fill(path, buffer, name, arrays, name)
    buffer.pos, buffer.full = _position(path, meta, buffer.buffer_size)


def _position(path: Path, meta: Mapping[str, Any], size: int) -> tuple[int, bool]:
    pos, full = meta.get("pos"), meta.get("full")
    if not isinstance(pos, int) or isinstance(pos, bool) or not 0 <= pos <= size or not isinstance(full, bool):
        raise ResumeStateError(f"{path}: write position {pos!r}/{full!r} outside a buffer of {size}")
    return pos, full


# ------------------------------------------------------------------ worlds mid-episode

class ActionLog(VecEnvWrapper):
    """Records, per world, the actions taken since its episode began: how format-1 checkpoints stored their worlds.

    Vectorized: one array write per step. A world whose episode ended in a step (SB3 resets it in
    the same step) starts again from no actions. Training no longer wraps its env in it (its
    checkpoints store world states, so no step records anything); a run that does (the tests'
    format-1 checkpoints, the published one-world stack) still writes its worlds as actions to replay.
    """

    def __init__(self, venv: VecEnv):
        super().__init__(venv)
        self.actions = np.zeros((self.num_envs, 64, *action_box(self.action_space).shape))
        self.lengths = np.zeros(self.num_envs, dtype=np.int64)

    def reset(self) -> Any:
        self.lengths[:] = 0
        return self.venv.reset()

    def step_async(self, actions: np.ndarray) -> None:
        if self.lengths.max() >= self.actions.shape[1]:  # a longer episode than recorded so far: twice the room
            self.actions = np.concatenate([self.actions, np.zeros_like(self.actions)], axis=1)
        self.actions[np.arange(self.num_envs), self.lengths] = actions  # float64 holds float32 actions exactly
        self.venv.step_async(actions)

    def step_wait(self) -> Any:
        observations, rewards, dones, infos = self.venv.step_wait()
        self.lengths += 1
        self.lengths[dones] = 0
        return observations, rewards, dones, infos
