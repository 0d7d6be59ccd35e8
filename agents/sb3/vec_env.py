"""Stable-Baselines3 collecting from the native vector env: a ``VecEnv`` over :class:`CrowdNavVectorEnv`.

    from crowdnav.agents.sb3.vec_env import CrowdNavSB3VecEnv
    env = CrowdNavSB3VecEnv.make("open_space", num_envs=16, seed=0, modalities=["lidar", "goal"])
    SAC("MultiInputPolicy", env).learn(10_000)

World ``i`` is what SB3's ``DummyVecEnv`` would give for ``Monitor(CrowdNavEnv)`` number ``i``
seeded ``seed + i``: the same observations, rewards, dones and infos, bit for bit (tested), with
SB3's conventions: a finished world is reset in the same step, its last observation in
``infos[i]["terminal_observation"]`` and ``infos[i]["TimeLimit.truncated"]`` set when the time
limit (not an event) ended it; ``infos[i]["episode"]`` (return ``r``, length ``l``, time ``t``)
as SB3's ``Monitor`` writes it, so SB3 logs episode returns. ``scales`` (modality key -> offset,
scale) normalises observations like :class:`crowdnav.agents.training.wrappers.NormalizeObservation`.

For training (:func:`crowdnav.agents.sb3.factory.make_vec_env`): ``episode_seeds`` (an
:class:`~crowdnav.agents.training.seeding.EpisodeSeedCounter`) numbers and seeds every episode, the first
ones included, whatever seed the algorithm passes to ``VecEnv.seed`` (SB3 passes its own, which
would otherwise replay held-out test seeds); a finished world's info then has ``episode_index``
and ``episode_seed``. ``reward_scale`` multiplies the rewards the algorithm sees (the logged
returns stay in env units) and ``reward_dtype`` is their dtype (SB3's float32 by default;
crowdnav's episode loop for registered algorithms keeps the env's float64); ``encoder`` replaces ``leog`` by a frozen encoder's latent, as
:class:`crowdnav.agents.training.wrappers.LeogLatentWrapper` does for one env.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from crowdnav.agents.training.seeding import EpisodeSeedCounter, train_seed
from crowdnav.agents.training.space_checks import box_space, dict_space
from crowdnav.agents.training.wrappers import ObservationScales, agent_observation
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvObs, VecEnvStepReturn

from crowdnav.envs.engines.world_state import VectorWorldState
from crowdnav.envs.vector.env import CrowdNavVectorEnv
from crowdnav.sensors.base import checked_scale, normalized_box


class CrowdNavSB3VecEnv(VecEnv):
    """SB3's ``VecEnv`` interface over one :class:`CrowdNavVectorEnv` in ``SAME_STEP`` autoreset mode."""

    def __init__(self, env: CrowdNavVectorEnv, seed: int | None = None, scales: ObservationScales | None = None, *,
                 episode_seeds: EpisodeSeedCounter | None = None, reward_scale: float = 1.0, encoder: Any = None,
                 reward_dtype: type[np.floating[Any]] = np.float32):
        if env.autoreset_mode is not AutoresetMode.SAME_STEP:
            raise ValueError("CrowdNavSB3VecEnv needs a CrowdNavVectorEnv with autoreset_mode=AutoresetMode.SAME_STEP (SB3 resets in the same step)")
        self.env = env
        space = dict_space(env.single_observation_space)
        if scales is not None:  # as NormalizeObservation: scaled keys get their mapped Box, the others pass through
            scales = {key: checked_scale(key, box_space(space, key), *scales[key]) for key in space.spaces if key in scales}
            space = spaces.Dict({key: normalized_box(box_space(space, key), *scales[key]) if key in scales else box
                                 for key, box in space.spaces.items()})
        if encoder is not None:  # the frozen encoder's latent instead of the grid
            encoder = encoder.eval().requires_grad_(False)
            space = spaces.Dict({**space.spaces, "leog": spaces.Box(-1.0, 1.0, shape=(encoder.latent,), dtype=np.float32)})
        self.scales = scales
        self.encoder = encoder
        self.episode_seeds = episode_seeds
        self.reward_scale = float(reward_scale)
        self.reward_dtype = reward_dtype
        if episode_seeds is not None:  # without it, the vector env's own hook (if any) is left alone
            env.episode_seeds = episode_seeds
        super().__init__(env.num_envs, space, env.single_action_space)
        self._seed = seed
        self._actions: np.ndarray | None = None
        self._returns = np.zeros(self.num_envs)
        self._lengths = np.zeros(self.num_envs, dtype=np.int64)
        self._start = time.time()

    @classmethod
    def make(cls, scenario: Any, num_envs: int, seed: int | None = None, scales: ObservationScales | None = None, *,
             episode_seeds: EpisodeSeedCounter | None = None, reward_scale: float = 1.0, encoder: Any = None,
             **options: Any) -> CrowdNavSB3VecEnv:
        """Build the vector env (``options``: the single env's) and wrap it."""
        return cls(CrowdNavVectorEnv(scenario, num_envs, autoreset_mode=AutoresetMode.SAME_STEP, **options), seed, scales,
                   episode_seeds=episode_seeds, reward_scale=reward_scale, encoder=encoder)

    def _observe(self, observation: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return agent_observation(observation, self.scales, self.encoder)

    def reset(self) -> VecEnvObs:
        # VecEnv.seed() (SB3 calls it with the algorithm's seed) wins over the constructor's; either applies to this reset only
        seed: Sequence[int | None] | int | None = self._seeds if any(s is not None for s in self._seeds) else self._seed
        if self.episode_seeds is not None:  # training: the run's own episode numbering, never the algorithm's seed
            seed = self.episode_seeds(range(self.num_envs))
        observation, _ = self.env.reset(seed=seed)
        self._reset_seeds()
        self._seed = None
        self._returns[:] = 0.0
        self._lengths[:] = 0
        return self._observe(observation)

    def world_counts(self) -> tuple[np.ndarray, np.ndarray]:
        """Each world's return and length so far in its episode (what ``infos[i]["episode"]`` will report), as copies."""
        return self._returns.copy(), self._lengths.copy()

    def restore_worlds(self, episodes: Sequence[int], actions: np.ndarray, lengths: np.ndarray,
                       returns: np.ndarray, episode_lengths: np.ndarray) -> dict[str, np.ndarray]:
        """A training resume: world ``i`` back in training episode ``episodes[i]`` after its first ``lengths[i]`` actions.

        The worlds are rebuilt by :meth:`CrowdNavVectorEnv.restore_worlds` with the episodes' seeds
        (``episode_seeds``, whose counter the caller has set to the checkpoint's); ``returns`` and
        ``episode_lengths`` are :meth:`world_counts` as saved. Returns the (normalised) observation.
        """
        counter = self.episode_seeds
        if counter is None:
            raise ValueError("restore_worlds needs the training episode counter (episode_seeds) that numbered the episodes")
        self._check_counts("restore_worlds", returns, episode_lengths)
        observation = self.env.restore_worlds([train_seed(counter.run_seed, int(e)) for e in episodes], actions, lengths)
        return self._resumed(observation, returns, episode_lengths)

    def load_worlds(self, states: Sequence[VectorWorldState], returns: np.ndarray, episode_lengths: np.ndarray) -> dict[str, np.ndarray]:
        """A training resume from stored world states: world ``i`` becomes ``states[i]``
        (:meth:`CrowdNavVectorEnv.load_worlds`); ``returns`` and ``episode_lengths`` are :meth:`world_counts` as saved, and
        later episodes take their seeds from ``episode_seeds`` (whose counter the caller has set to the checkpoint's).
        Returns the (normalised) observation."""
        self._check_counts("load_worlds", returns, episode_lengths)
        return self._resumed(self.env.load_worlds(states), returns, episode_lengths)

    def _check_counts(self, call: str, returns: np.ndarray, episode_lengths: np.ndarray) -> None:
        for name, value, kind in (("returns", returns, "f"), ("episode_lengths", episode_lengths, "i")):
            if np.shape(value) != (self.num_envs,) or np.asarray(value).dtype.kind != kind:
                raise ValueError(f"{call}: {name} must be one {'float' if kind == 'f' else 'integer'} per world "
                                 f"({self.num_envs}), got {np.asarray(value).dtype}{np.shape(value)}")

    def _resumed(self, observation: dict[str, np.ndarray], returns: np.ndarray, episode_lengths: np.ndarray) -> dict[str, np.ndarray]:
        self._returns[:] = returns
        self._lengths[:] = episode_lengths
        self._reset_seeds()  # SB3 seeded the new env; its worlds are seeded by the counter
        self._seed = None
        return self._observe(observation)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> VecEnvStepReturn:
        observation, rewards, terminated, truncated, infos = self.env.step(self._actions)
        dones = terminated | truncated
        self._returns += rewards
        self._lengths += 1
        out = _world_infos(infos, self.num_envs)  # SB3's API: one info dict per world
        ended = _world_infos(infos["final_info"], self.num_envs) if "final_info" in infos else out
        done, time_limit = dones.tolist(), (truncated & ~terminated).tolist()
        for i in range(self.num_envs):
            info = ended[i] if done[i] else out[i]
            out[i] = info
            info["TimeLimit.truncated"] = time_limit[i]
            if done[i]:
                info["terminal_observation"] = self._observe(infos["final_obs"][i])
                info["episode"] = {"r": round(float(self._returns[i]), 6), "l": int(self._lengths[i]), "t": round(time.time() - self._start, 6)}
                if self.episode_seeds is not None:  # the episode that ended (its world has started the next)
                    index = self.episode_seeds.ended_of[i]
                    info["episode_index"], info["episode_seed"] = index, train_seed(self.episode_seeds.run_seed, index)
        if any(done):
            self._returns[dones] = 0.0
            self._lengths[dones] = 0
        if self.reward_scale != 1.0:
            rewards = rewards * self.reward_scale
        return self._observe(observation), rewards.astype(self.reward_dtype), dones, out

    def close(self) -> None:
        self.env.close()

    # The worlds are one batched env: attributes are shared and a method runs for all worlds at once,
    # so a call aimed at some worlds only is refused rather than silently applied to every world.

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self.env, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        self._all_worlds("set_attr", attr_name, indices)
        if attr_name == "autoreset_mode" or not hasattr(self.env, attr_name):
            reason = "SB3 needs the same-step autoreset" if attr_name == "autoreset_mode" else "the env has no such attribute"
            raise ValueError(f"set_attr({attr_name!r}): refused, {reason}")
        setattr(self.env, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any) -> list[Any]:
        self._all_worlds("env_method", method_name, indices)
        result = getattr(self.env, method_name)(*method_args, **method_kwargs)  # once: it acts on every world
        return [result] * self.num_envs

    def _all_worlds(self, call: str, name: str, indices: Any) -> None:
        chosen = self._get_indices(indices)
        if sorted(int(i) for i in chosen) != list(range(self.num_envs)):
            raise ValueError(f"{call}({name!r}, indices={list(chosen)}): the {self.num_envs} worlds are one batched env, so it "
                             "applies to all of them; call it with indices=None")

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [None] * self.num_envs


def _world_infos(infos: Mapping[str, Any], n: int) -> list[dict[str, Any]]:
    """Gymnasium vector ``infos`` of ``n`` worlds as one info dict per world (world ``i``'s entries, as the single env's
    info dict: numpy scalars as Python ones). One ``tolist`` per key, then a loop over the worlds."""
    out: list[dict[str, Any]] = [{} for _ in range(n)]
    for key, value in infos.items():
        if key[0] == "_" or key == "final_obs" or key == "final_info":
            continue
        has = infos["_" + key].tolist()
        values = _world_infos(value, n) if isinstance(value, dict) else value.tolist()
        for i in range(n):
            if has[i]:
                out[i][key] = values[i]
    return out
