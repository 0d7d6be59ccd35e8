"""Experiment files: a list of configurations, each trained with every seed under one protocol.

An experiment file (YAML; examples in ``evaluation/experiments/``)::

    name: modalities                # folder under the results folder (default: the file name)
    description: Figure 4(b) ...
    protocol: {train_episodes: 700, eval_every: 50, test_episodes: 20, seeds: 5}   # optional
    defaults: {scenario: room_furniture, algo: sac}     # TrainConfig fields shared by all
    pretrain_encoder: {scenario: room_furniture, grids: 5000, epochs: 20}        # optional
    configurations:
      - name: leog                  # folder name; label: name in figures (default: name)
        label: LEOG
        train: {modalities: [leog, goal]}                # TrainConfig fields of this one

``train`` is merged over ``defaults`` (mappings key by key) and checked as an
:class:`agents.TrainConfig`; the protocol sets ``seed``, ``out``, ``episodes``,
``checkpoint_every``, ``progress``, ``torch_threads`` and ``save_replay_buffer`` itself.
With a ``pretrain_encoder`` section, a LEOG encoder is pre-trained once per experiment and
given to every configuration whose ``encoder.mode`` is frozen or finetune without weights.

Every problem is an :class:`ExperimentError` naming the file, the line and the field.
"""

from __future__ import annotations

import copy
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import yaml
from crowdnav.evaluation.baselines import BASELINE_PREFIX
from crowdnav.evaluation.protocol import Protocol, protocol_fields, quick
from crowdnav.evaluation.runner import PRETRAINED, PROTOCOL_FIELDS, UnitSpec

from crowdnav.scenario.loader import yaml_line

EXPERIMENTS_DIR = Path(__file__).resolve().parent / "experiments"
DEFAULT_EXPERIMENT = "default"
PRETRAIN_DEFAULTS = {"scenario": "room_furniture", "grids": 5000, "epochs": 20, "seed": 99, "every": 2}
"""``pretrain_encoder`` fields and defaults (collection seeds never meet test or training seeds: agents.wrappers.dataset_seed)."""
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
_TOP_KEYS = ("name", "description", "protocol", "defaults", "pretrain_encoder", "configurations")
_CONFIGURATION_KEYS = ("name", "label", "train")


class ExperimentError(ValueError):
    """An invalid experiment file; ``str()`` is ``FILE:LINE: field: problem``."""


@dataclass(frozen=True)
class Configuration:
    name: str
    """Folder name of its runs."""
    label: str
    """Name in figures and tables."""
    train: dict[str, Any]
    """TrainConfig fields, defaults merged in."""


@dataclass(frozen=True)
class Experiment:
    name: str
    description: str
    protocol: Protocol
    configurations: tuple[Configuration, ...]
    pretrain_encoder: dict[str, Any] | None = None
    source: str = field(default="<experiment>", compare=False)

    def with_options(self, *, seeds: int | None = None, quick_protocol: bool = False) -> Experiment:
        """This experiment with the ``--quick`` protocol and/or another number of seeds."""
        protocol = quick(self.protocol) if quick_protocol else self.protocol
        if seeds is not None:
            protocol = replace(protocol, seeds=seeds)
        return replace(self, protocol=protocol)

    def units(self, folder: str | Path) -> list[tuple[UnitSpec, Path]]:
        """Every (configuration, seed) run and its folder under ``folder`` (the experiment's results folder).

        Seed by seed (all configurations of the first seed, then the next), so an experiment
        stopped part-way has comparable runs of every configuration.
        """
        folder = Path(folder)
        return [
            (UnitSpec(self.name, configuration.name, seed, copy.deepcopy(configuration.train), self.protocol.to_dict(),
                      configuration.label),
             folder / configuration.name / f"seed_{seed}")
            for seed in self.protocol.run_seeds for configuration in self.configurations
        ]

    def needs_encoder(self) -> bool:
        return any(configuration.train.get("encoder", {}).get("weights") == PRETRAINED for configuration in self.configurations)

    def to_dict(self) -> dict[str, Any]:
        """The resolved experiment (what experiment.yaml in the results folder holds)."""
        return {
            "name": self.name, "description": self.description, "protocol": self.protocol.to_dict(),
            "pretrain_encoder": self.pretrain_encoder,
            "configurations": [{"name": c.name, "label": c.label, "train": c.train} for c in self.configurations],
        }


