"""Environment wrappers used in training: seeded episodes and the frozen-encoder latent.

* :class:`EpisodeSeeds` gives training episode ``i`` the seed :func:`train_seed` ``(seed, i)``
  (the seed rules live in :mod:`crowdnav.agents.training.seeding`, free of torch), so a run is
  reproducible, a resumed run continues the same episode sequence, and evaluation seeds (below
  :data:`TRAIN_SEED_BASE`) never occur in training.
* :class:`NormalizeObservation` maps every float modality to ``(x - offset) / scale`` with the
  scales its modality declares (:meth:`crowdnav.sensors.Modality.scale`): fixed numbers, not
  running statistics, so a checkpoint stores them (:func:`scales_to_json`) and a loaded policy
  applies exactly what it was trained on.
* :class:`LeogLatentWrapper` encodes the occupancy grid once per step with a frozen encoder,
  so the agent (and its replay buffer) sees a small float vector instead of the grid.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from crowdnav.agents.networks.encoders import LeogEncoder
from crowdnav.agents.training.seeding import DATASET_SEED_OFFSET, TRAIN_SEED_BASE, dataset_seed, train_seed  # noqa: F401  (re-exported)
from crowdnav.agents.training.space_checks import box_space
from gymnasium import spaces

from crowdnav.sensors.base import checked_scale, normalize_values, normalized_box


class EpisodeSeeds(gym.Wrapper):
    """Every reset uses the next training seed, whatever seed the caller passes (SB3 seeds only the first reset)."""

    def __init__(self, env: gym.Env, seed: int, first_episode: int = 0):
        super().__init__(env)
        self.run_seed = seed
        self.episode = first_episode - 1
        """Index of the current episode (-1 before the first reset)."""

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        self.episode += 1
        observation, info = self.env.reset(seed=train_seed(self.run_seed, self.episode), options=options)
        info["episode_index"] = self.episode
        return observation, info


ObservationScales = dict[str, tuple[np.ndarray, np.ndarray]]
"""Observation key -> ``(offset, scale)`` float32 arrays of that key's shape."""


def observation_scales(env: gym.Env) -> ObservationScales:
    """The declared ``(offset, scale)`` of every float observation key of a crowdnav env (wrapped or not).

    Read from the modalities of ``env.unwrapped.core``. Left out, so passed on unscaled: integer
    keys (the uint8 LEOG grid: SB3 treats it as an image and the extractor reads ``grid > 0``),
    keys an inner :class:`NormalizeObservation` already scales (wrapping twice scales once) and
    keys an inner wrapper replaced (the frozen encoder's latent).
    """
    modalities = getattr(getattr(env.unwrapped, "core", None), "modalities", None)
    space = env.observation_space
    if modalities is None or not isinstance(space, spaces.Dict):
        raise TypeError(f"observation_scales needs a crowdnav environment (CrowdNavEnv or a wrapper of it), got {env}")
    scaled: set[str] = set()
    inner = env
    while isinstance(inner, gym.Wrapper):
        if isinstance(inner, NormalizeObservation):
            scaled |= set(inner.scales)
        inner = inner.env
    return {key: scale for key, scale in declared_scales(modalities).items()
            if key in space.spaces and key not in scaled and space[key] == modalities[key].space()}


def declared_scales(modalities: Mapping[str, Any]) -> ObservationScales:
    """Key -> the declared ``(offset, scale)`` of every float modality (integer keys, the uint8 grid, are left out)."""
    return {key: modality.normalization() for key, modality in modalities.items()
            if np.issubdtype(modality.space().dtype, np.floating)}


def normalize_observation(observation: Mapping[str, np.ndarray], scales: ObservationScales) -> dict[str, np.ndarray]:
    """``observation`` with each key of ``scales`` mapped to ``(x - offset) / scale`` (float32); batches work too."""
    observation = dict(observation)
    for key, (offset, scale) in scales.items():
        observation[key] = normalize_values(observation[key], offset, scale)
    return observation


def scales_to_json(scales: ObservationScales) -> dict[str, dict[str, list[Any]]]:
    """JSON-ready ``{key: {"offset": [...], "scale": [...]}}`` (nested lists of the observation's shape)."""
    return {key: {"offset": offset.tolist(), "scale": scale.tolist()} for key, (offset, scale) in scales.items()}


