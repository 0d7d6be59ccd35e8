"""A trained policy as one ONNX file: the raw env observation in, the deterministic action out.

:func:`export_onnx` writes what :class:`crowdnav.agents.AgentPolicy` computes, as a graph a robot can run
with onnxruntime alone (no torch, no Stable-Baselines3, no crowdnav; docs/deploy.md):

* **inputs**: one per observation key, named after it, with the raw
  :class:`crowdnav.envs.CrowdNavEnv` dtype and shape plus a leading batch axis (float32 vectors,
  the LEOG grid as uint8 ``(batch, 1, H, W)``);
* **inside**: the observation normalisation stored with the checkpoint (``(x - offset) / scale``
  per key), the frozen LEOG encoder when the model was trained on its latents, then the module the
  agent's ``export_module`` gives (:class:`crowdnav.agents.training.algorithm_protocol.Exportable`, every
  algorithm alike): for the SB3 algorithms :class:`SB3Actor`, the features extractor and the actor's
  deterministic action (SAC: ``tanh`` of the Gaussian's mean; TD3 / DDPG: the actor; PPO / A2C: the
  mean, clipped to [-1, 1]), then SB3's mapping to the action space's bounds; for ``sarl`` the
  lookahead, value network and argmax (:mod:`crowdnav.agents.sarl.export`). An agent without
  ``export_module`` is refused in one line;
* **output** ``action``: float32 ``(batch, 2)`` in [-1, 1], what ``policy(observation)`` returns
  (holonomic ``(vx, vy)`` in the robot frame, or unicycle ``(v, omega)``, times the max speeds).
* a recurrent policy (an LSTM, :class:`RecurrentSB3Actor`) carries its state through the graph: inputs ``lstm_h``,
  ``lstm_c`` (``(layers, batch, hidden)``) and ``episode_start`` (``(batch,)``, 1.0 where an episode begins) after the
  observation keys, outputs ``next_lstm_h`` and ``next_lstm_c`` after ``action`` (docs/deploy.md).

The file's metadata (``custom_metadata_map`` in onnxruntime) holds ``crowdnav.env_options`` (the
CrowdNavEnv options, JSON), ``crowdnav.algo`` and ``crowdnav.observation`` (key -> shape and dtype).
The TorchScript exporter (``dynamo=False``, still in torch 2.13 though no longer the default) is
used: the ``torch.export``-based one needs the extra package onnxscript and (torch 2.13) stops at
a data-dependent guard in SB3's Normal distribution for PPO / A2C. Tests check that onnxruntime
matches the torch policy to 1e-5 on recorded observations, for SAC, TD3, PPO and the LEOG, and
SARL's actions in every library scenario it drives (tests/agents/test_sarl_export.py).
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from crowdnav.agents.training.space_checks import box_space, dict_space
from torch import nn

from crowdnav.errors import CrowdNavError
from crowdnav.files import replacing

OPSET = 17
ACTION_OUTPUT = "action"
EPISODE_START_INPUT = "episode_start"
"""A recurrent policy's input: 1.0 for the rows whose episode begins at this step (their state is forgotten), else 0.0."""


class ExportError(CrowdNavError, ValueError):
    """A policy that cannot be exported, or an output that cannot be written; one line."""


class SB3Actor(nn.Module):
    """An SB3 policy's deterministic action from the model's input tensors (in ``keys`` order), mapped to the action space."""

    low: torch.Tensor  # the action space's bounds (buffers), declared for the type checker
    high: torch.Tensor

    def __init__(self, model: Any, keys: list[str]):
        super().__init__()
        self.keys = list(keys)
        self.network = model.policy
        self.network.set_training_mode(False)
        for module in self.network.modules():  # the plain formulas: no per-batch caches in a traced graph
            if hasattr(module, "reference"):
                module.reference = True
        space = model.action_space
        self.register_buffer("low", torch.as_tensor(space.low, dtype=torch.float32))
        self.register_buffer("high", torch.as_tensor(space.high, dtype=torch.float32))
        self.squash = bool(self.network.squash_output)

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        actions = self.network._predict(dict(zip(self.keys, inputs, strict=True)), deterministic=True)
        if self.squash:  # SB3's predict: unscale_action, else clip to the action space
            return self.low + 0.5 * (actions + 1.0) * (self.high - self.low)
        return torch.clamp(actions, self.low, self.high)


