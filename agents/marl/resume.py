"""Exact resume of shared robot training (``agents: robots``): the checkpoint at a PPO rollout's end, and its way back.

A run is stored when a rollout is complete and before SB3 trains on it:

* ``model.zip`` (parameters and optimizer) and ``training_state.json`` (SB3's counters and every
  random stream: torch, numpy, Python), written by :func:`crowdnav.agents.runs.checkpoint.save_checkpoint`;
* ``robots_state.npz`` (:data:`STATE_FILE`, format :data:`STATES_FORMAT`, kind "states"): the collected rollout, the
  last observation and episode starts, the episode log's running return and length per robot row, and each world
  as its state (:meth:`RobotsVecEnv.snapshot <crowdnav.agents.marl.vec_env.RobotsVecEnv.snapshot>`): the robots
  engine's world state with every robot's last observation (as arrays and JSON, :mod:`crowdnav.envs.engines.world_state_codec`:
  ``worlds/<i>/`` and ``worlds/states.json``), its episode counters, which robots' rows are active
  (``worlds/active``) and the network's actions since its reset (``worlds/actions``, ``worlds/lengths``: the env's
  record of them goes on; nothing replays them).

A resumed run resets each world to its episode's seed (what the stored states are checked against: their parts'
shapes and dtypes, the scenario, settings and robots), loads the states (either engine's into either), puts the
rollout back, takes the update the checkpoint preceded, then collects as the uninterrupted run did: the same
episodes and the same weights, bit for bit, wherever the run was killed. The observation the loaded worlds give
must equal the stored one, or the resume is refused.

Format 1 (no kind; still resumed) stored each world as its counters and every robot's actions since its episode's
reset; the worlds are reset with their episodes' seeds and replay them (:meth:`RobotsVecEnv.restore_worlds`): the
simulator's generator, seeded at reset, is an episode's only randomness.

The folder is built whole in a staging folder beside ``checkpoint/`` (the checkpoint, then the
state) and swapped in as every checkpoint is (:func:`crowdnav.files.swap_folder`), so a kill leaves
a complete checkpoint for :func:`crowdnav.agents.runs.folder.recover_checkpoint` to pick.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from crowdnav.agents.marl.vec_env import RobotsVecEnv, RobotsWorldState
from crowdnav.agents.runs.checkpoint import save_checkpoint
from crowdnav.agents.runs.resume_state import _ROLLOUT, ROLLOUT_FORMAT, ResumeStateError, _fill, _position, _read_npz, _write_npz

from crowdnav.envs.engines.world_state import VectorWorldState
from crowdnav.envs.engines.world_state_codec import from_arrays, to_arrays
from crowdnav.files import discard_leftovers, staging_beside, swap_folder

STATE_FILE = "robots_state.npz"
"""The rollout and worlds of a resumable shared robot checkpoint."""
STATES_FORMAT = ROLLOUT_FORMAT
"""``crowdnav-resume/2``: the worlds stored as states (version 1, their actions to replay, still resumes); an older crowdnav
refuses it in one line, saying to upgrade."""


def save_resumable(model: Any, folder: Path, info: Mapping[str, Any], vec: RobotsVecEnv, rows: Mapping[str, np.ndarray]) -> None:
    """Write the resumable checkpoint ``folder`` (module docstring); ``rows``: the episode log's per-row running sums."""
    discard_leftovers(folder)  # a killed save's copies (links removed, not followed)
    staging = staging_beside(folder)
    save_checkpoint(model, staging, info, rng_state=True)
    _save_state(staging / STATE_FILE, model, vec, rows)
    swap_folder(staging, folder)  # only now complete: recover_checkpoint never picks a staging folder still being written


def _save_state(path: Path, model: Any, vec: RobotsVecEnv, rows: Mapping[str, np.ndarray]) -> None:
    buffer = model.rollout_buffer
    states = [vec.snapshot(world) for world in range(vec.num_worlds)]
    lengths = np.array([len(state.actions) for state in states], dtype=np.int64)
    actions = np.zeros((len(states), int(lengths.max(initial=0)), len(vec.robots), 2), np.float32)
    for world, state in enumerate(states):  # a checkpoint's, once per world
        actions[world, : len(state.actions)] = state.actions
    # the codec's unit is a vector env's world; a robots world never waits for its reset (it resets in the step that ends it)
    worlds = to_arrays([VectorWorldState(state.world, False, False, False) for state in states], "worlds")
    arrays = {"last_obs": np.asarray(model._last_obs), "last_episode_starts": np.asarray(model._last_episode_starts),
              "rollout/observations": buffer.observations, **{f"rollout/{name}": getattr(buffer, name) for name in _ROLLOUT},
              **worlds, "worlds/active": np.stack([state.active for state in states]), "worlds/actions": actions,
              "worlds/lengths": lengths, **{f"log/{key}": value for key, value in rows.items()}}
    meta = {"kind": "states", "rollout": {"pos": int(buffer.pos), "full": bool(buffer.full)},
            "worlds": [{"first_episode": state.first_episode, "played": state.played} for state in states]}
    _write_npz(path, arrays, meta, STATES_FORMAT)


def has_state(folder: Path) -> bool:
    """Whether the checkpoint ``folder`` was taken at a rollout's end (with its worlds), not at the budget's end."""
    return (folder / STATE_FILE).is_file()


