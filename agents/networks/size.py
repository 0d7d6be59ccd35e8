"""How many parameters a model will hold, counted from its sizes before anything is allocated.

Every layer width a config or a checkpoint declares is bounded on its own (:data:`MAX_UNITS`
units, 16 layers, 16 critics), but widths multiply: ``net_arch`` of 16 layers of 4,096 units is
268 M parameters per head, and SAC builds five heads (actor, two critics, two target critics).
So the whole model's parameter count is computed here by arithmetic, from the observation and
action sizes and the layer widths, and refused above :data:`MAX_PARAMETERS` before a single
tensor exists (:func:`check_parameters`). The counts are exact for crowdnav's extractor and
SB3's own heads and extractors (``tests/agents/test_network_size.py`` compares them with built
models); an encoder registered with :func:`crowdnav.agents.register_encoder` is user code and
counts as nothing.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from crowdnav.agents.training.config import ConfigError

from crowdnav.registry import algorithm_spec

MAX_PARAMETERS = 50_000_000
"""Most parameters one model may hold, all its networks together (actor, critics, targets): 200 MB of float32.
crowdnav's default networks hold about 100,000; a checkpoint of the biggest allowed model is under 1 GiB."""

MAX_LSTM_UNITS = 4096
"""Widest LSTM (``policy_kwargs.lstm_hidden_size``) a recurrent policy may declare: the widest layer a checkpoint may."""
MAX_LSTM_LAYERS = 16


class NetworkSizeError(ConfigError):
    """A model whose networks would hold more than :data:`MAX_PARAMETERS` parameters; one line, raised before building it."""


def check_parameters(total: int, label: str, what: str) -> int:
    """``total`` if within :data:`MAX_PARAMETERS`, else :class:`NetworkSizeError` naming it, ``what`` made it, and the limit."""
    if total > MAX_PARAMETERS:
        raise NetworkSizeError(f"{label}: its networks would hold {total:,} parameters ({what}), more than the {MAX_PARAMETERS:,} "
                               "a crowdnav model may hold (crowdnav.agents.networks.size); use fewer or narrower layers")
    return total


def mlp(inputs: int, hidden: Sequence[int], outputs: int = 0) -> tuple[int, int]:
    """(parameters, output width) of fully connected layers ``inputs -> hidden... (-> outputs)``, each with a bias."""
    total, width = 0, inputs
    for units in [*hidden, *([outputs] if outputs > 0 else [])]:
        total += width * units + units
        width = units
    return total, width


# ------------------------------------------------------------------ SB3's heads on top of an extractor


def heads(kind: str, features: int, extractor: int, actions: int, net_arch: Any, *, n_critics: int = 2,
          share_features_extractor: bool | None = None, use_sde: bool = False, full_std: bool = True) -> int:
    """Parameters of an SB3 policy: ``kind`` ``actor_critic`` (PPO, A2C), ``sac`` or ``td3`` (TD3, DDPG).

    ``features``: the extractor's output width; ``extractor``: its parameters (counted once per
    copy the policy makes); ``net_arch``: a list (every head) or SB3's dict (``pi``, ``vf``, ``qf``).
    """
    if isinstance(net_arch, Mapping):
        pi, vf, qf = list(net_arch.get("pi", [])), list(net_arch.get("vf", [])), list(net_arch.get("qf", []))
    else:
        pi = vf = qf = list(net_arch)
    if kind == "actor_critic":
        shared = True if share_features_extractor is None else share_features_extractor
        policy, latent_pi = mlp(features, pi)
        value, latent_vf = mlp(features, vf)
        action = latent_pi * actions + actions
        log_std = (latent_pi * (actions if full_std else 1)) if use_sde else actions
        return extractor * (1 if shared else 2) + policy + value + action + log_std + latent_vf + 1
    shared = bool(share_features_extractor)
    critic = n_critics * mlp(features + actions, qf, 1)[0]
    if kind == "sac":
        latent, width = mlp(features, pi)
        mean = width * actions + actions
        log_std = width * (actions if full_std else 1) if use_sde else width * actions + actions
        actor = latent + mean + log_std
        # actor, critic (its own extractor unless shared), target critic (always its own)
        return actor + 2 * critic + extractor * (2 if shared else 3)
    if kind == "td3":
        actor = mlp(features, pi, actions)[0]
        # actor, target actor, critic and target critic (the critics use the actors' extractors when shared)
        return 2 * actor + 2 * critic + extractor * (2 if shared else 4)
    raise ValueError(f"unknown policy kind {kind!r}")


