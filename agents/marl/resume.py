"""Exact resume of shared robot training (``agents: robots``): the checkpoint at a PPO rollout's end, and its way back.

The robots' vector env (:class:`crowdnav.agents.marl.vec_env.RobotsVecEnv`) keeps each world's episode
counters and the network's actions since each world's reset, and an episode's only randomness is the
simulator's generator seeded at reset. So a run is stored
as a single-robot on-policy run was before its checkpoints stored world states (format 1 of
:mod:`crowdnav.agents.runs.resume_worlds`: each world's actions, replayed), when a rollout is
complete and before SB3 trains on it:

* ``model.zip`` (parameters and optimizer) and ``training_state.json`` (SB3's counters and every
  random stream: torch, numpy, Python), written by :func:`crowdnav.agents.runs.checkpoint.save_checkpoint`;
* ``robots_state.npz`` (:data:`STATE_FILE`): the collected rollout, the last observation and
  episode starts, the episode log's running return and length per robot row, and each world as
  its episode counters and every robot's actions since that episode's reset.

A resumed run rebuilds each world by resetting it with its episode's seed and replaying the
actions (:meth:`RobotsVecEnv.restore_worlds`; the rebuilt observation must equal the stored one, or the resume is refused), puts the
rollout back, takes the update the checkpoint preceded, then collects as the uninterrupted run
did: the same episodes and the same weights, bit for bit, wherever the run was killed.

The folder is built whole in a staging folder beside ``checkpoint/`` (the checkpoint, then the
state) and swapped in as every checkpoint is (:func:`crowdnav.files.swap_folder`), so a kill leaves
a complete checkpoint for :func:`crowdnav.agents.runs.folder.recover_checkpoint` to pick.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from crowdnav.agents.marl.vec_env import RobotsVecEnv
from crowdnav.agents.runs.checkpoint import save_checkpoint
from crowdnav.agents.runs.resume_state import _ROLLOUT, ResumeStateError, _fill, _position, _read_npz, _write_npz

from crowdnav.files import discard_leftovers, staging_beside, swap_folder

STATE_FILE = "robots_state.npz"
"""The rollout and worlds of a resumable shared robot checkpoint."""


def save_resumable(model: Any, folder: Path, info: Mapping[str, Any], vec: RobotsVecEnv, rows: Mapping[str, np.ndarray]) -> None:
    """Write the resumable checkpoint ``folder`` (module docstring); ``rows``: the episode log's per-row running sums."""
    discard_leftovers(folder)  # a killed save's copies (links removed, not followed)
    staging = staging_beside(folder)
    save_checkpoint(model, staging, info, rng_state=True)
    _save_state(staging / STATE_FILE, model, vec, rows)
    swap_folder(staging, folder)  # only now complete: recover_checkpoint never picks a staging folder still being written


def _save_state(path: Path, model: Any, vec: RobotsVecEnv, rows: Mapping[str, np.ndarray]) -> None:
    buffer = model.rollout_buffer
    actions, lengths = vec.episode_actions()
    arrays = {"last_obs": np.asarray(model._last_obs), "last_episode_starts": np.asarray(model._last_episode_starts),
              "rollout/observations": buffer.observations, **{f"rollout/{name}": getattr(buffer, name) for name in _ROLLOUT},
              "worlds/actions": actions, "worlds/lengths": lengths, **{f"log/{key}": value for key, value in rows.items()}}
    meta = {"rollout": {"pos": int(buffer.pos), "full": bool(buffer.full)},
            "worlds": [{"first_episode": first, "played": played} for first, played in vec.episode_counters()]}
    _write_npz(path, arrays, meta)


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
    arrays, meta = _read_npz(path)
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
    _replay_worlds(path, vec, arrays, meta, last_obs)
    model._last_obs, model._last_episode_starts = last_obs, starts


def _replay_worlds(path: Path, vec: RobotsVecEnv, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any],
                   last_obs: np.ndarray) -> None:
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
    rebuilt = vec.restore_worlds(pairs, actions, lengths)
    for w in range(len(worlds)):
        if not np.array_equal(rebuilt[w * robots: (w + 1) * robots], last_obs[w * robots: (w + 1) * robots]):
            raise ResumeStateError(f"{path}: world {w} replayed to another observation than the one stored; the scenario or "
                                   "crowdnav changed since the checkpoint (resume with the version that wrote it)")


def pending_update(model: Any) -> Callable[[], None]:
    """The update the checkpoint preceded, as SB3's learning loop takes it after a rollout (run it at the start of ``learn``)."""
    def update() -> None:
        model._update_current_progress_remaining(model.num_timesteps, model._total_timesteps)
        model.train()
    return update
