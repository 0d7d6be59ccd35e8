"""The agent factory: a :class:`~crowdnav.agents.training.config.TrainConfig` -> wrapped environment + SB3 model.

Every algorithm gets the same :class:`~crowdnav.agents.networks.extractor.MultiModalExtractor` (the shared
latent), then SB3's own actor/critic heads (``net_arch``) on top of it. What differs between the
Stable-Baselines3 algorithms (class, defaults, replay buffer) is read from their
:class:`crowdnav.registry.AlgorithmSpec`: another SB3 algorithm is one spec there; an algorithm outside
SB3 implements :mod:`crowdnav.agents.training.algorithm_protocol` instead (docs/architecture.md, "Adding a learning
algorithm").
"""

from __future__ import annotations

from collections.abc import Mapping
from functools import partial
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from crowdnav.agents.networks.encoders import LeogEncoder
from crowdnav.agents.networks.extractor import MultiModalExtractor
from crowdnav.agents.sb3.replay_buffer import PackedGridReplayBuffer
from crowdnav.agents.sb3.vec_env import CrowdNavSB3VecEnv
from crowdnav.agents.training.algorithm_protocol import import_reference
from crowdnav.agents.training.config import ConfigError, TrainConfig
from crowdnav.agents.training.seeding import EpisodeSeedCounter
from crowdnav.agents.training.space_checks import action_box, box_space
from crowdnav.agents.training.wrappers import (
    EpisodeSeeds,
    LeogLatentWrapper,
    NormalizeObservation,
    ObservationScales,
    declared_scales,
)
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.noise import NormalActionNoise
from stable_baselines3.common.type_aliases import GymEnv
from stable_baselines3.common.vec_env import VecEnv

from crowdnav.registry import ALGORITHM_NAMES, ALGORITHM_SPECS, OFF_POLICY_ALGORITHMS, AlgorithmSpec, algorithm_spec


def model_class(algo: str, reference: bool = False) -> type[BaseAlgorithm]:
    """The class :func:`make_model` builds for ``algo``: crowdnav's (the spec's ``model_class``) or, ``reference``, SB3's own."""
    spec = algorithm_spec(algo)
    name = spec.sb3_class if reference or spec.model_class is None else spec.model_class
    if name is None:
        raise ConfigError(f"algo: {algo!r} is not a Stable-Baselines3 algorithm (its spec has no sb3_class)")
    cls = import_reference(name)
    if not (isinstance(cls, type) and issubclass(cls, BaseAlgorithm)):
        raise TypeError(f"algorithm {algo!r}: {name} is not a Stable-Baselines3 algorithm class")
    return cls


_BUILT_IN_SB3: dict[str, AlgorithmSpec] = {name: ALGORITHM_SPECS[name] for name in ALGORITHM_NAMES if ALGORITHM_SPECS[name].sb3}

ALGORITHMS: dict[str, type[BaseAlgorithm]] = {name: model_class(name) for name in _BUILT_IN_SB3}
"""The built-in SB3 algorithms' classes (read from their specs): SB3's, with the same updates at less cost per
step for SAC/TD3/DDPG (crowdnav.agents.sb3.algorithms)."""

SB3_ALGORITHMS: dict[str, type[BaseAlgorithm]] = {name: model_class(name, reference=True) for name in _BUILT_IN_SB3}
"""The built-in SB3 algorithms' own Stable-Baselines3 classes (``make_model(..., reference=True)``: benchmarks/bench_train.py's reference)."""

OFF_POLICY = OFF_POLICY_ALGORITHMS
"""The built-in algorithms with a replay buffer (the registry entries' ``off_policy``; the code asks :func:`crowdnav.registry.is_off_policy`)."""

ALGORITHM_DEFAULTS: Mapping[str, Mapping[str, Any]] = {name: spec.defaults for name, spec in _BUILT_IN_SB3.items()}
"""The built-in SB3 algorithms' defaults for the config fields left at ``None`` (their specs' ``defaults``)."""

BATCHED_DEFAULTS: Mapping[str, Mapping[str, Any]] = {name: spec.batched_defaults for name, spec in _BUILT_IN_SB3.items()}
"""What replaces :data:`ALGORITHM_DEFAULTS` entries when a run collects from ``num_envs > 1`` worlds (the specs' ``batched_defaults``)."""