def kind_of(algo: str) -> str:
    """The policy kind of an SB3 algorithm's name, from its registry entry: on-policy actor-critic, off-policy with a
    deterministic actor (TD3's heads) or with a stochastic one (SAC's)."""
    spec = algorithm_spec(algo)
    return "actor_critic" if not spec.off_policy else "td3" if spec.exploration_noise else "sac"


def policy_kind(cls: type) -> str:
    """``actor_critic`` (PPO, A2C), ``sac`` or ``td3`` (TD3, DDPG): the head layout of an SB3 policy class."""
    from stable_baselines3.common.policies import ActorCriticPolicy
    from stable_baselines3.sac.policies import SACPolicy
    from stable_baselines3.td3.policies import TD3Policy

    for base, kind in ((ActorCriticPolicy, "actor_critic"), (SACPolicy, "sac"), (TD3Policy, "td3")):
        if issubclass(cls, base):
            return kind
    raise ValueError(f"{cls.__name__}: not a policy of a Stable-Baselines3 algorithm crowdnav trains")


# ------------------------------------------------------------------ crowdnav's multi-modal extractor


def conv_output(length: int, kernel: int, stride: int, padding: int = 0) -> int:
    return (length + 2 * padding - kernel) // stride + 1


def extractor_size(shapes: Mapping[str, tuple[int, ...]], settings: Mapping[str, Any], leog_architecture: Mapping[str, Any] | None = None,
                   leog_precomputed: bool = False) -> tuple[int, int]:
    """(parameters, output width) of :class:`crowdnav.agents.networks.extractor.MultiModalExtractor` on observations of ``shapes``.

    ``settings``: :class:`~crowdnav.agents.training.config.ExtractorConfig`'s fields; the branch of each key is
    chosen as the extractor chooses it. Keys with a registered encoder count as nothing.
    """
    from crowdnav.agents.networks.extractor import ENCODERS, LOWDIM_MAX

    total = width = 0
    for key, shape in shapes.items():
        if key in ENCODERS:
            continue
        if len(shape) == 3 or (key == "leog" and leog_precomputed):
            if key == "leog" and leog_precomputed:
                latent, encoder = shape[0], 0
            else:
                architecture = leog_architecture or {"grid_shape": list(shape), "channels": settings["leog_channels"],
                                                     "kernels": settings["leog_kernels"], "strides": settings["leog_strides"],
                                                     "latent": settings["leog_latent"]}
                encoder, latent = _leog_encoder(architecture)
            head, out = mlp(latent, settings["leog_head"])
            total, width = total + encoder + head, width + out
        elif len(shape) == 1 and shape[0] > LOWDIM_MAX:
            convs, channels, length = 0, 1, shape[0]
            for out_channels in settings["lidar_conv_channels"]:  # kernel 5, stride 2, circular padding 2
                convs += channels * out_channels * 5 + out_channels
                channels, length = out_channels, conv_output(length, 5, 2, 2)
            fc, out = mlp(channels * max(length, 0), settings["lidar_hidden"])
            total, width = total + convs + fc, width + out
        elif len(shape) == 1:
            centres = settings["rbf_centres"]
            rbf = 2 * shape[0] * centres if settings["rbf_trainable"] else 0
            fc, out = mlp(shape[0] * (centres + 1), settings["lowdim_hidden"])
            total, width = total + rbf + fc, width + out
        elif len(shape) == 2:
            fc, out = mlp(int(np.prod(shape)), settings["table_hidden"])
            total, width = total + fc, width + out
    return total, width


def _leog_encoder(architecture: Mapping[str, Any]) -> tuple[int, int]:
    """(parameters, latent) of :class:`crowdnav.agents.networks.encoders.LeogEncoder` (convolutions, fc, layer norm)."""
    channels, height, width = (int(v) for v in architecture["grid_shape"])
    total = 0
    for out_channels, kernel, stride in zip(architecture["channels"], architecture["kernels"], architecture["strides"], strict=True):
        total += channels * out_channels * kernel * kernel + out_channels
        channels, height, width = out_channels, conv_output(height, kernel, stride), conv_output(width, kernel, stride)
    latent = int(architecture["latent"])
    flat = channels * max(height, 0) * max(width, 0)
    return total + flat * latent + latent + 2 * latent, latent


