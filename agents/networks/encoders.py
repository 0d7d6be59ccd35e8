"""The per-modality networks: LEOG CNN (and its autoencoder decoder), LIDAR and low-dimensional branches.

The LEOG encoder is the part that can be pre-trained: convolutions, flatten, one fully
connected layer with a tanh, so its latent lies in [-1, 1] (a fixed scale for the agent's
heads, and a fixed Box for the observation wrapper of frozen mode). Its architecture is a
plain dict (:func:`leog_architecture`) stored next to pre-trained weights.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any, cast

import numpy as np
import torch
import torch.nn.functional as F
from crowdnav.agents.networks import batch_cache
from crowdnav.agents.networks.rbf import GaussianRBF
from torch import nn


class MLP(nn.Module):
    """Linear layers, each followed by a ReLU (applied functionally: fewer modules for SB3 to walk
    through on every ``set_training_mode``, which it calls twice per step). The layers are applied
    with ``F.linear`` on their weights, which is what ``nn.Linear.forward`` does, without the cost of
    a module call (forward hooks on the inner ``nn.Linear`` layers are therefore not called)."""

    def __init__(self, in_features: int, hidden: Sequence[int]):
        super().__init__()
        sizes = [in_features, *hidden]
        self.layers = nn.ModuleList(nn.Linear(a, b) for a, b in zip(sizes, sizes[1:], strict=False))
        self.out_features = sizes[-1]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # a ModuleList yields Modules: these are the nn.Linear built above (one cast per call, none per layer)
        for layer in cast("Iterable[nn.Linear]", self.layers):
            x = torch.relu(F.linear(x, layer.weight, layer.bias))
        return x


def mlp(in_features: int, hidden: Sequence[int]) -> tuple[nn.Module, int]:
    """:class:`MLP` (identity when ``hidden`` is empty) and its output size."""
    module = MLP(in_features, hidden)
    return module, module.out_features


def leog_architecture(grid_shape: Sequence[int], channels: Sequence[int], kernels: Sequence[int],
                      strides: Sequence[int], latent: int) -> dict[str, Any]:
    """The JSON-able description a :class:`LeogEncoder` is built from (and saved with)."""
    return {"grid_shape": [int(v) for v in grid_shape], "channels": [int(v) for v in channels],
            "kernels": [int(v) for v in kernels], "strides": [int(v) for v in strides], "latent": int(latent)}


def conv_sizes(architecture: dict[str, Any]) -> list[tuple[int, int]]:
    """Spatial size (H, W) of the grid before the first convolution and after each one."""
    _, height, width = architecture["grid_shape"]
    sizes = [(height, width)]
    for kernel, stride in zip(architecture["kernels"], architecture["strides"], strict=True):
        height, width = (height - kernel) // stride + 1, (width - kernel) // stride + 1
        if height < 1 or width < 1:
            raise ValueError(
                f"LEOG convolutions {architecture['kernels']} (strides {architecture['strides']}) do not fit a "
                f"{architecture['grid_shape'][1]}x{architecture['grid_shape'][2]} grid; use fewer or smaller layers"
            )
        sizes.append((height, width))
    return sizes


class LeogEncoder(nn.Module):
    """Occupancy grid (B, 1, H, W) of 0/1 floats -> latent (B, latent) in [-1, 1].

    Convolutions without padding, each followed by a ReLU, then flatten, Linear and tanh.
    """

    def __init__(self, architecture: dict[str, Any]):
        super().__init__()
        self.architecture = dict(architecture)
        sizes = conv_sizes(architecture)
        layers: list[nn.Module] = []
        in_channels = architecture["grid_shape"][0]
        for out_channels, kernel, stride in zip(architecture["channels"], architecture["kernels"], architecture["strides"], strict=True):
            layers += [nn.Conv2d(in_channels, out_channels, kernel, stride), nn.ReLU()]
            in_channels = out_channels
        self.conv = nn.Sequential(*layers)
        self.flat_features = in_channels * sizes[-1][0] * sizes[-1][1]
        self.fc = nn.Linear(self.flat_features, architecture["latent"])
        self.norm = nn.LayerNorm(architecture["latent"])
        self.latent = int(architecture["latent"])

    def forward(self, grid: torch.Tensor) -> torch.Tensor:
        return torch.tanh(self.norm(self.fc(self.conv(grid).flatten(1))))


class LeogDecoder(nn.Module):
    """Latent -> occupancy logits (B, 1, H, W): the mirror image of a :class:`LeogEncoder`.

    ``width`` multiplies its channels: the decoder is dropped after pre-training, so it can be
    wider than the encoder at no cost to the agent (a 4x4-stride-4 last layer with only 8
    channels can draw few shapes per 4x4 block, too few for thin walls at any angle).
    """

    def __init__(self, architecture: dict[str, Any], width: int = 1):
        super().__init__()
        sizes = conv_sizes(architecture)
        channels = [architecture["grid_shape"][0], *(c * width for c in architecture["channels"])]
        self.start_shape = (channels[-1], *sizes[-1])
        self.fc = nn.Linear(architecture["latent"], int(np.prod(self.start_shape)))
        layers: list[nn.Module] = []
        steps = list(zip(architecture["kernels"], architecture["strides"], strict=True))
        for index in reversed(range(len(steps))):
            kernel, stride = steps[index]
            target = sizes[index]
            produced = [(sizes[index + 1][axis] - 1) * stride + kernel for axis in (0, 1)]
            # the encoder's floor division dropped up to stride - 1 rows/columns: add them back
            padding = tuple(target[axis] - produced[axis] for axis in (0, 1))
            deconv = nn.ConvTranspose2d(channels[index + 1], channels[index], kernel, stride, output_padding=padding)
            layers.append(deconv)
            if index > 0:
                layers.append(nn.ReLU())
        # Zero last layer (the deconvolution of index 0): the untrained decoder predicts p = 0.5 everywhere
        # (loss ln 2 whatever the seed), and learning starts from that neutral guess.
        nn.init.zeros_(deconv.weight)
        if deconv.bias is not None:  # always: built with the default bias=True
            nn.init.zeros_(deconv.bias)
        self.deconv = nn.Sequential(*layers)

    def forward(self, latent: torch.Tensor) -> torch.Tensor:
        hidden = torch.relu(self.fc(latent)).view(-1, *self.start_shape)
        return self.deconv(hidden)


class LeogAutoencoder(nn.Module):
    """Encoder + decoder; ``forward`` returns reconstruction logits (train with BCE-with-logits)."""

    def __init__(self, architecture: dict[str, Any], decoder_width: int = 1):
        super().__init__()
        self.encoder = LeogEncoder(architecture)
        self.decoder = LeogDecoder(architecture, decoder_width)

    def forward(self, grid: torch.Tensor) -> torch.Tensor:
        return self.decoder(self.encoder(grid))


class LidarEncoder(nn.Module):
    """Scan (B, beams) -> features: proximity, optional circular 1-D convolutions, fully connected layers.

    The readings are first turned into proximities ``(high - x) / (high - low)`` (0 where a beam
    sees nothing, 1 at contact), so an empty scan is all zeros. Fed as they are, the many
    readings that sit at 1 together would act like a bias whose effective learning rate grows
    with the number of beams (Adam moves every weight by about the same step), and SAC then
    fails to learn in open space. The circular padding lets a 360-degree scan wrap around
    (the first and last beams are neighbours).
    """

    _high: torch.Tensor  # buffers (register_buffer), declared for the type checker
    _scale: torch.Tensor

    def __init__(self, low: np.ndarray, high: np.ndarray, hidden: Sequence[int], conv_channels: Sequence[int] = (),
                 kernel: int = 5, stride: int = 2):
        super().__init__()
        low, high = np.asarray(low, dtype=np.float32).ravel(), np.asarray(high, dtype=np.float32).ravel()
        finite = np.isfinite(low) & np.isfinite(high)
        self.register_buffer("_high", torch.as_tensor(np.where(finite, high, 0.0)))
        self.register_buffer("_scale", torch.as_tensor(np.where(finite, 1.0 / np.where(finite, high - low, 1.0), -1.0)))
        beams = low.size
        layers: list[nn.Module] = []
        in_channels, length = 1, beams
        for out_channels in conv_channels:
            layers += [nn.Conv1d(in_channels, out_channels, kernel, stride, padding=kernel // 2, padding_mode="circular"), nn.ReLU()]
            length = (length + 2 * (kernel // 2) - kernel) // stride + 1
            in_channels = out_channels
        self.conv = nn.Sequential(*layers) if layers else None
        self.fc, self.out_features = mlp(in_channels * length, hidden)
        self._key: tuple[Any, ...] | None = None

    reference = False  # True: the proximities computed on every call, for benchmarks/bench_train.py's reference timing

    def proximity(self, scan: torch.Tensor) -> torch.Tensor:
        """``(high - scan) / (high - low)`` per beam, once per sampled batch (:mod:`crowdnav.agents.networks.batch_cache`)."""
        if self.reference:
            return self._proximity(scan)
        versions = ((id(self._high), self._high._version), (id(self._scale), self._scale._version))
        if self._key is None or self._key[0] != versions:
            self._key = (versions, ("lidar", batch_cache.fingerprint(self._high, self._scale)))
        return batch_cache.cached(self._key[1], scan, self._proximity)

    def _proximity(self, scan: torch.Tensor) -> torch.Tensor:
        return (self._high - scan) * self._scale

    def forward(self, scan: torch.Tensor) -> torch.Tensor:
        proximity = self.proximity(scan)
        if self.conv is not None:
            proximity = self.conv(proximity.unsqueeze(1)).flatten(1)
        return self.fc(proximity)


class TableEncoder(nn.Module):
    """A table of rows (B, rows, features), e.g. the ``humans`` modality's nearest humans -> flattened -> fully connected layers.

    The rows come sorted (nearest human first) and absent ones are zeros with a presence flag, so
    a plain MLP on the flattened table sees each slot at a fixed place.
    """

    def __init__(self, shape: Sequence[int], hidden: Sequence[int]):
        super().__init__()
        self.fc, self.out_features = mlp(int(np.prod(shape)), hidden)

    def forward(self, table: torch.Tensor) -> torch.Tensor:
        return self.fc(table.flatten(1))


class LowDimEncoder(nn.Module):
    """A few bounded values -> Gaussian RBF expansion -> fully connected layers."""

    def __init__(self, low: np.ndarray, high: np.ndarray, centres: int, hidden: Sequence[int], trainable: bool = False):
        super().__init__()
        self.rbf = GaussianRBF(low, high, centres, trainable=trainable)  # centres=0: scaling to [-1, 1] only
        self.fc, self.out_features = mlp(self.rbf.out_features, hidden)

    def forward(self, values: torch.Tensor) -> torch.Tensor:
        return self.fc(self.rbf(values))