class LinearDecay:
    """SB3 learning-rate schedule: ``initial`` times the progress remaining (1 at the start, 0 at the budget's end); picklable."""

    def __init__(self, initial: float):
        self.initial = float(initial)

    def __call__(self, progress_remaining: float) -> float:
        return self.initial * progress_remaining


def hyperparameters(config: TrainConfig) -> dict[str, Any]:
    """The config's algorithm fields, ``None`` replaced by :data:`ALGORITHM_DEFAULTS` (only those the algorithm takes)."""
    spec = algorithm_spec(config.algo)
    defaults = dict(spec.defaults)
    if config.num_envs > 1:
        defaults.update(spec.batched_defaults)
    chosen = {}
    for name, default in defaults.items():
        value = getattr(config, name)
        chosen[name] = default if value is None else value
    chosen["learning_rate_schedule"] = config.learning_rate_schedule or defaults.get("learning_rate_schedule", "constant")
    minibatches = not spec.off_policy and "batch_size" in defaults  # PPO: minibatches of each rollout
    if config.num_envs > 1 and minibatches and config.batch_size is None:  # a minibatch no larger than the rollout
        chosen["batch_size"] = min(chosen["batch_size"], chosen["n_steps"] * config.num_envs)
    for name in ("batch_size", "buffer_size", "learning_starts", "n_step_returns", "n_steps"):
        if getattr(config, name) is not None and name not in defaults:
            raise ConfigError(f"{name} does not apply to {config.algo}; remove it (or pass algorithm options in algo_kwargs)")
    return chosen


def env_options(config: TrainConfig) -> dict[str, Any]:
    """Keyword arguments of :class:`crowdnav.envs.CrowdNavEnv` for this run (stored with checkpoints)."""
    return {"scenario": config.scenario, "modalities": list(config.modalities), "sensors": dict(config.sensors),
            "overrides": dict(config.overrides), "reward_weights": dict(config.reward_weights),
            **({"shield": config.shield} if config.shield else {}), **({"residual": True} if config.residual else {})}


def make_env(config: TrainConfig, encoder: LeogEncoder | None = None, first_episode: int = 0,
             scales: ObservationScales | None = None) -> gym.Env:
    """CrowdNavEnv -> (NormalizeObservation) -> (LeogLatentWrapper when ``encoder`` is given) -> EpisodeSeeds -> Monitor
    -> (reward scaling).

    ``config.normalize_observations`` adds the normalisation, with the modalities' declared scales or
    ``scales`` (a resumed run's own, from its checkpoint). It leaves the uint8 grid alone, so the
    latent wrapper still encodes the raw grid. The Monitor sits below the reward scaling, so logged
    returns are the env's own.
    """
    from crowdnav.envs import CrowdNavEnv

    env: gym.Env = CrowdNavEnv(**env_options(config))
    if config.normalize_observations:
        env = NormalizeObservation(env, scales)
    if encoder is not None:
        check_leog_shape(config, encoder.architecture, env.observation_space)
        env = LeogLatentWrapper(env, encoder)
    env = Monitor(EpisodeSeeds(env, config.seed, first_episode))
    if config.reward_scale != 1.0:
        env = gym.wrappers.TransformReward(env, partial(_scaled, scale=config.reward_scale))
    return env


def _scaled(reward: SupportsFloat, scale: float) -> float:
    return float(reward) * scale