def scales_from_json(document: Mapping[str, Mapping[str, Any]]) -> ObservationScales:
    """Inverse of :func:`scales_to_json`."""
    return {key: (np.asarray(item["offset"], dtype=np.float32), np.asarray(item["scale"], dtype=np.float32))
            for key, item in document.items()}


class NormalizeObservation(gym.ObservationWrapper):
    """Feed the agent O(1) numbers: each float modality becomes ``(x - offset) / scale``.

    The scales are those the modalities declare (:func:`observation_scales`), or ``scales`` when
    given (the ones stored with a checkpoint, so a resumed run keeps its own). Unlike
    ``gymnasium.wrappers.NormalizeObservation`` there are no running statistics: the mapping is
    fixed, the same in training, evaluation and after loading. The space of a scaled key is its
    Box mapped the same way (float32), so it contains every scaled observation; other keys
    (the uint8 LEOG grid) pass through unchanged, so a :class:`LeogLatentWrapper` stacked on
    top still receives the raw grid.
    """

    def __init__(self, env: gym.Env, scales: Mapping[str, tuple[Any, Any]] | None = None):
        super().__init__(env)
        space = env.observation_space
        if not isinstance(space, spaces.Dict):
            raise TypeError(f"NormalizeObservation needs a Dict observation space, got {space}")
        if scales is None:
            scales = observation_scales(env)
        unknown = sorted(set(scales) - set(space.spaces))
        if unknown:
            raise ValueError(f"NormalizeObservation: scales for keys the environment does not observe: {unknown}")
        self.scales: ObservationScales = {key: checked_scale(key, box_space(space, key), *scales[key]) for key in space.spaces
                                          if key in scales}
        """Key -> (offset, scale) float32 arrays; the keys left out pass through."""
        self.observation_space = spaces.Dict({
            key: normalized_box(box_space(space, key), *self.scales[key]) if key in self.scales else box for key, box in space.spaces.items()
        })

    def observation(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return normalize_observation(observation, self.scales)


class LeogLatentWrapper(gym.ObservationWrapper):
    """Replace ``leog`` (uint8 grid) by the frozen encoder's latent (float32 in [-1, 1]).

    The grid is binarized with ``grid > 0`` exactly as in :class:`crowdnav.agents.networks.extractor.MultiModalExtractor`,
    so a policy sees the same latent whether the encoder runs here or inside the extractor.
    """

    def __init__(self, env: gym.Env, encoder: LeogEncoder, key: str = "leog"):
        super().__init__(env)
        space = env.observation_space
        if not isinstance(space, spaces.Dict) or key not in space.spaces:
            raise ValueError(f"LeogLatentWrapper needs a Dict observation with a {key!r} key, got {space}")
        if box_space(space, key).shape != tuple(encoder.architecture["grid_shape"]):
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


def agent_observation(observation: Mapping[str, np.ndarray], scales: ObservationScales | None,
                      encoder: LeogEncoder | None = None) -> dict[str, np.ndarray]:
    """A raw CrowdNavEnv observation (one, or a batch stacked per key) -> what the agent's network receives.

    Each key of ``scales`` normalised (:func:`normalize_observation`), then, with ``encoder``, the
    ``leog`` grid replaced by the frozen encoder's latent: the one mapping training
    (:class:`~crowdnav.agents.sb3.vec_env.CrowdNavSB3VecEnv`), a loaded policy and the demonstrations apply.
    """
    observation = dict(observation) if scales is None else normalize_observation(observation, scales)
    if encoder is not None:
        grid = np.asarray(observation["leog"])
        single = grid.ndim == 3  # one (1, H, W) grid
        latent = encode_grids(encoder, grid[None] if single else grid)
        observation["leog"] = latent[0] if single else latent
    return observation


ENCODE_CHUNK = 4096
"""Grids encoded per forward pass: a demonstration set of many thousand grids stays within memory."""


def encode_grids(encoder: LeogEncoder, grids: np.ndarray) -> np.ndarray:
    """(N, 1, H, W) grids (non-zero = occupied) -> (N, latent) float32 latents, without gradients."""
    grids = np.asarray(grids)
    with torch.no_grad():
        if len(grids) > ENCODE_CHUNK:
            return np.concatenate([encode_grids(encoder, grids[i : i + ENCODE_CHUNK]) for i in range(0, len(grids), ENCODE_CHUNK)])
        return encoder(torch.as_tensor(grids > 0, dtype=torch.float32)).numpy()
