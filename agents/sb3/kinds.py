"""An SB3 model seen as the kind of algorithm it is: on-policy (PPO, A2C) or off-policy (SAC, TD3, DDPG).

Training, checkpoints and resume hold a model as SB3's ``BaseAlgorithm``, which has neither the
replay buffer and update settings of an off-policy algorithm nor the rollout buffer of an
on-policy one. These return the model as its kind, or raise TypeError naming what it is, so the
code that uses those attributes is checked against the class that defines them.
"""

from __future__ import annotations

from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
from stable_baselines3.common.type_aliases import TrainFreq


def off_policy(model: BaseAlgorithm) -> OffPolicyAlgorithm:
    """``model`` as an off-policy algorithm (TypeError for another kind)."""
    if not isinstance(model, OffPolicyAlgorithm):
        raise TypeError(f"expected an off-policy algorithm (SAC, TD3, DDPG), got {type(model).__name__}")
    return model


def on_policy(model: BaseAlgorithm) -> OnPolicyAlgorithm:
    """``model`` as an on-policy algorithm (TypeError for another kind)."""
    if not isinstance(model, OnPolicyAlgorithm):
        raise TypeError(f"expected an on-policy algorithm (PPO, A2C), got {type(model).__name__}")
    return model


def train_freq(model: OffPolicyAlgorithm) -> TrainFreq:
    """``model.train_freq`` as the TrainFreq SB3 turns it into when it sets the model up (typed by SB3 as the argument given)."""
    frequency = model.train_freq
    if not isinstance(frequency, TrainFreq):
        raise TypeError(f"{type(model).__name__}.train_freq is {frequency!r}, not yet a TrainFreq (the model is not set up)")
    return frequency


def replay_buffer(model: BaseAlgorithm) -> ReplayBuffer:
    """The replay buffer of an off-policy ``model`` (TypeError for another kind, or before SB3 has built it)."""
    buffer = off_policy(model).replay_buffer
    if buffer is None:
        raise TypeError(f"{type(model).__name__} has no replay buffer yet")
    return buffer