def make_vec_env(config: TrainConfig, encoder: LeogEncoder | None = None, first_episode: int = 0,
                 scales: ObservationScales | None = None, reward_dtype: type[np.floating[Any]] = np.float32) -> CrowdNavSB3VecEnv:
    """The batched counterpart of :func:`make_env`: ``config.num_envs`` worlds of the native vector env for SB3.

    The same observations as :func:`make_env` gives (normalised with the modalities' scales or
    ``scales``, the frozen encoder's latent when ``encoder`` is given), the same rewards (scaled
    for the algorithm only), and every episode seeded by the run's own numbering from
    ``first_episode`` on (:class:`~crowdnav.agents.training.seeding.EpisodeSeedCounter`), never by the
    seed the algorithm passes. ``reward_dtype``: SB3's float32, or float64 (the env's own, as :func:`make_env` gives).
    """
    from gymnasium.vector import AutoresetMode

    from crowdnav.envs.vector.env import CrowdNavVectorEnv

    vector = CrowdNavVectorEnv(num_envs=config.num_envs, autoreset_mode=AutoresetMode.SAME_STEP, **env_options(config))
    if not config.normalize_observations:
        scales = None
    elif scales is None:
        scales = declared_scales(vector.modalities)
    if encoder is not None:
        check_leog_shape(config, encoder.architecture, vector.single_observation_space)
    return CrowdNavSB3VecEnv(vector, scales=scales, episode_seeds=EpisodeSeedCounter(config.seed, first_episode),
                             reward_scale=config.reward_scale, encoder=encoder, reward_dtype=reward_dtype)


def observation_normalization(env: gym.Env | VecEnv) -> ObservationScales | None:
    """The scales a :func:`make_env` or :func:`make_vec_env` environment (or a VecEnvWrapper of it) applies (None: raw observations)."""
    if isinstance(env, VecEnv):
        inner = env.unwrapped
        return inner.scales if isinstance(inner, CrowdNavSB3VecEnv) else None
    while isinstance(env, gym.Wrapper):
        if isinstance(env, NormalizeObservation):
            return env.scales
        env = env.env
    return None


def load_leog_weights(config: TrainConfig) -> tuple[LeogEncoder | None, dict[str, Any] | None]:
    """The pre-trained encoder of frozen/finetune modes (None for scratch) and its saved dict."""
    if config.encoder.mode == "scratch":
        return None, None
    if config.encoder.weights is None:  # TrainConfig refuses this; a config built with model_construct skips that check
        raise ConfigError(f"encoder.weights: encoder mode {config.encoder.mode!r} needs pre-trained weights (crowdnav pretrain-encoder)")
    from crowdnav.agents.networks.pretrain import load_encoder

    try:
        return load_encoder(config.encoder.weights)
    except (FileNotFoundError, ValueError) as error:
        raise ConfigError(f"encoder.weights: {error}") from None


def check_leog_shape(config: TrainConfig, architecture: dict[str, Any], observation_space: gym.Space[Any]) -> None:
    """ConfigError unless the pre-trained encoder was made for the environment's grid shape."""
    expected, actual = tuple(architecture["grid_shape"]), box_space(observation_space, "leog").shape
    if expected != actual:
        raise ConfigError(
            f"encoder.weights: {config.encoder.weights} expects grids of shape {expected}, but the environment's leog has "
            f"shape {actual}; match sensors.leog size/resolution to the grids the encoder was pre-trained on"
        )


def precomputes_leog(config: TrainConfig) -> bool:
    """Whether the frozen encoder runs in the env wrapper (the model then sees latents)."""
    return config.encoder.mode == "frozen" and config.encoder.precompute


def policy_kwargs(config: TrainConfig, architecture: dict[str, Any] | None, reference: bool = False) -> dict[str, Any]:
    """SB3 policy_kwargs: crowdnav's extractor and heads, plus the config's own ``policy_kwargs`` (``reference``: see make_model)."""
    hyper = hyperparameters(config)
    ours = {"features_extractor_class", "features_extractor_kwargs", "net_arch"}
    clash = sorted(ours & set(config.policy_kwargs))
    if clash:
        raise ConfigError(f"policy_kwargs: {', '.join(clash)} are set by crowdnav itself; use extractor and net_arch instead")
    kwargs = {
        "features_extractor_class": MultiModalExtractor,
        "features_extractor_kwargs": {
            "config": config.extractor.model_dump(),
            "leog_mode": config.encoder.mode,
            "leog_architecture": architecture,
            "leog_precomputed": precomputes_leog(config),
            **({"reference": True} if reference else {}),
        },
        "net_arch": list(hyper["net_arch"]),
        # fused Adam: one kernel per parameter group instead of a Python loop over tensors (~7% faster SAC steps on CPU)
        "optimizer_kwargs": {"fused": True},
        **algorithm_spec(config.algo).policy_kwargs,  # the algorithm's own (an LSTM's width), below the config's
    }
    kwargs.update(config.policy_kwargs)
    return kwargs


