"""The training configuration: typed dataclasses, loaded from YAML with strict checking.

Every field has a default and a one-line ``doc`` (in its metadata, also printed by
``crowdnav train --print-config``). Loading rejects unknown keys and wrongly typed values
with a :class:`ConfigError` that names the file, the line and the dotted key.

Algorithm hyperparameters left at ``None`` take crowdnav's per-algorithm default (see
:data:`agents.factory.ALGORITHM_DEFAULTS`); anything else SB3 accepts goes in ``algo_kwargs``.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import yaml

ALGORITHM_NAMES = ("sac", "td3", "ddpg", "a2c", "ppo")
ENCODER_MODES = ("scratch", "frozen", "finetune")


class ConfigError(ValueError):
    """A training configuration is invalid; ``str()`` names the file, line and key."""


def option(default: Any, doc: str) -> Any:
    """A dataclass field with a default (lists and dicts copied per instance) and a one-line doc."""
    if isinstance(default, (list, dict)):
        return field(default_factory=lambda: type(default)(default), metadata={"doc": doc})
    return field(default=default, metadata={"doc": doc})


@dataclass
class ExtractorConfig:
    """Sizes of the multi-modal encoder (one branch per observation key, concatenated into the latent)."""

    leog_channels: list[int] = option([8, 16, 16], "Output channels of each LEOG convolution (a few layers sized for 60x60 grids).")
    leog_kernels: list[int] = option([4, 3, 3], "Kernel size of each LEOG convolution.")
    leog_strides: list[int] = option([4, 2, 1], "Stride of each LEOG convolution.")
    leog_latent: int = option(64, "Size of the LEOG encoder's tanh output (the autoencoder's bottleneck).")
    leog_head: list[int] = option([], "Trainable fully connected layers after the LEOG encoder (also trained in frozen mode).")
    lidar_hidden: list[int] = option([64], "Fully connected layers of the LIDAR branch.")
    lidar_conv_channels: list[int] = option([], "Circular 1-D convolutions (kernel 5, stride 2) before the LIDAR's layers; [] for none.")
    rbf_centres: int = option(16, "Gaussian RBF centres per low-dimensional input value (goal, closest_obstacle, velocity); 0: no RBF.")
    rbf_trainable: bool = option(False, "Learn the RBF centres and widths (otherwise fixed, evenly spread over the value's range).")
    lowdim_hidden: list[int] = option([32], "Fully connected layers after the RBF layer, per low-dimensional key.")


@dataclass
class EncoderConfig:
    """How the LEOG encoder is initialised and trained."""

    mode: Literal["scratch", "frozen", "finetune"] = option(
        "scratch", "scratch: random start, trained with the agent; frozen: pre-trained, no gradient; finetune: pre-trained start, trained."
    )
    weights: str | None = option(None, "Pre-trained encoder file (encoder.pt from pretrain-encoder); required by frozen and finetune.")
    precompute: bool = option(True, "Frozen only: encode the grid once per env step in a wrapper, so the replay buffer stores latents.")


@dataclass
class TrainConfig:
    """One training run: environment, algorithm, networks, budget and outputs."""

    scenario: str = option("open_space", "Library scenario name or path to a scenario YAML file.")
    modalities: list[str] = option(["lidar", "goal"], "Observation keys the agent receives (goal, closest_obstacle, lidar, leog, velocity).")
    normalize_observations: bool = option(True, "Scale each float modality by its declared scale ((x - offset) / scale, O(1)); false: raw units.")
    sensors: dict[str, Any] = option({}, "Sensor-setting overrides, e.g. {lidar: {beams: 180}}.")
    overrides: dict[str, Any] = option({}, "Dotted scenario overrides, e.g. {humans.count: 5}.")
    reward_weights: dict[str, Any] = option({}, "Reward preset and weight overrides, e.g. {preset: paper, social: -50} (docs/agents.md#reward).")
    algo: Literal["sac", "td3", "ddpg", "a2c", "ppo"] = option("sac", "Stable-Baselines3 algorithm.")
    episodes: int = option(700, "Training length in episodes (the paper trains for 700).")
    seed: int = option(0, "Seed of the networks and of the training episodes (episode i uses seed train_seed(seed, i)).")
    out: str = option("runs/train", "Output folder: checkpoint, snapshots, episode log, resolved config.")
    net_arch: list[int] | None = option(None, "Hidden layers of the actor and critic heads on top of the latent (None: per-algorithm default).")
    learning_rate: float | None = option(None, "Optimizer learning rate (None: per-algorithm default).")
    batch_size: int | None = option(None, "Minibatch size (None: per-algorithm default; unused by A2C).")
    buffer_size: int | None = option(None, "Replay buffer capacity in transitions (off-policy only; None: default).")
    learning_starts: int | None = option(None, "Steps of random actions before gradient updates start (off-policy only; None: default).")
    gamma: float | None = option(None, "Discount factor (None: per-algorithm default).")
    n_step_returns: int | None = option(None, "Off-policy: rewards summed per replay sample before bootstrapping (None: per-algorithm default).")
    reward_scale: float = option(1.0, "Multiplies the reward the algorithm learns from (SAC's reward scale); logged returns stay in env units.")
    action_noise: float = option(0.1, "Std of the Gaussian exploration noise of TD3 and DDPG, in action units.")
    algo_kwargs: dict[str, Any] = option({}, "Further keyword arguments of the SB3 algorithm, e.g. {tau: 0.01}.")
    policy_kwargs: dict[str, Any] = option({}, "Further SB3 policy_kwargs, e.g. {share_features_extractor: true} (the extractor is crowdnav's).")
    extractor: ExtractorConfig = field(default_factory=ExtractorConfig, metadata={"doc": "Sizes of the multi-modal encoder."})
    encoder: EncoderConfig = field(default_factory=EncoderConfig, metadata={"doc": "LEOG encoder mode and pre-trained weights."})
    checkpoint_every: int = option(50, "Save a resumable checkpoint (and a policy snapshot) every this many episodes.")
    pack_grids: bool = option(True, "Off-policy: store LEOG grids in the replay buffer at 1 bit per cell (8x less memory than uint8).")
    save_replay_buffer: bool = option(True, "Store the replay buffer with the checkpoint so a resumed run continues with it.")
    torch_threads: int = option(1, "torch.set_num_threads for this process.")
    device: str = option("cpu", "torch device: cpu, cuda or auto.")
    progress: bool = option(True, "Show a progress bar (episodes, success rate, steps/s).")
    tensorboard: bool = option(False, "Write TensorBoard logs to OUT/tensorboard (needs the tensorboard package).")

    def validate(self, source: str = "<config>") -> TrainConfig:
        """Range checks that the types alone do not express; returns self."""
        problems = []
        for name in ("episodes", "checkpoint_every", "torch_threads"):
            if getattr(self, name) < 1:
                problems.append(f"{name}: expected an integer >= 1, got {getattr(self, name)}")
        for name in ("batch_size", "buffer_size", "n_step_returns"):
            value = getattr(self, name)
            if value is not None and value < 1:
                problems.append(f"{name}: expected an integer >= 1, got {value}")
        if self.learning_starts is not None and self.learning_starts < 0:
            problems.append(f"learning_starts: expected an integer >= 0, got {self.learning_starts}")
        if self.gamma is not None and not 0.0 < self.gamma <= 1.0:
            problems.append(f"gamma: expected a number in (0, 1], got {self.gamma}")
        if not self.reward_scale > 0.0:
            problems.append(f"reward_scale: expected a positive number, got {self.reward_scale}")
        if self.learning_rate is not None and self.learning_rate <= 0.0:
            problems.append(f"learning_rate: expected a positive number, got {self.learning_rate}")
        if not self.modalities:
            problems.append("modalities: expected at least one observation key")
        if self.encoder.mode in ("frozen", "finetune") and not self.encoder.weights:
            problems.append(f"encoder.weights: encoder mode {self.encoder.mode!r} needs pre-trained weights (crowdnav pretrain-encoder)")
        if self.encoder.mode != "scratch" and "leog" not in self.modalities:
            problems.append(f"encoder.mode: {self.encoder.mode!r} applies to the LEOG, but 'leog' is not among the modalities {self.modalities}")
        extractor = self.extractor
        if not (len(extractor.leog_channels) == len(extractor.leog_kernels) == len(extractor.leog_strides)) or not extractor.leog_channels:
            problems.append("extractor: leog_channels, leog_kernels and leog_strides must be non-empty lists of the same length")
        sizes = [*extractor.leog_channels, *extractor.leog_kernels, *extractor.leog_strides, *extractor.leog_head,
                 *extractor.lidar_hidden, *extractor.lidar_conv_channels, *extractor.lowdim_hidden, *(self.net_arch or [])]
        if any(size < 1 for size in sizes) or extractor.leog_latent < 1:
            problems.append("extractor / net_arch: layer sizes, kernels and strides must be >= 1")
        if extractor.rbf_centres < 0:
            problems.append(f"extractor.rbf_centres: expected an integer >= 0, got {extractor.rbf_centres}")
        if problems:
            raise ConfigError("\n".join(f"{source}: {problem}" for problem in problems))
        return self


# ------------------------------------------------------------------------- loading


def load_config(path: str | Path | None = None, overrides: Mapping[str, Any] | None = None) -> TrainConfig:
    """Read a YAML config file (``None``: all defaults), apply dotted ``overrides``, check everything.

    ``overrides`` maps dotted field names to values, e.g. ``{"algo": "td3", "encoder.mode": "frozen"}``.
    """
    document: dict[str, Any] = {}
    root = None
    label = "<defaults>" if path is None else str(path)
    if path is not None:
        try:
            text = Path(path).read_text(encoding="utf-8")
        except OSError as error:
            raise ConfigError(f"{label}: cannot read the config file: {error.strerror or error}") from None
        try:
            root = yaml.compose(text, Loader=yaml.SafeLoader)
            loaded = yaml.safe_load(text)
        except yaml.YAMLError as error:
            mark = getattr(error, "problem_mark", None)
            where = f"{label}:{mark.line + 1}" if mark is not None else label
            raise ConfigError(f"{where}: malformed YAML: {getattr(error, 'problem', None) or error}") from None
        if loaded is not None and not isinstance(loaded, dict):
            raise ConfigError(f"{label}: expected a mapping of training options at the top level, got {type(loaded).__name__}")
        document = loaded or {}
    for dotted, value in (overrides or {}).items():
        node = document
        *parents, last = dotted.split(".")
        for part in parents:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ConfigError(f"{label}: {dotted}: {part} is not a section")
        node[last] = value
    return config_from_mapping(document, label, root).validate(label)


def config_from_mapping(document: Mapping[str, Any], source: str = "<mapping>", root: yaml.Node | None = None) -> TrainConfig:
    """Build a :class:`TrainConfig` from a parsed mapping (strict: unknown keys and wrong types raise)."""
    return _build(TrainConfig, document, source, root, "")


def config_to_dict(config: TrainConfig) -> dict[str, Any]:
    """Plain dict (YAML-ready) of a config."""
    return dataclasses.asdict(config)


def describe_fields(cls: type = TrainConfig, prefix: str = "") -> list[tuple[str, str, str]]:
    """(dotted name, default, doc) of every field, nested sections expanded."""
    rows = []
    instance = cls()
    for item in dataclasses.fields(cls):
        value = getattr(instance, item.name)
        if dataclasses.is_dataclass(value):
            rows.extend(describe_fields(type(value), f"{prefix}{item.name}."))
        else:
            rows.append((f"{prefix}{item.name}", repr(value), item.metadata.get("doc", "")))
    return rows


def _build(cls: type, document: Any, source: str, root: yaml.Node | None, path: str) -> Any:
    if not isinstance(document, Mapping):
        raise ConfigError(f"{_where(source, root, path)}: {path or 'the config'}: expected a mapping, got {document!r}")
    fields = {item.name: item for item in dataclasses.fields(cls)}
    hints = typing.get_type_hints(cls)
    for key in document:
        if key not in fields:
            dotted = f"{path}{key}"
            known = ", ".join(fields)
            raise ConfigError(f"{_where(source, root, dotted)}: unknown key '{dotted}' in the {cls.__name__} section; known keys: {known}")
    values = {}
    for key, value in document.items():
        dotted = f"{path}{key}"
        hint = hints[key]
        if isinstance(hint, type) and dataclasses.is_dataclass(hint):
            values[key] = _build(hint, value if value is not None else {}, source, root, f"{dotted}.")
        else:
            values[key] = _checked(hint, value, lambda expected, d=dotted, v=value: ConfigError(
                f"{_where(source, root, d)}: {d}: expected {expected}, got {v!r}"
            ))
    return cls(**values)


def _checked(hint: Any, value: Any, error: Any) -> Any:
    """``value`` converted to ``hint`` (int -> float allowed), or raise ``error(expected)``."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        inner = [arg for arg in args if arg is not type(None)]
        return _checked(inner[0], value, lambda expected: error(f"{expected} or null"))
    if origin is Literal:
        if value not in args:
            raise error("one of " + ", ".join(map(repr, args)))
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise error("true or false")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise error("an integer")
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise error("a number")
        return float(value)
    if hint is str:
        if not isinstance(value, (str, Path)):
            raise error("a string")
        return str(value)
    if origin is list:
        if isinstance(value, str) or not isinstance(value, (list, tuple)):
            raise error(f"a list of {_name(args[0])}")
        return [_checked(args[0], item, lambda expected: error(f"a list of {_name(args[0])}")) for item in value]
    if origin is dict:
        if not isinstance(value, Mapping):
            raise error("a mapping")
        return dict(value)
    raise TypeError(f"unsupported config type {hint!r}")


def _name(hint: Any) -> str:
    return {int: "integers", float: "numbers", str: "strings"}.get(hint, str(hint))


def _where(source: str, root: yaml.Node | None, dotted: str) -> str:
    """``source:line`` of the key ``dotted`` (``a.b.``-style prefixes allowed) when the YAML node is known."""
    node, line = root, None
    for part in [p for p in dotted.split(".") if p]:
        if not isinstance(node, yaml.MappingNode):
            return source
        for key, child in node.value:
            if str(key.value) == part:
                node, line = child, key.start_mark.line + 1
                break
        else:
            return source
    return source if line is None else f"{source}:{line}"