def model_parameters(config: Any, net_arch: Any, observation_space: Any, action_space: Any,
                     leog_architecture: Mapping[str, Any] | None = None) -> int:
    """Parameters of the model :func:`crowdnav.agents.sb3.factory.make_model` builds for ``config`` on these spaces.

    ``net_arch``: the heads' layers the factory chose (``hyperparameters(config)["net_arch"]``).
    """
    precomputed = config.encoder.mode == "frozen" and config.encoder.precompute  # the factory's precomputes_leog
    shapes = {key: tuple(space.shape) for key, space in observation_space.spaces.items()}
    extractor, features = extractor_size(shapes, config.extractor.model_dump(), leog_architecture, precomputed)
    spec = algorithm_spec(config.algo)
    policy_kwargs = {**spec.policy_kwargs, **config.policy_kwargs}  # the factory's merge
    options = _head_options(policy_kwargs, spec.n_critics)
    if "use_sde" in config.algo_kwargs:  # an algorithm option SB3 hands to its policy
        options["use_sde"] = bool(config.algo_kwargs["use_sde"])
    memory = 0
    if spec.recurrent:  # the heads read the LSTM's output, not the extractor's
        memory, features = lstms(features, policy_kwargs)
    return memory + heads(kind_of(config.algo), features, extractor, int(np.prod(action_space.shape)), net_arch, **options)


def lstms(features: int, policy_kwargs: Mapping[str, Any]) -> tuple[int, int]:
    """(parameters, output width) of the LSTMs of sb3-contrib's ``RecurrentActorCriticPolicy`` on ``features`` inputs.

    The actor's LSTM; the critic's own (``enable_critic_lstm``, the default), none (``shared_lstm``) or a linear layer
    to the LSTM's width (neither). ``lstm_kwargs`` are not counted: torch's options there (no bias, a projection)
    only make an LSTM smaller, and a bidirectional one does not fit the policy's heads.
    """
    hidden, layers = policy_kwargs.get("lstm_hidden_size", 256), policy_kwargs.get("n_lstm_layers", 1)
    for name, value, most in (("lstm_hidden_size", hidden, MAX_LSTM_UNITS), ("n_lstm_layers", layers, MAX_LSTM_LAYERS)):
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= most:
            raise NetworkSizeError(f"policy_kwargs.{name} must be an integer 1..{most}, got {str(value)[:40]}")
    # torch's nn.LSTM: four gates, each with input and recurrent weights and two biases, per layer
    lstm = sum(4 * hidden * ((features if layer == 0 else hidden) + hidden) + 8 * hidden for layer in range(layers))
    if policy_kwargs.get("shared_lstm", False):
        critic = 0
    elif policy_kwargs.get("enable_critic_lstm", True):
        critic = lstm
    else:
        critic = mlp(features, [hidden])[0]
    return lstm + critic, hidden


def _head_options(policy_kwargs: Mapping[str, Any], critics_by_default: int = 2) -> dict[str, Any]:
    """The policy_kwargs that change the heads' sizes (``n_critics`` checked: an integer 1..16; DDPG's default is 1)."""
    options: dict[str, Any] = {}
    critics = policy_kwargs.get("n_critics", critics_by_default)
    if isinstance(critics, bool) or not isinstance(critics, int) or not 1 <= critics <= 16:
        raise NetworkSizeError(f"policy_kwargs.n_critics must be an integer 1..16, got {str(critics)[:40]}")
    options["n_critics"] = critics
    for name in ("share_features_extractor", "use_sde", "full_std"):
        if name in policy_kwargs:
            options[name] = bool(policy_kwargs[name])
    return options


def check_model(config: Any, net_arch: Any, observation_space: Any, action_space: Any, label: str,
                leog_architecture: Mapping[str, Any] | None = None) -> int:
    """:func:`model_parameters`, refused above :data:`MAX_PARAMETERS` (:class:`NetworkSizeError`) before anything is built."""
    total = model_parameters(config, net_arch, observation_space, action_space, leog_architecture)
    critics = f", {config.policy_kwargs['n_critics']} critics" if "n_critics" in config.policy_kwargs else ""
    return check_parameters(total, label, f"{config.algo}, net_arch {describe_layers(net_arch)}{critics}")


def describe_layers(layers: Any) -> str:
    """``[4096 x 16]`` for a repeated width, else the list (shortened)."""
    if isinstance(layers, Mapping):
        return "{" + ", ".join(f"{key}: {describe_layers(value)}" for key, value in layers.items()) + "}"
    layers = list(layers)
    if len(layers) > 2 and len(set(layers)) == 1:
        return f"[{layers[0]} x {len(layers)}]"
    return str(layers)[:80]