def load_state(folder: Path, model: Any, vec: RobotsVecEnv, rows: dict[str, np.ndarray]) -> None:
    """Put back what :func:`save_resumable` stored: rollout, last observation, worlds mid-episode, the log's running sums.

    The model's counters and random streams come from ``training_state.json``
    (:func:`crowdnav.agents.runs.resume_state.restore_training_state`, called by the caller after this).
    ``rows`` (the callback's arrays, built with the run's row count) are filled in place.
    """
    path = folder / STATE_FILE
    arrays, meta = _read_npz(path, STATES_FORMAT)
    buffer = model.rollout_buffer
    _fill(path, buffer, "observations", arrays, "rollout/observations")
    for name in _ROLLOUT:
        _fill(path, buffer, name, arrays, f"rollout/{name}")
    buffer.pos, buffer.full = _position(path, meta.get("rollout", {}), buffer.buffer_size)
    buffer.generator_ready = False
    for key in list(rows):
        _fill(path, rows, key, arrays, f"log/{key}")
    last_obs = arrays.get("last_obs")
    starts = arrays.get("last_episode_starts")
    expected = (model.env.num_envs, *model.observation_space.shape)
    if last_obs is None or last_obs.shape != expected or starts is None or starts.shape != (model.env.num_envs,):
        raise ResumeStateError(f"{path}: its last observation does not fit this run's {model.env.num_envs} robot rows")
    if meta.get("kind") == "states":
        _load_worlds(path, vec, arrays, meta, last_obs)
    else:
        _replay_worlds(path, vec, arrays, meta, last_obs)
    model._last_obs, model._last_episode_starts = last_obs, starts


def _worlds(path: Path, vec: RobotsVecEnv, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any]
            ) -> tuple[list[tuple[int, int]], np.ndarray, np.ndarray]:
    """Each world's episode counters and its actions since its reset ((W, steps, R, 2) and their lengths), checked."""
    worlds = range(vec.num_worlds)
    counters, actions, lengths = meta.get("worlds"), arrays.get("worlds/actions"), arrays.get("worlds/lengths")
    robots = len(vec.robots)
    if not isinstance(counters, list) or len(counters) != len(worlds) or actions is None or lengths is None \
            or actions.shape[0] != len(worlds) or actions.shape[2:] != (robots, 2) or lengths.shape != (len(worlds),) \
            or not all(0 <= length <= actions.shape[1] for length in lengths):
        raise ResumeStateError(f"{path}: its worlds do not fit this run's {len(worlds)} worlds of {robots} robots")
    pairs = []
    for w, counter in enumerate(counters):
        try:
            pairs.append((int(counter["first_episode"]), int(counter["played"])))
        except (KeyError, TypeError, ValueError):
            raise ResumeStateError(f"{path}: world {w}'s episode counters are unreadable") from None
    return pairs, actions, lengths


def _replay_worlds(path: Path, vec: RobotsVecEnv, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any],
                   last_obs: np.ndarray) -> None:
    """Format 1: every world reset to its episode, its actions replayed."""
    pairs, actions, lengths = _worlds(path, vec, arrays, meta)
    _check(path, vec.restore_worlds(pairs, actions, lengths), last_obs, len(vec.robots), "replayed")


def _load_worlds(path: Path, vec: RobotsVecEnv, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any],
                 last_obs: np.ndarray) -> None:
    """Kind "states": every world reset to its episode (what its stored state must fit), then the states loaded."""
    pairs, actions, lengths = _worlds(path, vec, arrays, meta)
    active = arrays.get("worlds/active")
    if active is None or active.shape != (vec.num_worlds, len(vec.robots)) or active.dtype != bool or actions.dtype != np.float32:
        raise ResumeStateError(f"{path}: its worlds do not fit this run's {vec.num_worlds} worlds of {len(vec.robots)} robots")
    try:
        vec.restart(pairs)
        like = [VectorWorldState(vec.snapshot(world).world, False, False, False) for world in range(vec.num_worlds)]
        stored = from_arrays(arrays, "worlds", like)
        if any(state.ended for state in stored):
            raise ValueError("a world stored as waiting for its reset: robot worlds reset in the step that ends them")
        rebuilt = vec.load_worlds([RobotsWorldState(state.world, first, played, active[w], actions[w, : lengths[w]])
                                   for w, (state, (first, played)) in enumerate(zip(stored, pairs, strict=True))])
    except ValueError as error:  # (a WorldStateFileError is one)
        raise ResumeStateError(f"{path}: cannot load its worlds ({str(error).splitlines()[0][:200]})") from None
    _check(path, rebuilt, last_obs, len(vec.robots), "loaded")


def _check(path: Path, rebuilt: np.ndarray, last_obs: np.ndarray, robots: int, how: str) -> None:
    """The rebuilt worlds' rows must be the stored observation's, world by world (the first that differs named)."""
    for w in range(len(rebuilt) // robots):
        if not np.array_equal(rebuilt[w * robots: (w + 1) * robots], last_obs[w * robots: (w + 1) * robots]):
            raise ResumeStateError(f"{path}: world {w} {how} to another observation than the one stored; the scenario or "
                                   "crowdnav changed since the checkpoint, or the file is damaged (resume with the version that wrote it)")


def pending_update(model: Any) -> Callable[[], None]:
    """The update the checkpoint preceded, as SB3's learning loop takes it after a rollout (run it at the start of ``learn``)."""
    def update() -> None:
        model._update_current_progress_remaining(model.num_timesteps, model._total_timesteps)
        model.train()
    return update
