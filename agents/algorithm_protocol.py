"""The learning-algorithm seam: what crowdnav asks of an algorithm, and the SB3 algorithms seen through it.

An algorithm is registered by name with :func:`crowdnav.registry.register_algorithm` and an
:class:`~crowdnav.registry.AlgorithmSpec` whose ``builder`` is a class (or factory) with

* ``builder(env, config) -> Algorithm``: a new agent for the run's env (a :func:`crowdnav.agents.factory.make_env`
  environment: the observation dict as the modalities give it, normalised if the config says so; actions in
  [-1, 1]) and its :class:`~crowdnav.agents.config.TrainConfig` (``seed``, ``gamma``, ``learning_rate``, ``algo_kwargs``, ...);
* ``builder.load(folder) -> Algorithm``: the agent :meth:`Algorithm.save` wrote to ``folder``, with everything a
  resumed run continues from (weights, optimiser state, random streams).

Then ``crowdnav train`` trains it (:mod:`crowdnav.agents.protocol_training`: episodes counted, logged in
``episodes.csv`` and seeded as for SB3, checkpoints, snapshots, ``--resume``), and ``crowdnav evaluate RUN``,
``crowdnav render`` and the experiment runner load it with :func:`crowdnav.agents.load_policy`. A checkpoint holds
no pickle: :meth:`Algorithm.save` writes arrays (``.npz`` read with ``allow_pickle=False``, or safetensors) and
JSON. ``crowdnav export`` (:mod:`crowdnav.agents.onnx_export`) writes a registered algorithm's agent to ONNX when it
is :class:`Exportable` (it has ``export_module``; ``sarl`` is) and refuses it in one line otherwise; ``agents: robots``
is for SB3 algorithms only.

The built-in algorithms are Stable-Baselines3's: their policies predict through the same :class:`Predictor` side
(:class:`SB3Predictor`), their training keeps SB3's own loop (:mod:`crowdnav.agents.training`: callbacks, replay
buffers and rollouts restored mid-episode for an exact resume) and their checkpoints SB3's ``model.zip``, read back
as tensors only.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import gymnasium as gym
import numpy as np

if TYPE_CHECKING:
    from torch import nn

ALGORITHM_FOLDER = "algorithm"
"""Where a registered (non-SB3) algorithm's :meth:`Algorithm.save` writes inside a checkpoint folder."""


@runtime_checkable
class Predictor(Protocol):
    """What a trained agent does in evaluation, rendering and experiments (:class:`crowdnav.agents.checkpoint.AgentPolicy`)."""

    def predict(self, observation: Mapping[str, np.ndarray], deterministic: bool = True) -> np.ndarray:
        """Actions for one observation (float (2,)) or a batch of them stacked per key (float (N, 2))."""


@runtime_checkable
class Algorithm(Predictor, Protocol):
    """A learning agent crowdnav can train, checkpoint, resume and evaluate (module docstring: how it is registered)."""

    def learn(self, env: gym.Env, keep_going: Callable[[], bool]) -> None:
        """Train on ``env`` (reset it, step it, learn) until ``keep_going()`` returns False.

        Call ``keep_going()`` after every episode, once what the episode taught is in the agent's state: crowdnav
        logs the episodes that ended since the last call there, stops on the budget (episodes, or env steps
        counted by crowdnav) and may call :meth:`save` from inside it for a checkpoint. Play every episode to its
        end before the next reset: crowdnav seeds each training episode itself, whatever seed ``reset`` is given.
        """

    def save(self, folder: Path) -> None:
        """Write the agent into the empty ``folder``: arrays and JSON, no pickle; ``builder.load(folder)`` gives it back."""


@runtime_checkable
class Exportable(Protocol):
    """An agent ``crowdnav export`` can write to ONNX (optional: an :class:`Algorithm` without it is refused in one line)."""

    def export_module(self, keys: Sequence[str]) -> nn.Module:
        """:meth:`Predictor.predict` with ``deterministic=True`` as a torch module the TorchScript ONNX exporter traces.

        ``forward`` takes one tensor per observation key, in ``keys`` order, each with a leading batch axis and
        holding what ``predict`` receives for that key (crowdnav puts the checkpoint's observation normalisation, and
        a frozen LEOG encoder, before it in the graph), and returns the actions, float32 ``(batch, 2)``. It may ignore
        keys it does not read.
        """


class SB3Predictor:
    """A Stable-Baselines3 model seen as a :class:`Predictor`: ``predict`` without SB3's recurrent-state tuple."""

    def __init__(self, model: Any):
        self.model = model

    def predict(self, observation: Mapping[str, np.ndarray], deterministic: bool = True) -> np.ndarray:
        action, _ = self.model.predict(observation, deterministic=deterministic)
        return np.asarray(action)


def as_predictor(model: Any) -> Predictor:
    """``model`` as a :class:`Predictor`: a registered algorithm's agent as it is, an SB3 model through :class:`SB3Predictor`."""
    from stable_baselines3.common.base_class import BaseAlgorithm

    if isinstance(model, BaseAlgorithm):
        return SB3Predictor(model)
    if not isinstance(model, Predictor):
        raise TypeError(f"{type(model).__name__} is neither an SB3 model nor a Predictor (predict)")
    return model


def builder_of(algo: str) -> Any:
    """The registered ``builder`` of a non-SB3 algorithm (ValueError for an unknown name or an SB3 one)."""
    from crowdnav.registry import algorithm_spec

    spec = algorithm_spec(algo)
    if spec.builder is None:
        raise ValueError(f"algorithm {algo!r} is a Stable-Baselines3 algorithm, trained and loaded through SB3")
    return spec.builder


def load_algorithm(folder: Path, algo: str) -> Algorithm:
    """The agent a checkpoint of the registered algorithm ``algo`` holds in ``folder/algorithm/``."""
    agent = builder_of(algo).load(folder / ALGORITHM_FOLDER)
    if not isinstance(agent, Algorithm):
        raise TypeError(f"{algo}: load() returned {type(agent).__name__}, not an Algorithm (learn, predict, save)")
    return agent
