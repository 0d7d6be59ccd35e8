"""The names a configuration may use: algorithms, encoder modes, observation modalities, reward presets.

One place that the configs (validation and JSON Schema), the command line (``choices``), the agents
and the docs read, so that a name is added once. This module imports neither torch nor
Stable-Baselines3: ``crowdnav --help`` and config validation stay light. An algorithm's spec says
everything the code asks of it (its builder, its Stable-Baselines3 class and defaults, whether it
keeps a replay buffer); the classes are named as ``"module:attribute"`` texts, imported by the agents
when first used, as installed plug-ins name theirs (:data:`PLUGIN_GROUP`).

Modalities and reward presets have registries of their own, kept where they are defined
(:data:`crowdnav.sensors.MODALITIES`, which users extend with ``register_modality``, and
:data:`crowdnav.scenario.reward_presets.REWARD_PRESETS`); the functions below read them. The
registry sits at the top of the environment core (it reads the sensors): modules below it take the
"unknown name" wording from :mod:`crowdnav.suggest`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from crowdnav.scenario.reward_presets import REWARD_PRESETS
from crowdnav.sensors import MODALITIES  # numpy and gymnasium only; registers the built-in modalities
from crowdnav.suggest import did_you_mean, unknown_name_message  # noqa: F401  (re-exported: the one wording)

SB3_BUILDER = "crowdnav.agents.sb3.algorithm:SB3_BUILDER"
"""The builder of the Stable-Baselines3 algorithms (:class:`crowdnav.agents.sb3.algorithm.SB3Builder`), named, not imported."""


@dataclass(frozen=True)
class AlgorithmSpec:
    """What crowdnav knows about a learning algorithm: its builder and the properties the agents code branches on.

    The code reads these instead of lists of names, so adding an algorithm is one entry here (or
    one :func:`register_algorithm` call) and its class: see docs/architecture.md, "Adding a
    learning algorithm".
    """

    description: str
    """One line for ``--help``, the docs and the JSON Schema."""
    off_policy: bool = False
    """A replay buffer (buffer_size, learning_starts, n_step_returns, save_replay_buffer apply)."""
    exploration_noise: bool = False
    """Deterministic actor explored with Gaussian action noise (the config's ``action_noise``)."""
    builder: Callable[..., Any] | str | None = None
    """The class (or factory) of an :class:`crowdnav.agents.training.algorithm_protocol.Algorithm`, or its ``"module:attribute"``
    (imported when first used: :func:`crowdnav.agents.training.algorithm_protocol.builder_of`): ``builder(env, config)`` makes a
    new one, ``builder.load(folder)`` a saved one (docs/architecture.md, "Adding a learning algorithm"). The
    Stable-Baselines3 algorithms' is :data:`SB3_BUILDER`. None: a name that cannot be trained or loaded."""
    sb3_class: str | None = None
    """Stable-Baselines3's class, ``"module:attribute"`` (e.g. ``"stable_baselines3:SAC"``): the reference
    ``make_model(..., reference=True)`` builds; None for an algorithm outside SB3."""
    model_class: str | None = None
    """The class crowdnav trains instead (the same updates at less cost per step, :mod:`crowdnav.agents.sb3.algorithms`);
    None: :attr:`sb3_class` itself."""
    defaults: Mapping[str, Any] = field(default_factory=dict)
    """crowdnav's values of the config fields the algorithm takes, for those left at ``None`` (``net_arch``,
    ``learning_rate``, ``batch_size``, ...; a field not named here is refused: :func:`crowdnav.agents.sb3.factory.hyperparameters`)."""
    batched_defaults: Mapping[str, Any] = field(default_factory=dict)
    """What replaces :attr:`defaults` entries when a run collects from ``num_envs > 1`` worlds."""
    n_critics: int = 2
    """Q-networks an off-policy SB3 policy has unless ``policy_kwargs`` say (DDPG: 1); the network-size count reads it."""
    policy: str = "MultiInputPolicy"
    """The SB3 class's alias of its policy for Dict observations (sb3-contrib's recurrent ones: ``"MultiInputLstmPolicy"``)."""
    policy_kwargs: Mapping[str, Any] = field(default_factory=dict)
    """crowdnav's ``policy_kwargs`` for this algorithm (e.g. the LSTM's width); the config's own ``policy_kwargs`` override them."""
    recurrent: bool = False
    """An LSTM policy (sb3-contrib's ``RecurrentActorCriticPolicy``): its state is carried between steps, so the network-size
    count adds the LSTMs and behaviour cloning (a feed-forward fit) is refused."""
    robots_trainer: Callable[..., Any] | str | None = None
    """What trains it as ``agents: robots`` (one shared policy for every robot of a ``robots:`` scenario):
    ``trainer(config, resume=..., on_checkpoint=...) -> TrainResult``, or its ``"module:attribute"`` (imported when first
    used, :func:`crowdnav.agents.training.run.robots_trainer_of`). None: ``agents: robots`` is refused for it."""

    @property
    def sb3(self) -> bool:
        """Whether Stable-Baselines3 implements it (:attr:`sb3_class`; its builder trains it with SB3's loop)."""
        return self.sb3_class is not None


# gamma 0.95 (a 4 s horizon at the 0.2 s step) and 5-step returns: with the default reward's dense progress term,
# avoidance is a short-horizon problem; measured in docs/agents.md#the-main-job. Small networks: CPU training.
_OFF_POLICY_DEFAULTS = MappingProxyType({"net_arch": [64, 64], "learning_rate": 3e-4, "batch_size": 256, "buffer_size": 100_000,
                                         "learning_starts": 1_000, "gamma": 0.95, "n_step_returns": 5})
# measured in docs/agents.md#batched-training: one gradient step per 8 env steps on 4x larger batches keeps
# SAC/TD3/DDPG learning at several hundred env steps/s on 2 cores; PPO/A2C roll out n_steps per world
_OFF_POLICY_BATCHED = MappingProxyType({"updates_per_step": 0.125, "batch_size": 512})

_ALGORITHM_SPECS: dict[str, AlgorithmSpec] = {
    "sac": AlgorithmSpec("Soft Actor-Critic: off-policy, entropy-regularised (crowdnav's default).", off_policy=True,
                         builder=SB3_BUILDER, sb3_class="stable_baselines3:SAC", model_class="crowdnav.agents.sb3.algorithms:CrowdNavSAC",
                         defaults=_OFF_POLICY_DEFAULTS, batched_defaults=_OFF_POLICY_BATCHED),
    "td3": AlgorithmSpec("Twin Delayed DDPG: off-policy, deterministic policy with Gaussian exploration noise.",
                         off_policy=True, exploration_noise=True,
                         builder=SB3_BUILDER, sb3_class="stable_baselines3:TD3", model_class="crowdnav.agents.sb3.algorithms:CrowdNavTD3",
                         defaults=_OFF_POLICY_DEFAULTS, batched_defaults=_OFF_POLICY_BATCHED),
    "ddpg": AlgorithmSpec("Deep Deterministic Policy Gradient: off-policy, deterministic policy with Gaussian exploration noise.",
                          off_policy=True, exploration_noise=True,
                          builder=SB3_BUILDER, sb3_class="stable_baselines3:DDPG", model_class="crowdnav.agents.sb3.algorithms:CrowdNavDDPG",
                          defaults=_OFF_POLICY_DEFAULTS, batched_defaults=_OFF_POLICY_BATCHED, n_critics=1),
    "a2c": AlgorithmSpec("Advantage Actor-Critic: on-policy, synchronous.", builder=SB3_BUILDER, sb3_class="stable_baselines3:A2C",
                         defaults=MappingProxyType({"net_arch": [64, 64], "learning_rate": 7e-4, "gamma": 0.95, "n_steps": 5}),
                         batched_defaults=MappingProxyType({"n_steps": 8})),
    "ppo": AlgorithmSpec("Proximal Policy Optimization: on-policy, clipped updates.", builder=SB3_BUILDER, sb3_class="stable_baselines3:PPO",
                         robots_trainer="crowdnav.agents.marl.robots:train_robots",
                         defaults=MappingProxyType({"net_arch": [64, 64], "learning_rate": 3e-4, "batch_size": 64, "gamma": 0.95,
                                                    "n_steps": 2048}),
                         # a constant rate let a 6 M-step run collapse (79% -> 5% held-out success); decaying it did not (docs/agents.md)
                         batched_defaults=MappingProxyType({"n_steps": 64, "batch_size": 512, "learning_rate_schedule": "linear"})),
    # PPO's settings (measured for PPO, not re-tuned); a 64-unit LSTM between the extractor and the heads keeps it a CPU network
    "recurrent_ppo": AlgorithmSpec("Recurrent PPO (sb3-contrib): PPO with an LSTM policy that remembers the episode so far.",
                                   builder=SB3_BUILDER, sb3_class="sb3_contrib:RecurrentPPO", policy="MultiInputLstmPolicy",
                                   policy_kwargs=MappingProxyType({"lstm_hidden_size": 64}), recurrent=True,
                                   defaults=MappingProxyType({"net_arch": [64, 64], "learning_rate": 3e-4, "batch_size": 64,
                                                              "gamma": 0.95, "n_steps": 2048}),
                                   batched_defaults=MappingProxyType({"n_steps": 64, "batch_size": 512, "learning_rate_schedule": "linear"})),
}

ALGORITHM_SPECS: Mapping[str, AlgorithmSpec] = MappingProxyType(_ALGORITHM_SPECS)
"""Algorithm name (``algo`` in a training config, ``crowdnav train --algo``) -> its :class:`AlgorithmSpec` (a live view:
:func:`register_algorithm` adds to it; installed plug-ins appear once :func:`algorithm_names` or :func:`algorithm_spec` ran)."""

ALGORITHMS: Mapping[str, str] = MappingProxyType({name: spec.description for name, spec in _ALGORITHM_SPECS.items()})
"""The built-in algorithms: name -> one-line description (``crowdnav train --algo`` choices)."""

ALGORITHM_NAMES: tuple[str, ...] = tuple(ALGORITHMS)
"""The built-in algorithm names; :func:`algorithm_names` adds registered ones."""

OFF_POLICY_ALGORITHMS: tuple[str, ...] = tuple(name for name, spec in _ALGORITHM_SPECS.items() if spec.off_policy)
"""The built-in algorithms with a replay buffer (derived from their specs)."""


PLUGIN_GROUP = "crowdnav.algorithms"
"""Entry-point group of installed algorithms: ``name = "package.module:SPEC"`` (an :class:`AlgorithmSpec`), registered
the first time the registry is read, so ``crowdnav train`` and ``crowdnav evaluate`` find them in a new process."""

_plugins_loaded = False


def _load_plugins() -> None:
    """Register the installed packages' algorithms (:data:`PLUGIN_GROUP`), once per process."""
    global _plugins_loaded
    if _plugins_loaded:
        return
    _plugins_loaded = True
    from importlib.metadata import entry_points

    for point in entry_points(group=PLUGIN_GROUP):
        if point.name in _ALGORITHM_SPECS:
            continue
        spec = point.load()
        if not isinstance(spec, AlgorithmSpec):
            raise TypeError(f"entry point {point.name} = {point.value} ({PLUGIN_GROUP}) is {type(spec).__name__}, not an AlgorithmSpec")
        register_algorithm(point.name, spec)


def register_algorithm(name: str, spec: AlgorithmSpec) -> None:
    """Make ``name`` a valid ``algo`` (config validation reads the registry each time); ValueError if taken by another spec."""
    if not name.isidentifier() or name != name.lower():
        raise ValueError(f"algorithm name {name!r}: use a lowercase identifier, e.g. 'sarl'")
    if _ALGORITHM_SPECS.get(name, spec) is not spec:
        raise ValueError(f"algorithm {name!r} is registered already")
    _ALGORITHM_SPECS[name] = spec


def unregister_algorithm(name: str) -> None:
    """Remove an algorithm :func:`register_algorithm` added (the built-in ones stay)."""
    if name in ALGORITHMS:
        raise ValueError(f"algorithm {name!r} is built in")
    _ALGORITHM_SPECS.pop(name, None)


def algorithm_names() -> tuple[str, ...]:
    """Every algorithm a config may name now: the built-in ones, then the registered and installed ones."""
    _load_plugins()
    return tuple(_ALGORITHM_SPECS)


def algorithm_spec(name: str) -> AlgorithmSpec:
    """The spec of ``name``; ValueError with the registry's "unknown name" wording."""
    if name not in _ALGORITHM_SPECS:
        _load_plugins()
    try:
        return _ALGORITHM_SPECS[name]
    except KeyError:
        raise ValueError(unknown_name_message("algorithm", name, tuple(_ALGORITHM_SPECS))) from None


def is_off_policy(name: str) -> bool:
    """Whether the algorithm ``name`` keeps a replay buffer (an unknown name: False)."""
    if name not in _ALGORITHM_SPECS:
        _load_plugins()
    spec = _ALGORITHM_SPECS.get(name)
    return spec is not None and spec.off_policy


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
