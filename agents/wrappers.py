"""Environment wrappers used in training: seeded episodes and the frozen-encoder latent.

* :class:`EpisodeSeeds` gives training episode ``i`` the seed :func:`train_seed` ``(seed, i)``,
  so a run is reproducible, a resumed run continues the same episode sequence, and
  evaluation seeds (below :data:`TRAIN_SEED_BASE`) never occur in training;
  :func:`dataset_seed` does the same for the random-policy grid collections.
* :class:`LeogLatentWrapper` encodes the occupancy grid once per step with a frozen encoder,
  so the agent (and its replay buffer) sees a small float vector instead of the grid.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces

from agents.encoders import LeogEncoder

TRAIN_SEED_BASE = 1_000_000
"""Training seeds start here; seeds below it are free for held-out test episodes."""


def train_seed(seed: int, episode: int) -> int:
    """Seed of training episode ``episode`` (0-based) of a run with seed ``seed``: disjoint ranges per run seed."""
    return TRAIN_SEED_BASE * (seed + 1) + episode


DATASET_SEED_OFFSET = TRAIN_SEED_BASE // 2
"""Grid-collection episodes use the upper half of each seed's band: no run trains 500,000 episodes."""


def dataset_seed(seed: int, episode: int) -> int:
    """Seed of episode ``episode`` of a random-policy grid collection with seed ``seed``.

    Disjoint from the held-out test seeds (below :data:`TRAIN_SEED_BASE`) and from every
    training episode, so an encoder pre-trained on the collection never saw a test episode.
    """
    return TRAIN_SEED_BASE * (seed + 1) + DATASET_SEED_OFFSET + episode


class EpisodeSeeds(gym.Wrapper):
    """Every reset uses the next training seed, whatever seed the caller passes (SB3 seeds only the first reset)."""

    def __init__(self, env: gym.Env, seed: int, first_episode: int = 0):
        super().__init__(env)
        self.run_seed = seed
        self.episode = first_episode - 1
        """Index of the current episode (-1 before the first reset)."""

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        self.episode += 1
        observation, info = self.env.reset(seed=train_seed(self.run_seed, self.episode), options=options)
        info["episode_index"] = self.episode
        return observation, info


class LeogLatentWrapper(gym.ObservationWrapper):
    """Replace ``leog`` (uint8 grid) by the frozen encoder's latent (float32 in [-1, 1]).

    The grid is binarized with ``grid > 0`` exactly as in :class:`agents.extractor.MultiModalExtractor`,
    so a policy sees the same latent whether the encoder runs here or inside the extractor.
    """

    def __init__(self, env: gym.Env, encoder: LeogEncoder, key: str = "leog"):
        super().__init__(env)
        space = env.observation_space
        if not isinstance(space, spaces.Dict) or key not in space.spaces:
            raise ValueError(f"LeogLatentWrapper needs a Dict observation with a {key!r} key, got {space}")
        if tuple(space[key].shape) != tuple(encoder.architecture["grid_shape"]):
            raise ValueError(
                f"the encoder expects grids of shape {tuple(encoder.architecture['grid_shape'])}, "
                f"the environment's {key!r} has shape {space[key].shape}"
            )
        self.key = key
        self.encoder = encoder.eval().requires_grad_(False)
        latent = spaces.Box(-1.0, 1.0, shape=(encoder.latent,), dtype=np.float32)
        self.observation_space = spaces.Dict({**space.spaces, key: latent})

    def observation(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        observation = dict(observation)
        observation[self.key] = encode_grids(self.encoder, observation[self.key][None])[0]
        return observation


def encode_grids(encoder: LeogEncoder, grids: np.ndarray) -> np.ndarray:
    """(N, 1, H, W) grids (non-zero = occupied) -> (N, latent) float32 latents, without gradients."""
    with torch.no_grad():
        grid = torch.as_tensor(np.asarray(grids) > 0, dtype=torch.float32)
        return encoder(grid).numpy()