def make_model(config: TrainConfig, env: GymEnv, saved_encoder: dict[str, Any] | None = None,
               tensorboard_log: str | None = None, reference: bool = False) -> BaseAlgorithm:
    """A new SB3 model for ``config`` on ``env``, with pre-trained LEOG weights loaded if any.

    ``reference=True``: the same model trained the way crowdnav did before its speed-ups: SB3's own
    algorithm and policy classes, the extractor's and replay buffer's plain code paths. Same
    results, more time per step: the baseline of ``benchmarks/bench_train.py`` and of the tests.
    """
    hyper = hyperparameters(config)
    kwargs: dict[str, Any] = {k: v for k, v in hyper.items()
                              if k not in ("net_arch", "n_step_returns", "updates_per_step", "learning_rate_schedule")}
    if hyper["learning_rate_schedule"] == "linear":
        kwargs["learning_rate"] = LinearDecay(kwargs["learning_rate"])
    spec = algorithm_spec(config.algo)
    if spec.off_policy and config.num_envs > 1:
        # one rollout = one step of every world; the update-to-data ratio sets the gradient steps after it
        frequency = config.algo_kwargs.get("train_freq", 1)  # a rollout of several steps of all worlds: as many more updates
        frequency = frequency if isinstance(frequency, int) and frequency > 0 else 1
        kwargs["train_freq"] = 1
        # half up, not Python's round-half-even (4 worlds at 0.125 would give 1 update, double the ratio asked)
        kwargs["gradient_steps"] = max(1, int(hyper["updates_per_step"] * config.num_envs * frequency + 0.5))
    if spec.exploration_noise and config.action_noise > 0:
        dims = action_box(env.action_space).shape[0]
        kwargs["action_noise"] = NormalActionNoise(np.zeros(dims), np.full(dims, config.action_noise))
    clash = sorted(set(config.algo_kwargs) & {"policy", "env", "policy_kwargs", "seed", "device", "tensorboard_log"})
    if clash:
        raise ConfigError(f"algo_kwargs: {', '.join(clash)} are set by crowdnav itself; use the config's own fields")
    if spec.off_policy:
        # crowdnav's buffer: bit-packed grids, and n-step returns for Dict observations (SB3's own refuses those)
        kwargs["replay_buffer_class"] = PackedGridReplayBuffer
        kwargs["replay_buffer_kwargs"] = {"packed_keys": ["leog"] if config.pack_grids else [], "n_steps": hyper["n_step_returns"],
                                          "gamma": hyper["gamma"], **({"fast_sampling": False} if reference else {})}
    kwargs.update(config.algo_kwargs)
    architecture = saved_encoder["architecture"] if saved_encoder is not None else None
    if architecture is not None and not precomputes_leog(config):
        check_leog_shape(config, architecture, env.observation_space)
    from crowdnav.agents.networks.size import check_model  # counted before anything is allocated

    check_model(config, hyper["net_arch"], env.observation_space, env.action_space, "config", architecture)
    try:
        model = model_class(config.algo, reference)(
            spec.policy, env, policy_kwargs=policy_kwargs(config, architecture, reference), seed=config.seed,
            device=config.device, tensorboard_log=tensorboard_log, verbose=0, **kwargs,
        )
    except TypeError as error:  # an algo_kwargs / policy_kwargs key the algorithm or its policy does not take
        raise ConfigError(f"algo_kwargs / policy_kwargs for {config.algo}: {error}") from None
    if saved_encoder is not None and not precomputes_leog(config):
        for module in model.policy.modules():
            if isinstance(module, MultiModalExtractor):
                module.load_leog_encoder(saved_encoder["encoder"])
    return model


def extractors(model: BaseAlgorithm) -> list[MultiModalExtractor]:
    """Every MultiModalExtractor of the model's policy (actor, critic and their targets)."""
    return [module for module in model.policy.modules() if isinstance(module, MultiModalExtractor)]
