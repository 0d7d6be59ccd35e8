"""``rollout_state.npz``: an interrupted rollout and the worlds mid-episode, as arrays (see :mod:`crowdnav.agents.runs.resume_state`).

A world is stored as its state (format ``crowdnav-resume/2``, kind "states"): the vector env's
:meth:`~crowdnav.envs.vector.env.CrowdNavVectorEnv.snapshot` of it, as arrays and JSON
(:mod:`crowdnav.envs.engines.world_state_codec`: arrays under ``worlds/<i>/``, their description in
``worlds/states.json``), with the episode counter that seeds the later episodes and each
world's return and length so far. A resume resets the worlds to their episodes' seeds (what the
stored states are checked against: their parts' shapes and dtypes, the scenario, settings and
robots), then loads the states (:meth:`~crowdnav.agents.sb3.vec_env.CrowdNavSB3VecEnv.load_worlds`).

Format 1 (kinds "vector" and "single", still resumed) stored each world as the index of the
episode it plays and the actions it took since that episode's reset (recorded by
:class:`~crowdnav.agents.runs.resume_state.ActionLog`); a resume resets it with the episode's seed
and replays the actions: the simulator's generator, seeded at reset, is the episode's only
randomness, so this rebuilds the world bit for bit. Either way the observation the worlds are
rebuilt to must equal the stored last observation, or the resume is refused.

A recurrent policy's memory is stored too: the LSTM states the next rollout starts from (sb3-contrib's
``_last_lstm_states``) and those its rollout buffer holds per step (what its update starts each sequence from).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from crowdnav.agents.runs.resume_state import (
    _ROLLOUT,
    RESUME_FORMAT,
    ROLLOUT_FORMAT,
    ActionLog,
    ResumeStateError,
    _fill,
    _position,
    _read_npz,
    _write_npz,
)
from crowdnav.agents.sb3.vec_env import CrowdNavSB3VecEnv
from crowdnav.agents.training.seeding import train_seed

from crowdnav.envs.engines.world_state_codec import from_arrays, to_arrays

_RECURRENT_ROLLOUT = ("hidden_states_pi", "cell_states_pi", "hidden_states_vf", "cell_states_vf")
"""sb3-contrib's recurrent rollout buffers' LSTM states, one per step (absent from SB3's own buffers)."""


def save_rollout(path: Path, state: Mapping[str, Any]) -> None:
    """Write :meth:`ResumePoint.rollout_state`'s dict: the rollout buffer (on-policy), last observation, worlds, LSTM states."""
    arrays: dict[str, np.ndarray] = {f"last_obs/{key}": value for key, value in _as_dict(state["last_obs"]).items()}
    arrays["last_episode_starts"] = np.asarray(state["last_episode_starts"])
    meta: dict[str, Any] = {"episode_num": int(state.get("episode_num") or 0), "dict_obs": isinstance(state["last_obs"], dict)}
    if state.get("last_original_obs") is not None:  # off-policy: the observation stored in the replay buffer
        arrays.update({f"last_original_obs/{key}": value for key, value in _as_dict(state["last_original_obs"]).items()})
    buffer = state.get("rollout_buffer")
    if buffer is not None:
        arrays.update({f"rollout/observations/{key}": value for key, value in buffer.observations.items()})
        arrays.update({f"rollout/{name}": getattr(buffer, name) for name in (*_ROLLOUT, *_RECURRENT_ROLLOUT) if hasattr(buffer, name)})
        meta["rollout"] = {"pos": int(buffer.pos), "full": bool(buffer.full)}
    if state.get("lstm_states") is not None:
        arrays.update(_lstm_arrays(state["lstm_states"]))
    env = state["env"]
    world_arrays, meta["worlds"] = _recorded_worlds(env) if isinstance(env, ActionLog) else _world_states(env)
    arrays.update(world_arrays)
    _write_npz(path, arrays, meta, RESUME_FORMAT if isinstance(env, ActionLog) else ROLLOUT_FORMAT)


def load_rollout(path: Path, model: Any) -> dict[str, Any]:
    """Fill the model's rollout buffer (if stored), rebuild its env's worlds; returns the state for ``restore_rollout``."""
    arrays, meta = _read_npz(path, ROLLOUT_FORMAT)
    env = model.get_env()
    if not isinstance(_training_env(env), CrowdNavSB3VecEnv):
        raise ResumeStateError(f"{path}: the run's environment is {type(env).__name__}, not crowdnav's training vector env")
    try:
        last_obs, original = (_observation(arrays, prefix, meta["dict_obs"]) for prefix in ("last_obs/", "last_original_obs/"))
        state = {"last_obs": last_obs, "last_original_obs": original, "last_episode_starts": arrays["last_episode_starts"],
                 "episode_num": int(meta["episode_num"])}
        if "rollout" in meta:
            buffer = model.rollout_buffer
            for key in buffer.observations:
                _fill(path, buffer.observations, key, arrays, f"rollout/observations/{key}")
            for name in (*_ROLLOUT, *(name for name in _RECURRENT_ROLLOUT if hasattr(buffer, name))):
                _fill(path, buffer, name, arrays, f"rollout/{name}")
            buffer.pos, buffer.full = _position(path, meta["rollout"], buffer.buffer_size)
            buffer.generator_ready = False
            state["rollout_buffer"] = True
        if getattr(model, "_last_lstm_states", None) is not None:  # a recurrent policy: without its memory the run would differ
            state["lstm_states"] = _lstm_states(path, arrays, model._last_lstm_states)
        _restore_worlds(path, env, arrays, meta["worlds"], state["last_obs"])
    except (KeyError, TypeError, ValueError, IndexError) as error:
        if isinstance(error, ResumeStateError):
            raise
        raise ResumeStateError(f"{path}: cannot resume from it ({str(error).splitlines()[0][:200]})") from None
    return state


def _lstm_arrays(states: Any) -> dict[str, np.ndarray]:
    """sb3-contrib's ``RNNStates`` (actor ``pi`` and critic ``vf``, each a (hidden, cell) pair of tensors) as arrays."""
    return {f"lstm_states/{head}/{i}": tensor.detach().cpu().numpy() for head in ("pi", "vf")
            for i, tensor in enumerate(getattr(states, head))}


def _lstm_states(path: Path, arrays: Mapping[str, np.ndarray], current: Any) -> Any:
    """The stored LSTM states, as tensors shaped and placed like the freshly built model's ``current`` ones."""
    import torch

    heads = {}
    for head in ("pi", "vf"):
        tensors = []
        for i, tensor in enumerate(getattr(current, head)):
            built = {"state": tensor.detach().cpu().numpy()}
            _fill(path, built, "state", arrays, f"lstm_states/{head}/{i}")  # refuses another shape or dtype (or none stored)
            tensors.append(torch.as_tensor(built["state"], device=tensor.device))
        heads[head] = tuple(tensors)
    return type(current)(**heads)


def _observation(arrays: Mapping[str, np.ndarray], prefix: str, is_dict: bool) -> Any:
    found = {key.removeprefix(prefix): value for key, value in arrays.items() if key.startswith(prefix)}
    return (found if is_dict else found[""]) if found else None


def _as_dict(observation: Any) -> dict[str, np.ndarray]:
    return dict(observation) if isinstance(observation, dict) else {"": np.asarray(observation)}


def _training_env(env: Any) -> Any:
    """The training vector env a run collects from (behind an ActionLog where one records its actions)."""
    return env.venv if isinstance(env, ActionLog) else env


def _counter_meta(inner: Any) -> dict[str, Any]:
    if not isinstance(inner, CrowdNavSB3VecEnv) or inner.episode_seeds is None:  # make_vec_env gives it its counter
        raise ResumeStateError(f"cannot store the worlds of {type(inner).__name__}: expected crowdnav's training vector env")
    counter = inner.episode_seeds
    return {"run_seed": counter.run_seed, "next_episode": counter.next_episode,
            "episode_of": [counter.episode_of[i] for i in range(inner.num_envs)],
            "ended_of": {str(k): v for k, v in counter.ended_of.items()}}


def _world_states(inner: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Kind "states": every world's state (arrays under ``worlds/<i>/``), its return and length so far, the episode counter."""
    meta = {"kind": "states", **_counter_meta(inner)}
    arrays = to_arrays([inner.env.snapshot(i) for i in range(inner.num_envs)], "worlds")
    returns, lengths = inner.world_counts()
    arrays.update({"worlds/returns": returns, "worlds/episode_lengths": lengths})
    return arrays, meta


def _recorded_worlds(env: ActionLog) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Kind "vector" (format 1): every world as the actions an ActionLog recorded since its reset, replayed on resume."""
    inner: Any = env.venv
    meta = {"kind": "vector", **_counter_meta(inner)}
    longest = int(env.lengths.max(initial=0))
    returns, lengths = inner.world_counts()
    return {"worlds/actions": env.actions[:, :longest], "worlds/lengths": env.lengths.copy(),
            "worlds/returns": returns, "worlds/episode_lengths": lengths}, meta


def _restore_worlds(path: Path, env: Any, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any], last_obs: Any) -> None:
    inner = _training_env(env)
    n = inner.num_envs
    if meta["kind"] == "states":
        if isinstance(env, ActionLog):
            raise ResumeStateError(f"{path}: its worlds are stored as states; a run recording its worlds' actions cannot continue them")
        observation = _load_states(inner, arrays, meta)
        how = "loading its worlds' states"
    else:
        actions, lengths = arrays["worlds/actions"], arrays["worlds/lengths"]
        if lengths.shape != (n,) or lengths.dtype != np.int64 or actions.shape[:1] != (n,) or actions.shape[2:] != env.action_space.shape \
                or (lengths < 0).any() or lengths.max(initial=0) > actions.shape[1] or not np.isfinite(actions).all():
            raise ResumeStateError(f"{path}: its worlds' actions do not fit the run's {n} worlds")
        if meta["kind"] == "vector":
            episodes = _set_counter(inner, meta)
            observation = inner.restore_worlds(episodes, actions, lengths, arrays["worlds/returns"], arrays["worlds/episode_lengths"])
        elif meta["kind"] == "single" and n == 1:
            observation = _replay_single(inner, actions, lengths, meta)
        else:
            raise ResumeStateError(f"{path}: its worlds are {meta['kind']!r}, the run's config builds {n} worlds")
        if isinstance(env, ActionLog):  # it goes on recording from the replayed actions
            env.actions = np.concatenate([actions, np.zeros((n, max(64, actions.shape[1]), *actions.shape[2:]))], axis=1)
            env.lengths = lengths.copy()
        how = "replaying its worlds' episodes"
    expected = _as_dict(last_obs)
    rebuilt = _as_dict(observation)
    if expected.keys() != rebuilt.keys() or not all(np.array_equal(expected[key], rebuilt[key]) for key in expected):
        raise ResumeStateError(f"{path}: {how} does not give the observation it holds "
                               "(written by another crowdnav version, or damaged); start the run afresh")


def _set_counter(inner: CrowdNavSB3VecEnv, meta: Mapping[str, Any]) -> list[int]:
    """The run's episode counter as the checkpoint left it (the seeds of the worlds' next episodes); returns the episode each
    world plays."""
    counter = inner.episode_seeds
    if counter is None or int(meta["run_seed"]) != counter.run_seed:
        raise ValueError(f"the worlds were seeded by run seed {meta['run_seed']}, the run's config has {getattr(counter, 'run_seed', None)}")
    counter.next_episode = int(meta["next_episode"])
    counter.episode_of = {i: int(episode) for i, episode in enumerate(meta["episode_of"])}
    counter.ended_of = {int(k): int(v) for k, v in meta["ended_of"].items()}
    return [counter.episode_of[i] for i in range(inner.num_envs)]


def _load_states(inner: CrowdNavSB3VecEnv, arrays: Mapping[str, np.ndarray], meta: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """Kind "states": the worlds reset to their episodes (what the stored states must fit), then the states loaded."""
    episodes = _set_counter(inner, meta)
    run_seed = int(meta["run_seed"])  # (the counter's: checked)
    inner.env.reset(seed=[train_seed(run_seed, episode) for episode in episodes])
    like = [inner.env.snapshot(i) for i in range(inner.num_envs)]
    states = from_arrays(arrays, "worlds", like)
    return inner.load_worlds(states, arrays["worlds/returns"], arrays["worlds/episode_lengths"])


def _replay_single(inner: CrowdNavSB3VecEnv, actions: np.ndarray, lengths: np.ndarray, meta: Mapping[str, Any]) -> Any:
    """A ``num_envs: 1`` checkpoint written before every run collected from the vector env (kind "single": a
    ``DummyVecEnv`` of one env, its world stored as the episode it plays, without its return so far).

    Replayed through the one world's own steps, which count the return and length as the single env's ``Monitor``
    did; the episode cannot end within them (it was mid-episode when stored).
    """
    counter = inner.episode_seeds
    if counter is None or int(meta["run_seed"]) != counter.run_seed:
        raise ValueError(f"the world was seeded by run seed {meta['run_seed']}, the run's config has {getattr(counter, 'run_seed', None)}")
    counter.next_episode, counter.episode_of, counter.ended_of = int(meta["episode"]), {}, {}
    observation = inner.reset()  # the stored episode, numbered by the counter
    for action in actions[0, : int(lengths[0])]:
        inner.step_async(action[None])
        observation, _, dones, _ = inner.step_wait()
        if dones[0]:
            raise ValueError("its world's episode ends within the actions it stores")
    return observation
