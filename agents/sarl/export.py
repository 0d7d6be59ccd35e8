"""ONNX export of the SARL-style agent: :meth:`SarlAgent.predict` (deterministic) as one torch module.

:class:`SarlPolicyModule` is what :meth:`crowdnav.agents.sarl.agent.SarlAgent.export_module` returns (the
``export_module`` side of :class:`crowdnav.agents.training.algorithm_protocol.Exportable`): the observation as ``predict``
receives it (crowdnav's normalisation already applied, batch first) in, the action ``(batch, 2)`` float32 out.

Shared with ``predict``: the per-state maths of :mod:`~crowdnav.agents.sarl.lookahead`, the very functions the agent
acts with, run here on torch tensors (:class:`TorchOps`, float64 as numpy's, the value network in float32):

* :func:`~crowdnav.agents.sarl.lookahead.decode`: the agent's stored scales undone, a polar goal made cartesian,
  the humans' absolute velocities;
* :func:`~crowdnav.agents.sarl.lookahead.lookahead`: the 81 actions, the humans at constant velocity, the closest
  approach during the step, the predicted reward and end;
* :func:`~crowdnav.agents.sarl.lookahead.features` and
  :func:`~crowdnav.agents.sarl.lookahead.value_ceiling` (``value_bound``);
* :func:`~crowdnav.agents.sarl.lookahead.backup` (``r + discount * V * (not done)``) and, with ``lookahead_depth: 2``,
  :func:`~crowdnav.agents.sarl.lookahead.deepen` (the ``lookahead_width`` best actions looked ahead once more: ``topk``,
  ``gather`` and ``scatter`` here where numpy sorts and indexes).

Written here: the module and its buffers (actions, scales), the value network on the features, and the first best
action (``argmax`` as numpy's) and its command. Without the ``obstacles`` modality the graph holds no static tensors at
all (``decode(..., empty_static=False)``), where numpy carries empty ones.

The only differences left are those of the kernels: ``hypot`` is ``sqrt(x * x + y * y)`` here (ONNX has none), and
onnxruntime's float32 matrix products and ``exp`` may round otherwise than torch's. They move a score by about 1e-7
of its size, which changes the chosen action only where two actions score that close (tests/agents/test_sarl_export.py;
none seen so far: the graph's actions have equalled ``predict``'s bit for bit).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import torch
from crowdnav.agents.sarl.lookahead import GEODESIC_KEY, REQUIRED_KEYS, STATIC_KEY, backup, decode, deepen, features, lookahead, value_ceiling
from crowdnav.agents.sarl.ops import Ops
from torch import nn

F64 = torch.float64


class TorchOps:
    """:class:`~crowdnav.agents.sarl.ops.Ops` in torch, in the calls the ONNX exporter (TorchScript) writes as numpy computes."""

    def float64(self, x: Any) -> Any:
        return x.to(F64)

    def float32(self, x: Any) -> Any:
        return x.to(torch.float32)

    def int64(self, x: Any) -> Any:
        return x.to(torch.int64)

    def norm(self, vectors: Any) -> Any:  # numpy's hypot (ONNX has none)
        x, y = vectors[..., 0], vectors[..., 1]
        return torch.sqrt(x * x + y * y)

    def stack(self, arrays: Sequence[Any]) -> Any:
        return torch.stack(list(arrays), dim=-1)

    def concatenate(self, arrays: Sequence[Any]) -> Any:
        return torch.cat(list(arrays), dim=-1)

    def sum(self, x: Any, axis: int) -> Any:
        return torch.sum(x, dim=axis)

    def any(self, x: Any) -> Any:  # a sum: ONNX reduces no booleans
        return x.to(F64).sum(dim=-1) > 0

    def where(self, condition: Any, a: Any, b: Any) -> Any:
        def tensor(x: Any) -> Any:  # a float branch: a float64 tensor of the condition's shape
            return x if isinstance(x, torch.Tensor) else torch.zeros_like(condition, dtype=F64) + x

        return torch.where(condition, tensor(a), tensor(b))

    def clip(self, x: Any, low: float, high: float) -> Any:
        return torch.clamp(x, low, high)

    def maximum(self, x: Any, low: float) -> Any:
        return torch.clamp(x, min=low)

    def minimum(self, x: Any, high: float) -> Any:
        return torch.clamp(x, max=high)

    def exp(self, x: Any) -> Any:
        return torch.exp(x)

    def floor(self, x: Any) -> Any:
        return torch.floor(x)

    def ceil(self, x: Any) -> Any:
        return torch.ceil(x)

    def power(self, base: float, exponent: Any) -> Any:
        return torch.pow(torch.full_like(exponent, base), exponent)

    def take(self, x: Any, index: Any) -> Any:
        return torch.gather(x, -1, index)

    def broadcast_to(self, x: Any, shape: Sequence[Any]) -> Any:
        return x.expand(*shape)

    def zeros_like(self, x: Any) -> Any:
        return torch.zeros_like(x)

    def zeros(self, shape: Sequence[int]) -> Any:
        return torch.zeros(tuple(shape), dtype=F64)

    def copy(self, x: Any) -> Any:
        return x.clone()

    def size(self, n: Any) -> int:
        with warnings.catch_warnings():  # the tracer fixes it: only the batch axis of the graph's inputs varies
            warnings.filterwarnings("ignore", message="Converting a tensor to a Python")  # torch's TracerWarning
            return int(n)

    def keep(self, done: Any) -> Any:
        return (~done).to(F64)

    def best(self, scores: Any, width: int) -> Any:  # onnxruntime's topk keeps the lower index of equal scores first
        return torch.topk(scores, width, dim=1).indices

    def rows(self, x: Any, index: Any) -> Any:
        picked = torch.gather(x, 1, index.reshape(*index.shape, *([1] * (x.dim() - 2))).expand(-1, -1, *x.shape[2:]))
        return picked.reshape(-1, *x.shape[2:])

    def row_max(self, x: Any) -> Any:
        return x.max(dim=1).values

    def spread(self, scores: Any, index: Any, values: Any) -> Any:
        return torch.full_like(scores, float("-inf")).scatter(1, index, values)


TORCH: Ops = TorchOps()
"""The backend the export traces (:mod:`~crowdnav.agents.sarl.lookahead`'s ``xp``)."""


class SarlPolicyModule(nn.Module):
    """``forward(*observation)`` (tensors in :attr:`keys` order, batch first) -> the agent's deterministic actions (batch, 2)."""

    actions: torch.Tensor  # (81, 2) goal-frame velocities, float64 (a buffer)

    def __init__(self, agent: Any, keys: Sequence[str]):
        super().__init__()
        missing = [key for key in REQUIRED_KEYS if key not in keys]
        if missing:
            raise ValueError(f"algorithm 'sarl' reads humans, goal and velocity; the observation has no {', '.join(missing)}")
        self.depth, self.width = int(agent.options["lookahead_depth"]), int(agent.options["lookahead_width"])
        if self.depth not in (1, 2):
            raise ValueError(f"algorithm 'sarl' with lookahead_depth {self.depth}: ONNX export covers depths 1 and 2")
        self.keys = list(keys)
        self.room = bool(agent.statics)  # it reads the walls and furniture (no static tensors in the graph otherwise)
        self.geodesic = bool(agent.geodesic)  # the distance to the goal around obstacles, on the modality's grid
        self.read = (*REQUIRED_KEYS, *((STATIC_KEY,) if self.room else ()), *((GEODESIC_KEY,) if self.geodesic else ()))
        missing = [key for key in self.read if key not in self.keys]
        if missing:
            raise ValueError(f"algorithm 'sarl' trained on {', '.join(missing)} reads it; the observation has no {', '.join(missing)}")
        self.index = {key: self.keys.index(key) for key in self.read}
        self.physics = agent.physics
        self.discount = float(agent.discount)
        self.register_buffer("actions", torch.as_tensor(agent.actions, dtype=F64))
        self.count = len(agent.actions)
        self.scaled = [key for key in self.read if key in agent.scales]
        for key in self.scaled:
            offset, scale = agent.scales[key]
            self.register_buffer(f"offset_{key}", torch.as_tensor(offset, dtype=F64))
            self.register_buffer(f"scale_{key}", torch.as_tensor(scale, dtype=F64))
        self.network = agent.network
        self.bounded = bool(agent.options["value_bound"])
        self.human_margin = float(agent.options["human_margin"])

    def decode(self, inputs: Sequence[torch.Tensor]) -> dict[str, torch.Tensor]:
        """The joint states (robot frame, float64) of the inputs (:func:`~crowdnav.agents.sarl.lookahead.decode`)."""
        scales = {key: (getattr(self, f"offset_{key}"), getattr(self, f"scale_{key}")) for key in self.scaled}
        return decode({key: inputs[self.index[key]] for key in self.read}, scales, TORCH, empty_static=False)

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        state = self.decode(inputs)
        ahead = lookahead(state, self.physics, self.actions, self.human_margin, TORCH)
        scores = backup(ahead, self.value, self.discount, TORCH)
        if self.depth > 1:
            scores = deepen(ahead, scores, self.width, self.value, self.physics, self.actions, self.human_margin, self.discount, TORCH)
        choice = torch.argmax(scores, dim=1)  # the first best, as numpy's
        return torch.gather(ahead["commands"], 1, choice[:, None, None].expand(-1, 1, 2))[:, 0, :]

    def value(self, state: Mapping[str, torch.Tensor]) -> torch.Tensor:
        """V of joint states (B, M) in float64: :func:`~crowdnav.agents.sarl.lookahead.features`, then the network."""
        robot, humans, statics = features(state, self.physics, TORCH)
        values = self.network(robot.reshape(-1, robot.shape[-1]), humans.reshape(-1, *humans.shape[-2:]),
                              None if statics is None else statics.reshape(-1, *statics.shape[-2:]))
        values = values.reshape(-1, self.count).to(F64)
        if not self.bounded:
            return values
        return torch.minimum(values, value_ceiling(TORCH.norm(state["goal"]), self.physics, self.discount, TORCH))
