"""The names a configuration may use: algorithms, encoder modes, observation modalities, reward presets.

One place that the configs (validation and JSON Schema), the command line (``choices``) and the
docs read, so that a name is added once. This module imports neither torch nor Stable-Baselines3:
``crowdnav --help`` and config validation stay light. The classes behind the algorithm names live
in :data:`crowdnav.agents.factory.ALGORITHMS` (a test asserts both name sets are equal).

Modalities and reward presets have registries of their own, kept where they are defined
(:data:`crowdnav.sensors.MODALITIES`, which users extend with ``register_modality``, and
:data:`crowdnav.scenario.reward_presets.REWARD_PRESETS`); the functions below read them.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Mapping
from types import MappingProxyType

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
    from crowdnav.sensors import MODALITIES  # numpy and gymnasium only; registers the built-in modalities

    return tuple(sorted(MODALITIES))


def reward_preset_names() -> tuple[str, ...]:
    """Names of :data:`crowdnav.scenario.reward_presets.REWARD_PRESETS`, the default first."""
    from crowdnav.scenario.reward_presets import REWARD_PRESETS

    return tuple(REWARD_PRESETS)


def did_you_mean(name: object, valid: Iterable[str]) -> str:
    """``"; did you mean 'sac'?"`` when a valid name is close to ``name``, else ``""``."""
    close = difflib.get_close_matches(str(name), list(valid), n=1)
    return f"; did you mean '{close[0]}'?" if close else ""


def unknown_name_message(what: str, name: object, valid: Iterable[str]) -> str:
    """E.g. ``unknown algorithm 'sca'; did you mean 'sac'? expected one of: sac, td3, ddpg, a2c, ppo``."""
    valid = list(valid)
    hint = did_you_mean(name, valid) or ";"
    return f"unknown {what} {name!r}{hint} expected one of: {', '.join(valid)}"