def experiment_path(source: str | Path | None) -> Path:
    """A shipped experiment's name (``modalities``) or a file path -> the file; None -> the default experiment."""
    if source is None:
        return EXPERIMENTS_DIR / f"{DEFAULT_EXPERIMENT}.yaml"
    path = Path(source)
    if not path.exists() and path.suffix == "" and (EXPERIMENTS_DIR / f"{source}.yaml").is_file():
        return EXPERIMENTS_DIR / f"{source}.yaml"
    return path


def shipped_experiments() -> list[str]:
    return sorted(path.stem for path in EXPERIMENTS_DIR.glob("*.yaml"))


def load_experiment(source: str | Path | None = None) -> Experiment:
    """Read and check an experiment file (see the module docstring); None: the default experiment."""
    path = experiment_path(source)
    label = str(path)
    if not path.is_file():
        shipped = ", ".join(shipped_experiments())
        raise ExperimentError(f"{label}: no such experiment file (shipped experiments: {shipped})")
    try:
        text = path.read_text(encoding="utf-8")
        root = yaml.compose(text, Loader=yaml.SafeLoader)
        document = yaml.safe_load(text)
    except (OSError, UnicodeDecodeError) as error:
        raise ExperimentError(f"{label}: cannot read the file: {error}") from None
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f"{label}:{mark.line + 1}" if mark is not None else label
        raise ExperimentError(f"{where}: malformed YAML: {getattr(error, 'problem', None) or error}") from None
    return experiment_from_mapping(document, label, root, default_name=path.stem)


def experiment_from_mapping(document: Any, label: str = "<experiment>", root: yaml.Node | None = None,
                            default_name: str = "experiment") -> Experiment:
    """Check a parsed experiment document; ``root`` (the YAML node) gives line numbers."""
    check = _Checker(label, root)
    check.mapping(document, "", _TOP_KEYS)
    name = document.get("name", default_name)
    if not isinstance(name, str) or not _NAME.match(name):
        check.fail("name", f"expected a folder-safe name (letters, digits, '_', '-', '.'), got {name!r}")
    description = document.get("description", "")
    if not isinstance(description, str):
        check.fail("description", f"expected a string, got {description!r}")
    protocol = _protocol(check, document.get("protocol") or {})
    defaults = document.get("defaults") or {}
    check.mapping(defaults, "defaults", None)
    _no_protocol_fields(check, defaults, "defaults")
    pretrain = _pretrain(check, document.get("pretrain_encoder"))
    configurations = document.get("configurations")
    if not isinstance(configurations, list) or not configurations:
        check.fail("configurations", f"expected a non-empty list of configurations, got {configurations!r}")
    items, seen = [], {}
    for index, item in enumerate(configurations):
        where = f"configurations.{index}"
        check.mapping(item, where, _CONFIGURATION_KEYS)
        config_name = item.get("name")
        if not isinstance(config_name, str) or not _NAME.match(config_name):
            check.fail(f"{where}.name", f"expected a folder-safe name (letters, digits, '_', '-', '.'), got {config_name!r}")
        if config_name.startswith(BASELINE_PREFIX):
            check.fail(f"{where}.name", f"names starting with {BASELINE_PREFIX!r} are kept for the scripted baselines, got {config_name!r}")
        if config_name in seen:
            check.fail(f"{where}.name", f"duplicate configuration name {config_name!r} (also configurations.{seen[config_name]})")
        seen[config_name] = index
        config_label = item.get("label", config_name)
        if not isinstance(config_label, str):
            check.fail(f"{where}.label", f"expected a string, got {config_label!r}")
        train = item.get("train") or {}
        check.mapping(train, f"{where}.train", None)
        _no_protocol_fields(check, train, f"{where}.train")
        merged = _merge(defaults, train)
        _with_encoder(merged, pretrain)
        _check_train(check, merged, f"{where}.train", config_name)
        items.append(Configuration(config_name, config_label, merged))
    try:
        protocol.check_disjoint()
    except ValueError as error:
        check.fail("protocol.test_seed_base", str(error).split(": ", 1)[1])
    return Experiment(name, description, protocol, tuple(items), pretrain, label)


