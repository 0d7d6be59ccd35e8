"""The multi-modal encoder shared by every algorithm: one branch per observation key, concatenated.

Branch per key (in the observation space's key order):

* a key registered with :func:`register_encoder` -> the user's module;
* ``(C, H, W)`` grids (the LEOG) -> :class:`~crowdnav.agents.networks.encoders.LeogEncoder` CNN, then the
  ``leog_head`` fully connected layers; with ``leog_precomputed`` the key already holds the
  frozen encoder's latent (see :class:`crowdnav.agents.training.wrappers.LeogLatentWrapper`) and only the head runs;
* vectors longer than :data:`LOWDIM_MAX` values (the LIDAR) -> :class:`~crowdnav.agents.networks.encoders.LidarEncoder`;
* short vectors (goal, closest_obstacle, velocity) -> :class:`~crowdnav.agents.networks.encoders.LowDimEncoder`
  (Gaussian RBF, then fully connected layers);
* tables ``(rows, features)`` (the ``humans`` modality) -> :class:`~crowdnav.agents.networks.encoders.TableEncoder`
  (flattened, then the ``table_hidden`` fully connected layers).

**Grid scaling.** SB3's ``preprocess_obs`` divides a uint8 observation by 255 only when
``normalize_images`` is on *and* ``is_image_space`` recognizes the Box (uint8, bounds 0..255);
otherwise the extractor receives 0/255 floats. The LEOG branch therefore binarizes its input
with ``grid > 0``: it sees exactly 0/1 floats in every case (also for 0/1 grids from another
simulator), the same values the autoencoder is pre-trained on.

**Speed** (docs/agents.md#performance). crowdnav's SAC/TD3/DDPG policies (:mod:`crowdnav.agents.sb3.algorithms`)
hand the extractor the observation tensors as sampled (:meth:`MultiModalExtractor.prepare`), without
SB3's ``float() / 255`` copy of the grid, which the binarization makes irrelevant. The grid is
binarized once per sampled batch, not once per network (the actor, critic and target networks all
read the same batch: :mod:`crowdnav.agents.networks.batch_cache`, which also serves the LIDAR proximities and the
RBF expansions), straight into float32 (:func:`binarize`; ``(grid > 0).float()`` converts through
a bool tensor, ~10x slower on CPU). ``reference=True`` keeps the plain formulas (what
benchmarks/bench_train.py times the fast path against; the tests check both give the same values).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import torch
from crowdnav.agents.networks import batch_cache
from crowdnav.agents.networks.encoders import LeogEncoder, LidarEncoder, LowDimEncoder, TableEncoder, leog_architecture, mlp
from crowdnav.agents.networks.rbf import GaussianRBF
from gymnasium import spaces
from stable_baselines3.common.preprocessing import preprocess_obs
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

LOWDIM_MAX = 16
"""Vectors with at most this many values go through the RBF branch, longer ones through the LIDAR branch."""

EncoderBuilder = Callable[[spaces.Box, Mapping[str, Any]], tuple[nn.Module, int]]
"""``builder(space, extractor_config) -> (module, output size)``; the module maps (B, *shape) floats to (B, size)."""

ENCODERS: dict[str, EncoderBuilder] = {}
"""Observation key -> custom branch builder, filled by :func:`register_encoder`."""


def register_encoder(key: str, builder: EncoderBuilder) -> None:
    """Use ``builder`` for observation ``key`` instead of the built-in branch chosen by its shape."""
    if not isinstance(key, str) or not callable(builder):
        raise TypeError("register_encoder(key, builder) expects an observation key and a callable")
    ENCODERS[key] = builder


def _binarize(grid: torch.Tensor) -> torch.Tensor:
    return torch.gt(grid, 0, out=torch.empty(grid.shape, dtype=torch.float32, device=grid.device))


def binarize(grid: torch.Tensor) -> torch.Tensor:
    """``(grid > 0).float()``, once per sampled batch (:func:`crowdnav.agents.networks.batch_cache.cached`).

    The result is written straight as float32 (``torch.gt(..., out=)``): ``(grid > 0).float()``
    goes through a bool tensor whose conversion costs ~10x more on CPU.
    """
    return batch_cache.cached("binarize", grid, _binarize)


class _LeogBranch(nn.Module):
    """Binarize, encode (unless precomputed), head."""

    reference = False  # True: the plain (slower) binarization, for benchmarks/bench_train.py's reference timing

    def __init__(self, encoder: LeogEncoder | None, head: nn.Module, out_features: int):
        super().__init__()
        self.encoder = encoder
        self.head = head
        self.out_features = out_features

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        if self.encoder is None:
            return self.head(observation)
        grid = (observation > 0).float() if self.reference else binarize(observation)
        if not any(p.requires_grad for p in self.encoder.parameters()):
            with torch.no_grad():  # frozen: no graph, so no backward cost
                return self.head(self.encoder(grid))
        return self.head(self.encoder(grid))


class MultiModalExtractor(BaseFeaturesExtractor):
    """SB3 features extractor: ``{key: (B, ...)}`` -> latent ``(B, features_dim)``.

    ``config``: the fields of :class:`crowdnav.agents.training.config.ExtractorConfig` as a dict.
    ``leog_mode``: ``scratch`` / ``finetune`` (the CNN is trained) or ``frozen`` (its parameters
    never get gradients). ``leog_architecture``: the CNN's architecture dict, when it comes from
    pre-trained weights (then ``config``'s LEOG sizes are not used). ``leog_precomputed``: the
    ``leog`` key holds the frozen encoder's latent instead of the grid.
    """

    def __init__(
        self,
        observation_space: spaces.Dict,
        config: Mapping[str, Any] | None = None,
        leog_mode: str = "scratch",
        leog_architecture: Mapping[str, Any] | None = None,
        leog_precomputed: bool = False,
        reference: bool = False,
    ):
        from crowdnav.agents.training.config import ENCODER_MODES, ExtractorConfig

        if not isinstance(observation_space, spaces.Dict):
            raise TypeError(f"MultiModalExtractor needs a Dict observation space, got {observation_space}")
        if leog_mode not in ENCODER_MODES:
            raise ValueError(f"leog_mode must be one of {ENCODER_MODES}, got {leog_mode!r}")
        settings = {**ExtractorConfig().model_dump(), **(config or {})}
        branches: dict[str, nn.Module] = {}
        sizes: dict[str, int] = {}
        leog_encoders: list[LeogEncoder] = []
        boxes: dict[str, spaces.Box] = {}
        for key, space in observation_space.spaces.items():
            if not isinstance(space, spaces.Box):
                raise TypeError(f"observation {key!r}: MultiModalExtractor handles Box spaces only, got {space}")
            boxes[key] = space
            if key in ENCODERS:
                branches[key], sizes[key] = ENCODERS[key](space, settings)
            elif len(space.shape) == 3 or (key == "leog" and leog_precomputed):
                leog = self._leog_branch(space, settings, leog_architecture, precomputed=key == "leog" and leog_precomputed)
                if leog.encoder is not None:
                    leog_encoders.append(leog.encoder)
                branches[key], sizes[key] = leog, leog.out_features
            elif len(space.shape) == 1 and space.shape[0] > LOWDIM_MAX:
                lidar = LidarEncoder(space.low, space.high, settings["lidar_hidden"], settings["lidar_conv_channels"])
                branches[key], sizes[key] = lidar, lidar.out_features
            elif len(space.shape) == 1:
                lowdim = LowDimEncoder(space.low, space.high, settings["rbf_centres"], settings["lowdim_hidden"], settings["rbf_trainable"])
                branches[key], sizes[key] = lowdim, lowdim.out_features
            elif len(space.shape) == 2:
                table = TableEncoder(space.shape, settings["table_hidden"])
                branches[key], sizes[key] = table, table.out_features
            else:
                raise ValueError(f"observation {key!r} has shape {space.shape}: register an encoder for it with crowdnav.agents.register_encoder")
        super().__init__(observation_space, features_dim=sum(sizes.values()))
        self.branches = nn.ModuleDict(branches)
        self.branch_sizes = sizes
        self.boxes = boxes
        """The observation space's entries, each a Box (checked above), in its order."""
        self.leog_mode = leog_mode
        self.leog_encoders = leog_encoders
        if leog_mode == "frozen":
            for encoder in leog_encoders:
                encoder.requires_grad_(False)
        self.reference = bool(reference)
        for module in self.modules():
            if isinstance(module, (_LeogBranch, GaussianRBF, LidarEncoder)):
                module.reference = self.reference
        # keys whose built-in branch reads the sampled tensor as it is (see prepare); the others get SB3's preprocessing
        self.raw_keys = frozenset(key for key in branches if key not in ENCODERS)

    @staticmethod
    def _leog_branch(space: spaces.Box, settings: Mapping[str, Any], architecture: Mapping[str, Any] | None, precomputed: bool) -> _LeogBranch:
        if precomputed:
            encoder, size = None, space.shape[0]
        else:
            if architecture is None:
                architecture = leog_architecture(space.shape, settings["leog_channels"], settings["leog_kernels"],
                                                 settings["leog_strides"], settings["leog_latent"])
            elif list(architecture["grid_shape"]) != list(space.shape):
                raise ValueError(
                    f"the pre-trained LEOG encoder expects grids of shape {tuple(architecture['grid_shape'])}, "
                    f"but the environment's leog has shape {space.shape}; match the scenario's sensors.leog size/resolution"
                )
            encoder = LeogEncoder(dict(architecture))
            size = encoder.latent
        head, out = mlp(size, settings["leog_head"])
        return _LeogBranch(encoder, head, out)

    def load_leog_encoder(self, state_dict: Mapping[str, torch.Tensor]) -> None:
        """Copy pre-trained weights into the LEOG encoder (frozen/finetune start)."""
        if not self.leog_encoders:
            raise ValueError("this extractor has no LEOG encoder to load weights into")
        for encoder in self.leog_encoders:
            encoder.load_state_dict(state_dict)

    def prepare(self, observations: dict[str, torch.Tensor], normalize_images: bool) -> dict[str, torch.Tensor]:
        """The extractor's input from the sampled tensors, in place of SB3's ``preprocess_obs``.

        The built-in branches get float32 vectors as SB3 would give them (``float()``, which is the
        same tensor for float32), but grids as sampled: the LEOG branch only asks which cells are
        non-zero, the same answer before and after SB3's ``float() / 255`` (and binarizing the
        sampled tensor lets the actor, critic and target networks share the work, see binarize).
        Registered encoders get SB3's preprocessing.
        """
        prepared = {}
        for key, space in self.boxes.items():
            value = observations[key]
            if key not in self.raw_keys:
                processed = preprocess_obs(value, space, normalize_images=normalize_images)
                if isinstance(processed, dict):  # SB3 returns a dict only for a Dict space, and these are Boxes
                    raise TypeError(f"observation {key!r}: preprocess_obs returned a dict for {space}")
                value = processed
            elif len(space.shape) != 3 and value.dtype != torch.float32:
                value = value.float()
            prepared[key] = value
        return prepared

    def forward(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
        return torch.cat([branch(observations[key]) for key, branch in self.branches.items()], dim=1)
