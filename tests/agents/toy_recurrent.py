"""A recurrent learning algorithm outside Stable-Baselines3, for the recurrent-agent recipe's test (docs/architecture.md).

The toy of tests/agents/toy_algorithm.py (a linear policy trained by antithetic random search) given a memory: its
action is ``tanh(W [x, m, 1])``, where ``x`` is the flattened observation and ``m`` the mean of the observations of
the episode so far. What it carries from one step to the next, per world, is that running sum and the count of steps:
``predict`` returns it as its state, one float64 array ``(1, N, F + 1)`` (the batch on axis 1, as the ONNX export lays a
recurrent state out), and forgets a row where ``episode_start`` is True. ``learn`` keeps the state of the run's worlds
itself and forgets a world's when its episode ends; a checkpoint saves none (a resume starts new episodes in every world).
``export_module`` gives the same step as a torch module whose state goes in and out of the ONNX graph.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.vec_env import VecEnv
from torch import nn

from crowdnav.registry import AlgorithmSpec
from tests.agents.toy_algorithm import RandomSearchAgent

Memory = np.ndarray
"""(1, N, F + 1) float64: per world, the sum of the episode's observations (F) and their count."""


class RunningMeanAgent(RandomSearchAgent):
    """Implements crowdnav.agents.training.algorithm_protocol.Algorithm (and Exportable), with a memory."""

    recurrent = True
    """What evaluation, rendering and ``crowdnav export`` read: keep this agent's state per world, flag episode starts."""

    def __init__(self, env: VecEnv, config: Any):
        super().__init__(env, config)
        actions, inputs = self.weights.shape  # F + 1: the observation and the bias
        self.weights = np.zeros((actions, 2 * inputs - 1))  # [x, m, 1]

    # ------------------------------------------------------------------ the protocol

    def learn(self, env: VecEnv, keep_going: Callable[[], bool]) -> None:
        observation = env.reset()
        returns = np.zeros(env.num_envs)
        memory, starts = None, np.ones(env.num_envs, dtype=bool)
        while True:
            if self.delta is None:
                self.delta = self.rng.standard_normal(self.weights.shape)
            sign = 1.0 if self.plus_return is None else -1.0
            actions, memory = self._step(self.weights + sign * self.noise * self.delta, observation, memory, starts)
            observation, rewards, dones, _ = env.step(actions)
            starts = dones  # an ended world was reset in the same step: its next observation begins an episode
            returns += rewards
            for world in np.flatnonzero(dones):
                self._ended(float(returns[world]))
                returns[world] = 0.0
                if not keep_going():
                    return

    def predict(self, observation: Mapping[str, np.ndarray], state: Memory | None = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, Memory]:
        first = next(iter(self.shapes))
        batched = np.ndim(observation[first]) > len(self.shapes[first])
        if not batched:  # one observation: a batch of one
            observation = {key: np.asarray(value)[None] for key, value in observation.items()}
        actions, memory = self._step(self.weights, observation, state, episode_start)
        return (actions if batched else actions[0]), memory

    def export_module(self, keys: Sequence[str]) -> nn.Module:
        return RunningMeanModule(self.weights, [list(keys).index(key) for key in self.shapes], self._features_size())

    # ------------------------------------------------------------------ helpers

    def _features_size(self) -> int:
        return sum(int(np.prod(shape)) for shape in self.shapes.values())

    def _step(self, weights: np.ndarray, observation: Mapping[str, np.ndarray], memory: Memory | None,
              starts: np.ndarray | None) -> tuple[np.ndarray, Memory]:
        """The actions of a batch and the memory after this step (a new array: the caller's is left as it was)."""
        x = np.concatenate([np.asarray(observation[key], dtype=np.float64).reshape(-1, int(np.prod(shape)))
                            for key, shape in self.shapes.items()], axis=-1)
        count = x.shape[0]
        if memory is None:  # SB3's convention: no state is an empty memory
            memory = np.zeros((1, count, x.shape[1] + 1))
        if starts is not None:
            memory = np.where(np.asarray(starts, dtype=bool)[None, :, None], 0.0, memory)
        memory = memory + np.concatenate([x, np.ones((count, 1))], axis=-1)[None]
        mean = memory[0, :, :-1] / memory[0, :, -1:]
        features = np.concatenate([x, mean, np.ones((count, 1))], axis=-1)
        return np.tanh(features @ weights.T).astype(np.float32), memory


class RunningMeanModule(nn.Module):
    """``(*observation, memory, episode_start) -> (action, memory)``: :meth:`RunningMeanAgent.predict` as a torch module."""

    state_names = ("memory",)
    """The ONNX input of the state (output ``next_memory``, batch on axis 1); then the input ``episode_start`` (batch,)."""

    def __init__(self, weights: np.ndarray, order: list[int], size: int):
        super().__init__()
        self.order = order  # the agent's keys (sorted) as positions among the exported inputs
        self.state_shape = (1, 1, size + 1)
        self.register_buffer("weights", torch.as_tensor(weights, dtype=torch.float32))

    def forward(self, *inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        *observation, memory, start = inputs
        x = torch.cat([observation[i].float().flatten(1) for i in self.order], dim=-1)
        ones = torch.ones_like(x[:, :1])
        memory = (1.0 - start.float()).view(1, -1, 1) * memory + torch.cat([x, ones], dim=-1).unsqueeze(0)
        mean = memory[0, :, :-1] / memory[0, :, -1:]
        return torch.tanh(torch.cat([x, mean, ones], dim=-1) @ self.weights.T), memory


SPEC = AlgorithmSpec("Linear policy on the observation and its running mean, trained by random search (a recurrent test algorithm).",
                     builder=RunningMeanAgent)
"""What a test registers: ``register_algorithm("running_mean", SPEC)``."""