class _Checker:
    """Raises ExperimentError with the file, the line of a dotted path, and the field."""

    def __init__(self, label: str, root: yaml.Node | None):
        self.label, self.root = label, root

    def line(self, dotted: str) -> int | None:
        return yaml_line(self.root, dotted)

    def fail(self, dotted: str, message: str) -> None:
        line = self.line(dotted)
        where = self.label if line is None else f"{self.label}:{line}"
        raise ExperimentError(f"{where}: {dotted}: {message}" if dotted else f"{where}: {message}")

    def mapping(self, value: Any, dotted: str, known: tuple[str, ...] | None) -> None:
        if not isinstance(value, Mapping):
            what = "an empty document" if value is None and not dotted else repr(value)
            self.fail(dotted, f"expected a mapping (key: value), got {what}")
        for key in value if known is not None else ():
            if key not in known:
                self.fail(f"{dotted}.{key}" if dotted else str(key), f"unknown key '{key}' (expected one of: {', '.join(known)})")


def _protocol(check: _Checker, document: Any) -> Protocol:
    known = protocol_fields()
    check.mapping(document, "protocol", tuple(known))
    for key, value in document.items():
        if not isinstance(value, int) or isinstance(value, bool):
            check.fail(f"protocol.{key}", f"expected an integer ({known[key]}), got {value!r}")
    try:
        return Protocol(**document)
    except ValueError as error:
        first = str(error).split("; ")[0]
        key, _, message = first.partition(": ")
        check.fail(f"protocol.{key}", message)
    raise AssertionError("unreachable")


def _pretrain(check: _Checker, document: Any) -> dict[str, Any] | None:
    if document is None:
        return None
    check.mapping(document, "pretrain_encoder", tuple(PRETRAIN_DEFAULTS))
    merged = {**PRETRAIN_DEFAULTS, **document}
    for key, value in merged.items():
        expected = str if key == "scenario" else int
        if not isinstance(value, expected) or isinstance(value, bool) or (expected is int and value < (0 if key == "seed" else 1)):
            check.fail(f"pretrain_encoder.{key}", f"expected {'a scenario name or path' if expected is str else 'a positive integer'}, "
                                                  f"got {value!r}")
    return merged


def _no_protocol_fields(check: _Checker, train: Mapping[str, Any], where: str) -> None:
    for key in train:
        if key in PROTOCOL_FIELDS:
            check.fail(f"{where}.{key}", f"'{key}' is set by the protocol for every run; remove it (see the protocol section)")


def _merge(base: Mapping[str, Any], top: Mapping[str, Any]) -> dict[str, Any]:
    """``top`` over ``base``; nested mappings merged key by key."""
    merged = copy.deepcopy(dict(base))
    for key, value in top.items():
        if isinstance(value, Mapping) and isinstance(merged.get(key), Mapping):
            merged[key] = _merge(merged[key], value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def _with_encoder(train: dict[str, Any], pretrain: dict[str, Any] | None) -> None:
    """Point frozen/finetune configurations without weights at the experiment's pre-trained encoder."""
    encoder = train.get("encoder")
    if pretrain is not None and isinstance(encoder, dict) and encoder.get("mode") in ("frozen", "finetune") and not encoder.get("weights"):
        encoder["weights"] = PRETRAINED


def _check_train(check: _Checker, train: dict[str, Any], where: str, name: str) -> None:
    from crowdnav.agents import ConfigError
    from crowdnav.agents.config import config_from_mapping

    from crowdnav.envs import CrowdNavEnv
    from crowdnav.scenario import ScenarioError

    source = f"{check.label} ({where}, configuration '{name}')"
    line = check.line(where)
    where_line = f"{check.label}:{line}" if line is not None else check.label
    try:
        config = config_from_mapping({**train, "out": "unused"}, source).validate(source)
    except ConfigError as error:
        detail = str(error).replace(f"{source}: ", "")
        raise ExperimentError(f"{where_line}: {where} (configuration '{name}'): {detail}") from None
    try:  # the environment the runs will train in: scenario, modalities, sensors, overrides, reward weights
        CrowdNavEnv(config.scenario, modalities=config.modalities, sensors=config.sensors, overrides=config.overrides,
                    reward_weights=config.reward_weights).close()
    except (ScenarioError, ValueError) as error:
        detail = " / ".join(str(error).splitlines())
        raise ExperimentError(f"{where_line}: {where} (configuration '{name}'): environment: {detail}") from None
