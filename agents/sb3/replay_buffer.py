"""A replay buffer that stores occupancy grids at one bit per cell.

SB3's ``DictReplayBuffer`` keeps every observation key at its own dtype, so a (1, 60, 60)
uint8 LEOG costs 3,600 bytes, twice per transition (observation and next observation):
0.72 GB for 100,000 transitions. The grid is binary (the extractor reads it as ``grid > 0``),
so :class:`PackedGridReplayBuffer` stores it with ``numpy.packbits`` (450 bytes) and unpacks the
sampled batch back to 0/255 uint8, exactly what the environment produced: 8 times less memory
for the grids, for about a millisecond of unpacking per sampled batch.

It also computes **n-step returns** at sampling time (``n_steps > 1``), which SB3's own
``NStepReplayBuffer`` does not do for Dict observations. A sampled transition then carries the
discounted sum of up to ``n_steps`` rewards, stopped at the episode's end, the observation
after the last of them and the discount to bootstrap with (``gamma ** k`` for ``k`` rewards).
Why: with the paper's weights a constant step penalty must be propagated through about
``1 / (1 - gamma)`` Bellman backups before "keep wandering" stops looking better than a
terminal collision; n steps make that n times faster.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from crowdnav.agents.training.space_checks import box_space
from gymnasium import spaces
from stable_baselines3.common.buffers import DictReplayBuffer
from stable_baselines3.common.type_aliases import DictReplayBufferSamples
from stable_baselines3.common.vec_env import VecNormalize

OCCUPIED = 255


def packable_keys(observation_space: spaces.Dict, keys: Sequence[str]) -> list[str]:
    """The ``keys`` that hold uint8 grids (3-D Box), i.e. those that can be stored packed."""
    return [key for key in keys if key in observation_space.spaces and _is_grid(observation_space[key])]


def _is_grid(space: spaces.Space[Any]) -> bool:
    return isinstance(space, spaces.Box) and len(space.shape) == 3 and space.dtype == np.uint8


class PackedGridReplayBuffer(DictReplayBuffer):
    """``DictReplayBuffer`` with the grids in ``packed_keys`` stored bit-packed (non-zero = occupied)."""

    n_steps = 1  # class-level defaults: buffers pickled before n-step returns (or fast sampling) existed still load
    gamma = 0.99
    fast_sampling = True

    def __init__(self, buffer_size: int, observation_space: spaces.Dict, action_space: spaces.Space[Any], device: Any = "auto",
                 n_envs: int = 1, optimize_memory_usage: bool = False, handle_timeout_termination: bool = True,
                 packed_keys: Sequence[str] = ("leog",), n_steps: int = 1, gamma: float = 0.99, fast_sampling: bool = True):
        if n_steps < 1:
            raise ValueError(f"n_steps must be >= 1, got {n_steps}")
        if optimize_memory_usage:
            raise ValueError("PackedGridReplayBuffer does not support optimize_memory_usage")
        self.n_steps = int(n_steps)
        self.gamma = float(gamma)
        self.fast_sampling = bool(fast_sampling)
        self.packed_keys = packable_keys(observation_space, packed_keys)
        self.grid_shapes = {key: box_space(observation_space, key).shape for key in self.packed_keys}
        stored = dict(observation_space.spaces)
        for key, shape in self.grid_shapes.items():
            stored[key] = spaces.Box(0, 255, shape=((int(np.prod(shape)) + 7) // 8,), dtype=np.uint8)
        super().__init__(buffer_size, spaces.Dict(stored), action_space, device, n_envs, optimize_memory_usage,
                         handle_timeout_termination)

    def _pack(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        packed = dict(observation)
        for key in self.packed_keys:
            grids = np.asarray(observation[key]).reshape(self.n_envs, -1)
            packed[key] = np.packbits(grids > 0, axis=1)
        return packed

    def add(  # type: ignore[override]  # DictReplayBuffer's own signature (SB3 marks it so too)
        self, obs: dict[str, np.ndarray], next_obs: dict[str, np.ndarray], action: np.ndarray, reward: np.ndarray, done: np.ndarray,
        infos: list[dict[str, Any]],
    ) -> None:
        super().add(self._pack(obs), self._pack(next_obs), action, reward, done, infos)

    def _unpack(self, stored: dict[str, np.ndarray], key: str, rows: np.ndarray, env_indices: np.ndarray) -> np.ndarray:
        shape = self.grid_shapes[key]
        bits = np.unpackbits(stored[key][rows, env_indices], axis=1, count=int(np.prod(shape)))
        bits *= OCCUPIED
        return bits.reshape(len(rows), *shape)

    def _normalized(self, batch: dict[str, np.ndarray], env: VecNormalize | None) -> dict[str, torch.Tensor]:
        """A sampled Dict batch through SB3's normalisation (a VecNormalize env's, if any), as tensors."""
        normalized = self._normalize_obs(batch, env)
        if not isinstance(normalized, dict):  # SB3 returns what it was given: a dict for a dict
            raise TypeError(f"expected the normalised batch to be a dict, got {type(normalized).__name__}")
        return {key: self.to_torch(values) for key, values in normalized.items()}

    def _get_samples(self, batch_inds: np.ndarray, env: VecNormalize | None = None) -> DictReplayBufferSamples:  # type: ignore[override]
        env_indices = np.random.randint(0, high=self.n_envs, size=(len(batch_inds),))
        if self.n_steps == 1:
            last_inds = batch_inds
            rewards = self.rewards[batch_inds, env_indices].reshape(-1, 1)
            discounts = None
        else:
            last_inds, rewards, discounts = self._n_step(batch_inds, env_indices)
        if self.fast_sampling and env is None:
            # Each array gathered straight into the tensor the networks get (torch.index_select on a view of
            # the buffer), instead of numpy fancy indexing then a copy into torch: the same values, one copy.
            rows = torch.from_numpy(batch_inds * self.n_envs + env_indices)
            observations = self._gather(self.observations, rows, batch_inds, env_indices)
            next_rows = rows if last_inds is batch_inds else torch.from_numpy(last_inds * self.n_envs + env_indices)
            next_observations = self._gather(self.next_observations, next_rows, last_inds, env_indices)
            actions = self._select(self.actions, rows)
        else:  # SB3's way (also with a VecNormalize env, which normalises the numpy batch)
            observations, next_observations = (
                self._normalized({key: (self._unpack(stored, key, rows, env_indices) if key in self.grid_shapes else values[rows, env_indices, :])
                                  for key, values in stored.items()}, env)
                for stored, rows in ((self.observations, batch_inds), (self.next_observations, last_inds)))
            actions = self.to_torch(self.actions[batch_inds, env_indices])
        dones = self.dones[last_inds, env_indices] * (1 - self.timeouts[last_inds, env_indices])
        return DictReplayBufferSamples(
            observations=observations,
            actions=actions,
            next_observations=next_observations,
            dones=self.to_torch(dones).reshape(-1, 1),
            rewards=self.to_torch(self._normalize_reward(rewards, env)),
            discounts=None if discounts is None else self.to_torch(discounts),
        )

    def _select(self, values: np.ndarray, flat_rows: torch.Tensor) -> torch.Tensor:
        """``values[rows, env_indices]`` as a tensor (``flat_rows = rows * n_envs + env_indices``)."""
        flat = torch.from_numpy(values).view(values.shape[0] * values.shape[1], *values.shape[2:])
        return torch.index_select(flat, 0, flat_rows).to(self.device)

    def _gather(self, stored: dict[str, np.ndarray], flat_rows: torch.Tensor, rows: np.ndarray,
                env_indices: np.ndarray) -> dict[str, torch.Tensor]:
        return {key: (torch.from_numpy(self._unpack(stored, key, rows, env_indices)).to(self.device) if key in self.grid_shapes
                      else self._select(values, flat_rows)) for key, values in stored.items()}

    def _n_step(self, batch_inds: np.ndarray, env_indices: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Last row, discounted reward sum and bootstrap discount of each sampled n-step transition.

        A window stops at the first row that ends an episode (terminated or truncated), and at
        the newest row written: the row after it is the oldest one (or empty), from another episode.
        """
        offsets = np.arange(self.n_steps)
        rows = (batch_inds[:, None] + offsets) % self.buffer_size  # [batch, n]
        flat = rows * self.n_envs + env_indices[:, None]  # the same elements as [rows, env_indices[:, None]], gathered faster
        ends = np.logical_or(self.dones.reshape(-1).take(flat), self.timeouts.reshape(-1).take(flat))
        ends |= rows == (self.pos - 1) % self.buffer_size
        ends[:, -1] = True
        count = ends.argmax(axis=1) + 1  # rewards summed per sample, 1..n
        used = offsets[None, :] < count[:, None]
        rewards = self.rewards.reshape(-1).take(flat) * (self.gamma ** offsets)[None, :] * used
        last_inds = rows[np.arange(len(batch_inds)), count - 1]
        discounts = (self.gamma ** count).astype(np.float32).reshape(-1, 1)
        return last_inds, rewards.sum(axis=1, dtype=np.float32).reshape(-1, 1), discounts