class RecurrentSB3Actor(SB3Actor):
    """An sb3-contrib LSTM policy's deterministic action and next state: ``(*inputs, h, c, episode_start) -> (action, h, c)``.

    One step of ``RecurrentActorCriticPolicy._predict`` written without its data-dependent branch (which a trace
    would freeze): the actor's LSTM state is zeroed where ``episode_start`` is 1, stepped once on the features, and its
    output read by the actor's MLP and mean. ``h`` and ``c`` are what ``predict`` returns as its state:
    ``(lstm layers, batch, hidden)``, batch on axis 1, zeros (or anything, with ``episode_start`` 1) at an episode's start.
    """

    state_names = ("lstm_h", "lstm_c")
    """The ONNX inputs of the state (outputs ``next_lstm_h``, ``next_lstm_c``); then the input ``episode_start`` (batch,)."""

    def __init__(self, model: Any, keys: list[str]):
        super().__init__(model, keys)
        self.state_shape = tuple(self.network.lstm_hidden_state_shape)  # (layers, 1, hidden): the batch axis is 1

    def forward(self, *inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:  # type: ignore[override]
        *observation, h, c, start = inputs
        policy = self.network
        from stable_baselines3.common.policies import BaseModel

        # the grandparent's extract_features, as sb3-contrib's policy calls it (SB3's input preprocessing, then the extractor)
        features = BaseModel.extract_features(policy, dict(zip(self.keys, observation, strict=True)), policy.pi_features_extractor)
        keep = (1.0 - start.float()).view(1, -1, 1)
        output, (h, c) = policy.lstm_actor(features.unsqueeze(0), (keep * h, keep * c))
        actions = policy.action_net(policy.mlp_extractor.forward_actor(output.flatten(0, 1)))
        if self.squash:
            return self.low + 0.5 * (actions + 1.0) * (self.high - self.low), h, c
        return torch.clamp(actions, self.low, self.high), h, c


def sb3_actor(model: Any, keys: list[str]) -> SB3Actor:
    """The exported module of an SB3 model: :class:`RecurrentSB3Actor` for an LSTM policy, else :class:`SB3Actor`."""
    from crowdnav.agents.training.algorithm_protocol import has_lstm_policy

    return RecurrentSB3Actor(model, keys) if has_lstm_policy(model) else SB3Actor(model, keys)


class DeployablePolicy(nn.Module):
    """Raw observation tensors (in :attr:`keys` order) -> deterministic actions, as :class:`crowdnav.agents.AgentPolicy` computes them.

    The checkpoint's observation normalisation and frozen LEOG encoder, then ``actor``: the model's input tensors in
    :attr:`keys` order -> actions (:class:`SB3Actor`, or a registered algorithm's
    :meth:`~crowdnav.agents.training.algorithm_protocol.Exportable.export_module`).
    """

    def __init__(self, policy: Any, keys: list[str], actor: nn.Module):
        super().__init__()
        self.keys = list(keys)
        scales = policy.scales or {}
        self.scaled = [key in scales for key in self.keys]
        for i, key in enumerate(self.keys):
            if key in scales:
                offset, scale = scales[key]
                self.register_buffer(f"offset_{i}", torch.as_tensor(np.asarray(offset, dtype=np.float32)))
                self.register_buffer(f"scale_{i}", torch.as_tensor(np.asarray(scale, dtype=np.float32)))
        self.encoder = policy.encoder  # the frozen LEOG encoder whose latents the model was trained on, or None
        self.actor = actor

    def forward(self, *inputs: torch.Tensor) -> Any:
        model_inputs = []
        carried = inputs[len(self.keys):]  # a recurrent actor's state and episode starts, passed as they are
        for i, (key, value) in enumerate(zip(self.keys, inputs[:len(self.keys)], strict=True)):
            if self.scaled[i]:  # crowdnav.agents.training.wrappers.normalize_observation, in float32
                value = (value.float() - getattr(self, f"offset_{i}")) / getattr(self, f"scale_{i}")
            elif key == "leog" and self.encoder is not None:  # crowdnav.agents.training.wrappers.encode_grids
                value = self.encoder((value > 0).float())
            model_inputs.append(value)
        return self.actor(*model_inputs, *carried)


def actor_of(policy: Any, keys: list[str], policy_path: str | Path) -> nn.Module:
    """What acts inside the graph: the module the policy's agent gives (:class:`~crowdnav.agents.training.algorithm_protocol.Exportable`).

    Every algorithm alike: an SB3 one's agent (:class:`crowdnav.agents.sb3.algorithm.SB3Algorithm`) gives an
    :class:`SB3Actor`. Raises :class:`ExportError` (one line) for an agent without ``export_module``.
    """
    from crowdnav.agents.training.algorithm_protocol import Exportable

    if not isinstance(policy.agent, Exportable):
        raise ExportError(f"{policy_path}: algorithm {policy.algo!r} has no ONNX export: its agent has no export_module() "
                          "(crowdnav.agents.training.algorithm_protocol.Exportable)")
    try:
        return policy.agent.export_module(keys)
    except ValueError as error:
        raise ExportError(f"{policy_path}: {str(error).splitlines()[0]}") from None


def export_onnx(policy_path: str | Path, out: str | Path, *, opset: int = OPSET) -> Path:
    """Write the policy at ``policy_path`` (a crowdnav run folder or checkpoint) to ``out`` as ONNX; returns ``out``.

    Only the checkpoint's parameters are read (:func:`crowdnav.agents.load_policy`). Raises
    :class:`ExportError` for a folder that holds no loadable policy.
    """
    from crowdnav.agents.runs.checkpoint import load_policy
    from crowdnav.agents.runs.folder import training_run

    path = training_run(policy_path)
    try:
        policy = load_policy(path)
    except (FileNotFoundError, ValueError) as error:
        line = str(error).splitlines()[0]  # most messages name the checkpoint already
        raise ExportError(line if line.startswith((str(policy_path), str(path))) else f"{policy_path}: {line}") from None
    env = policy.make_env()
    try:
        raw = dict_space(env.observation_space)
        example, _ = env.reset(seed=0)
    finally:
        env.close()
    keys = list(raw.spaces)
    actor = actor_of(policy, keys, policy_path)
    module = DeployablePolicy(policy, keys, actor).eval()
    inputs = tuple(torch.as_tensor(np.asarray(example[key])[None]) for key in keys)
    states: tuple[str, ...] = tuple(getattr(actor, "state_names", ()))  # a recurrent actor: its state in and out, batch on axis 1
    state_shape: list[int] = list(getattr(actor, "state_shape", ()))
    if states:
        inputs += (*(torch.zeros(state_shape) for _ in states), torch.ones(1))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    outputs = [ACTION_OUTPUT, *(f"next_{name}" for name in states)]
    names = [*keys, *states, *([EPISODE_START_INPUT] if states else [])]
    axes = {name: {0: "batch"} for name in (*keys, ACTION_OUTPUT, *([EPISODE_START_INPUT] if states else []))}
    axes.update({name: {1: "batch"} for name in (*states, *outputs[1:])})
    validate = torch.distributions.Distribution._validate_args
    # PPO / A2C build a Normal to take its mean: its argument checks only test values, and traced they become constants
    torch.distributions.Distribution.set_default_validate_args(False)
    # written whole under a temporary name, then renamed over ``out``: a link at ``out`` is replaced, never written through
    with replacing(out, suffix=".onnx") as temporary:
        try:
            with torch.no_grad(), warnings.catch_warnings():
                warnings.filterwarnings("ignore", category=DeprecationWarning, module=r"torch\.onnx.*|crowdnav\.agents\.onnx_export")
                warnings.filterwarnings("ignore", category=DeprecationWarning, message=".*legacy TorchScript-based ONNX export.*")
                # an LSTM's warning for graphs whose initial state is a constant; ours are inputs (tested at batch 2)
                warnings.filterwarnings("ignore", category=UserWarning, message="Exporting a model to ONNX with a batch_size other than 1")
                torch.onnx.export(module, inputs, str(temporary), input_names=names, output_names=outputs,
                                  dynamic_axes=axes, opset_version=opset, dynamo=False)
        finally:
            torch.distributions.Distribution.set_default_validate_args(validate)
        _add_metadata(temporary, {
            "crowdnav.env_options": json.dumps(policy.env_options, sort_keys=True),
            "crowdnav.algo": policy.algo,
            **({"crowdnav.state": json.dumps({name: state_shape for name in states})} if states else {}),
            "crowdnav.observation": json.dumps({key: {"shape": list(box_space(raw, key).shape), "dtype": str(space.dtype)}
                                              for key, space in raw.spaces.items()}),
        })
    return out


def _add_metadata(path: Path, properties: Mapping[str, str]) -> None:
    """Store ``properties`` in the ONNX file's ``metadata_props`` (and check the model)."""
    import onnx

    model = onnx.load(str(path))
    for key, value in properties.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
