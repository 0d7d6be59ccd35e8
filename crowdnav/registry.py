"""The names a configuration may use: algorithms, encoder modes, observation modalities, reward presets.

One place that the configs (validation and JSON Schema), the command line (``choices``) and the
docs read, so that a name is added once. This module imports neither torch nor Stable-Baselines3:
``crowdnav --help`` and config validation stay light. The classes behind the algorithm names live
in :data:`crowdnav.agents.factory.ALGORITHMS` (a test asserts both name sets are equal).

Modalities and reward presets have registries of their own, kept where they are defined
(:data:`crowdnav.sensors.MODALITIES`, which users extend with ``register_modality``, and
:data:`crowdnav.scenario.reward_presets.REWARD_PRESETS`); the functions below read them. The
registry sits at the top of the environment core (it reads the sensors): modules below it take the
"unknown name" wording from :mod:`crowdnav.suggest`.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from crowdnav.scenario.reward_presets import REWARD_PRESETS
from crowdnav.sensors import MODALITIES  # numpy and gymnasium only; registers the built-in modalities
from crowdnav.suggest import did_you_mean, unknown_name_message  # noqa: F401  (re-exported: the one wording)

ALGORITHMS: Mapping[str, str] = MappingProxyType({
    "sac": "Soft Actor-Critic: off-policy, entropy-regularised (crowdnav's default).",
    "td3": "Twin Delayed DDPG: off-policy, deterministic policy with Gaussian exploration noise.",
    "ddpg": "Deep Deterministic Policy Gradient: off-policy, deterministic policy with Gaussian exploration noise.",
    "a2c": "Advantage Actor-Critic: on-policy, synchronous.",
    "ppo": "Proximal Policy Optimization: on-policy, clipped updates.",
})
"""Algorithm name (``algo`` in a training config, ``crowdnav train --algo``) -> one-line description."""

ALGORITHM_NAMES: tuple[str, ...] = tuple(ALGORITHMS)

OFF_POLICY_ALGORITHMS: tuple[str, ...] = ("sac", "td3", "ddpg")
"""Algorithms with a replay buffer (buffer_size, learning_starts, n_step_returns apply)."""

ENCODER_MODES: Mapping[str, str] = MappingProxyType({
    "scratch": "random start, trained with the agent",
    "frozen": "pre-trained, no gradient",
    "finetune": "pre-trained start, trained with the agent",
})
"""LEOG encoder mode (``encoder.mode``, ``crowdnav train --encoder``) -> one-line description."""


def modality_names() -> tuple[str, ...]:
    """Observation keys registered in :data:`crowdnav.sensors.MODALITIES` (built-in and user-registered), sorted."""
    return tuple(sorted(MODALITIES))


def reward_preset_names() -> tuple[str, ...]:
    """Names of :data:`crowdnav.scenario.reward_presets.REWARD_PRESETS`, the default first."""
    return tuple(REWARD_PRESETS)
