"""Gaussian radial-basis-function layer: lifts a few bounded numbers into many smooth features.

Low-dimensional inputs (the goal's distance and bearing, the closest obstacle, the velocity)
are hard for a small MLP to resolve finely; expanding each value over a row of Gaussian bumps
gives the next layer a local, nearly one-hot code of it (the paper's RBF layer).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from crowdnav.agents.networks import batch_cache
from torch import nn


class GaussianRBF(nn.Module):
    """Per-value Gaussian RBF expansion: (B, d) -> (B, d * (centres + keep_input)).

    Each input value ``x_i`` is first scaled to ``z_i`` in [-1, 1] using its bounds
    (``2 (x - low) / (high - low) - 1``; a value with an infinite bound is squashed with
    ``tanh`` instead). Feature ``(i, k)`` is ``exp(-(z_i - c_k)^2 / (2 s^2))`` with ``centres``
    centres ``c_k`` evenly spread over [-1, 1] and ``s`` their spacing (neighbours overlap at
    ``exp(-1/2)``). With ``keep_input`` the scaled values ``z`` come first in the output, so
    the exact value is not lost between bumps (``centres=0``: the scaled values only). With ``trainable`` the centres and widths
    (per value) are learned, starting from that layout.
    """

    reference = False  # True: always the plain formula (reference_forward), for benchmarks/bench_train.py's reference timing
    # buffers (register_buffer) and, when trainable, parameters: declared for the type checker
    centre: torch.Tensor
    log_width: torch.Tensor
    _scale: torch.Tensor
    _offset: torch.Tensor
    _finite: torch.Tensor
    _repeat: torch.Tensor

    def __init__(self, low: np.ndarray, high: np.ndarray, centres: int = 16, trainable: bool = False, keep_input: bool = True):
        super().__init__()
        low, high = np.asarray(low, dtype=np.float64).ravel(), np.asarray(high, dtype=np.float64).ravel()
        if low.shape != high.shape:
            raise ValueError(f"low and high must have the same shape, got {low.shape} and {high.shape}")
        if centres < 0 or (centres == 0 and not keep_input):
            raise ValueError(f"centres must be >= 1 (or 0 with keep_input: scaling only), got {centres}")
        if np.any(high <= low):
            raise ValueError(f"every bound must satisfy low < high, got low={low.tolist()} high={high.tolist()}")
        finite = np.isfinite(low) & np.isfinite(high)
        span = np.where(finite, high - low, 2.0)
        self.in_features = low.size
        self.centres = centres
        self.keep_input = keep_input
        self.out_features = self.in_features * (centres + int(keep_input))
        scale = 2.0 / span
        # z = x * scale + offset, i.e. 2 (x - low) / (high - low) - 1
        self.register_buffer("_scale", torch.as_tensor(scale, dtype=torch.float32))
        self.register_buffer("_offset", torch.as_tensor(np.where(finite, -low * scale - 1.0, 0.0), dtype=torch.float32))
        self.register_buffer("_finite", torch.as_tensor(finite))
        self._all_finite = bool(finite.all())
        grid = torch.linspace(-1.0, 1.0, centres) if centres > 1 else torch.zeros(centres)
        spacing = 2.0 / (centres - 1) if centres > 1 else 1.0
        centre = grid.repeat(self.in_features, 1)  # (d, K)
        log_width = torch.full((self.in_features, centres), float(np.log(spacing)))
        if trainable:
            self.centre, self.log_width = nn.Parameter(centre), nn.Parameter(log_width)
        else:
            self.register_buffer("centre", centre)
            self.register_buffer("log_width", log_width)
        # fixed centres and widths: every constant of the expansion precomputed, flattened in output order
        self.register_buffer("_repeat", torch.arange(self.in_features).repeat_interleave(centres), persistent=False)
        self._constants: tuple[tuple[Any, ...], tuple[Any, ...], torch.Tensor, torch.Tensor] | None = None

    def scaled(self, x: torch.Tensor) -> torch.Tensor:
        """Inputs mapped to [-1, 1] (affinely from finite bounds, tanh otherwise)."""
        z = torch.addcmul(self._offset, x, self._scale)
        return z if self._all_finite else torch.where(self._finite, z, torch.tanh(x))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if (self.reference or self.centres == 0 or not self._all_finite or isinstance(self.centre, nn.Parameter)
                or torch.is_grad_enabled() and x.requires_grad):
            return self.reference_forward(x)
        key, _, _ = self._fixed_constants()
        return batch_cache.cached(key, x, self._expand)  # once per sampled batch for all the networks reading it

    def _expand(self, x: torch.Tensor) -> torch.Tensor:
        # The same elementwise ops as reference_forward, on the same values in the same order (so the
        # same result to the last bit), in 8 tensor ops instead of 11 and without the (B, d, K) broadcasts.
        _, centre, inverse_width = self._fixed_constants()
        z = torch.addcmul(self._offset, x, self._scale)
        features = torch.index_select(z, 1, self._repeat).sub_(centre).mul_(inverse_width).square_().mul_(-0.5).exp_()
        return torch.cat((z, features), dim=1) if self.keep_input else features

    def _fixed_constants(self) -> tuple[tuple[Any, ...], torch.Tensor, torch.Tensor]:
        """(cache key naming the constants by value, flattened centres, 1 / widths as reference_forward computes them).

        Remade when a constant changes (load_state_dict, .to()).
        """
        buffers = (self.centre, self.log_width, self._scale, self._offset)
        versions = tuple((id(t), t._version) for t in buffers)
        if self._constants is None or self._constants[0] != versions:
            with torch.no_grad():
                key = ("rbf", self.keep_input, batch_cache.fingerprint(*buffers))
                self._constants = (versions, key, self.centre.flatten().clone(), torch.exp(-self.log_width).flatten())
        return self._constants[1], self._constants[2], self._constants[3]

    def reference_forward(self, x: torch.Tensor) -> torch.Tensor:
        """The plain formula (trainable centres and widths, infinite bounds; the reference the fast path is tested against)."""
        z = self.scaled(x)
        if self.centres == 0:
            return z
        distance = (z.unsqueeze(-1) - self.centre) * torch.exp(-self.log_width)  # (B, d, K) in widths
        features = torch.exp(distance.square().mul_(-0.5)).flatten(1)
        return torch.cat((z, features), dim=1) if self.keep_input else features

    def extra_repr(self) -> str:
        return f"in_features={self.in_features}, centres={self.centres}, keep_input={self.keep_input}, out_features={self.out_features}"
