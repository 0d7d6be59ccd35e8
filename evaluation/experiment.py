"""Experiment files: a list of configurations, each trained with every seed under one protocol.

An experiment file (YAML; examples in ``evaluation/experiments/``)::

    name: modalities                # folder under the results folder (default: the file name)
    description: Figure 4(b) ...
    protocol: {train_episodes: 700, eval_every: 50, test_episodes: 20, seeds: 5}   # optional
    # or a budget in env steps: protocol: {train_steps: 2000000, eval_every_steps: 100000, ...}
    defaults: {scenario: room_furniture, algo: sac}     # TrainConfig fields shared by all
    pretrain_encoder: {scenario: room_furniture, grids: 5000, epochs: 20}        # optional
    configurations:
      - name: leog                  # folder name; label: name in figures (default: name)
        label: LEOG
        train: {modalities: [leog, goal]}                # TrainConfig fields of this one

``train`` is merged over ``defaults`` (mappings key by key) and checked as an
:class:`crowdnav.agents.TrainConfig`; the protocol sets ``seed``, ``out``, ``episodes``,
``checkpoint_every`` (or ``timesteps`` and ``checkpoint_every_steps``), ``progress``,
``torch_threads`` and ``save_replay_buffer`` itself.
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
from typing import Annotated, Any

from crowdnav.evaluation.baselines import BASELINE_PREFIX
from crowdnav.evaluation.protocol import Protocol, quick
from crowdnav.evaluation.storage import run_folder
from crowdnav.evaluation.unit_spec import PRETRAINED, PROTOCOL_FIELDS, UnitSpec
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, Strict, ValidationError, field_validator, model_validator

from crowdnav.config_errors import ConfigIssue, FieldProblems, YamlProblem, format_issues, read_yaml, validation_issues, yaml_line
from crowdnav.errors import CrowdNavError
from crowdnav.yaml_input import YamlLimitError, read_text_file

EXPERIMENTS_DIR = Path(__file__).resolve().parent / "experiments"
DEFAULT_EXPERIMENT = "default"
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


class ExperimentError(CrowdNavError, ValueError):
    """An invalid experiment file; ``str()`` is ``FILE:LINE: field: problem`` (several joined with `` / `` on one line)."""

    def __init__(self, message: str, issues: list[ConfigIssue] | None = None):
        super().__init__(message)
        self.issues = list(issues or [])


# ------------------------------------------------------------------ the file's schema


def _folder_name(name: str) -> str:
    if not _NAME.match(name):
        raise ValueError(f"expected a folder-safe name (letters, digits, '_', '-', '.'), got {name!r}")
    return name


FolderName = Annotated[str, Strict(), AfterValidator(_folder_name)]
Text = Annotated[str, Strict()]
Int = Annotated[int, Strict()]


def _protocol_owned(train: dict[str, Any]) -> dict[str, Any]:
    owned = [(key, f"'{key}' is set by the protocol for every run; remove it (see the protocol section)") for key in train
             if key in PROTOCOL_FIELDS]
    if owned:
        raise FieldProblems(owned)
    return train


TrainFields = Annotated[dict[str, Any], AfterValidator(_protocol_owned)]
"""TrainConfig fields (checked as a TrainConfig once merged; see :func:`experiment_from_mapping`)."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class PretrainEncoder(_Strict):
    """The ``pretrain_encoder`` section: a LEOG encoder pre-trained once for the experiment."""

    scenario: Text = Field("room_furniture", description="Scenario the grids are collected in (library name or path).")
    grids: Int = Field(5000, ge=1, description="Occupancy grids to collect.")
    epochs: Int = Field(20, ge=1, description="Autoencoder training epochs.")
    seed: Int = Field(99, ge=0, description="Collection seed (never meets test or training seeds: crowdnav.agents.training.seeding.dataset_seed).")
    every: Int = Field(2, ge=1, description="Keep every this many steps' grid.")


class ConfigurationEntry(_Strict):
    """One entry of ``configurations``: trained with every seed of the protocol."""

    name: FolderName = Field(description="Folder name of its runs (unique in the experiment).")
    label: Text | None = Field(None, description="Name in figures and tables (default: name).")
    train: TrainFields = Field(default_factory=dict, description="TrainConfig fields of this configuration, merged over defaults.")

    @field_validator("name")
    @classmethod
    def _not_a_baseline(cls, name: str) -> str:
        if name.startswith(BASELINE_PREFIX):
            raise ValueError(f"names starting with {BASELINE_PREFIX!r} are kept for the scripted baselines, got {name!r}")
        return name


class ExperimentFile(_Strict):
    """An experiment file: configurations, each trained with every seed under one protocol."""

    name: FolderName | None = Field(None, description="Folder under the results folder (default: the file name).")
    description: Text = Field("", description="What the experiment measures.")
    protocol: Protocol = Field(default_factory=Protocol, description="Training length, evaluation schedule, test episodes, seeds.")
    defaults: TrainFields = Field(default_factory=dict, description="TrainConfig fields shared by every configuration.")
    pretrain_encoder: PretrainEncoder | None = Field(None, description="Pre-train a LEOG encoder once, for frozen/finetune runs.")
    configurations: list[ConfigurationEntry] = Field(min_length=1, description="The configurations compared.")

    @model_validator(mode="after")
    def _unique_names(self) -> ExperimentFile:
        seen: dict[str, int] = {}
        for index, entry in enumerate(self.configurations):
            if entry.name in seen:
                raise FieldProblems([(f"configurations.{index}.name",
                                      f"duplicate configuration name {entry.name!r} (also configurations.{seen[entry.name]})")])
            seen[entry.name] = index
        return self


# ------------------------------------------------------------------ the experiment in memory


@dataclass(frozen=True)
class Configuration:
    name: str
    """Folder name of its runs."""
    label: str
    """Name in figures and tables."""
    train: dict[str, Any]
    """TrainConfig fields, defaults merged in."""
    config: Any = field(default=None, compare=False, repr=False)
    """The validated :class:`~crowdnav.agents.training.config.TrainConfig` (protocol fields at their defaults until a run sets them)."""


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
            protocol = Protocol(**{**protocol.to_dict(), "seeds": seeds})
        problems = _skipped_points(protocol, self.configurations)
        if problems:
            raise ExperimentError(f"{self.source}: protocol.eval_every_steps: {problems[0]}")
        return replace(self, protocol=protocol)

    def units(self, folder: str | Path) -> list[tuple[UnitSpec, Path]]:
        """Every (configuration, seed) run and its folder under ``folder`` (the experiment's results folder).

        Seed by seed (all configurations of the first seed, then the next), so an experiment
        stopped part-way has comparable runs of every configuration.
        """
        folder = Path(folder)
        return [
            (UnitSpec(self.name, configuration.name, seed, copy.deepcopy(configuration.train), self.protocol.to_dict(),
                      configuration.label, config=configuration.config),
             run_folder(folder, configuration.name, seed))
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
    if not path.exists():  # a FIFO or device is refused by name when read
        shipped = ", ".join(shipped_experiments())
        raise ExperimentError(f"{label}: no such experiment file (shipped experiments: {shipped})")
    try:
        document, root = read_yaml(read_text_file(path))  # a regular UTF-8 file of bounded size
    except YamlLimitError as error:
        raise ExperimentError(f"{label}: {error}") from None
    except YamlProblem as problem:
        raise _error(label, [problem.issue]) from None
    return experiment_from_mapping(document, label, root, default_name=path.stem)


def experiment_from_mapping(document: Any, label: str = "<experiment>", root: Any = None,
                            default_name: str = "experiment") -> Experiment:
    """Check a parsed experiment document once: the file's schema, then each configuration as a TrainConfig.

    ``root`` (the ``yaml.compose`` tree) gives line numbers. Each configuration's TrainConfig is
    validated here and travels with the experiment's units, so a run does not validate it again.
    """
    if document is None:
        raise _error(label, [ConfigIssue("", "expected a mapping (key: value), got an empty document", 1 if root else None)])
    try:
        parsed = ExperimentFile.model_validate(document)
    except ValidationError as error:
        issues = validation_issues(error, document, ExperimentFile)
        raise _error(label, [ConfigIssue(i.path, i.message, yaml_line(root, i.path)) for i in issues]) from None
    pretrain = None if parsed.pretrain_encoder is None else parsed.pretrain_encoder.model_dump()
    items, issues = [], []
    for index, entry in enumerate(parsed.configurations):
        merged = _merge(parsed.defaults, entry.train)
        _with_encoder(merged, pretrain)
        config, problems = _train_config(merged, parsed.defaults, entry.train, f"configurations.{index}.train", entry.name, root)
        issues.extend(problems)
        items.append(Configuration(entry.name, entry.label if entry.label is not None else entry.name, merged, config))
    if issues:
        raise _error(label, issues)
    for index, item in enumerate(items):
        _check_environment(label, item, f"configurations.{index}.train", root)
    try:
        parsed.protocol.check_disjoint()
    except ValueError as error:
        message = str(error).split(": ", 1)[1]
        raise _error(label, [ConfigIssue("protocol.test_seed_base", message, yaml_line(root, "protocol.test_seed_base"))]) from None
    skipped = _skipped_points(parsed.protocol, items)
    if skipped:
        raise _error(label, [ConfigIssue("protocol.eval_every_steps", problem, yaml_line(root, "protocol.eval_every_steps"))
                             for problem in skipped])
    return Experiment(parsed.name or default_name, parsed.description, parsed.protocol, tuple(items), pretrain, label)


def _skipped_points(protocol: Protocol, configurations: tuple[Configuration, ...] | list[Configuration]) -> list[str]:
    """Configurations whose worlds would step past evaluation points of a protocol in env steps.

    One training step adds ``num_envs`` env steps: with more worlds than ``eval_every_steps``
    a step can cross two points at once and the earlier one gets no snapshot.
    """
    if protocol.unit != "steps":
        return []
    return [f"{protocol.eval_every_steps} is less than num_envs ({item.config.num_envs}) of configuration '{item.name}': "
            f"one step of its {item.config.num_envs} worlds would pass an evaluation point; evaluate every "
            f"{item.config.num_envs} env steps or more" for item in configurations
            if item.config is not None and item.config.num_envs > protocol.eval_every_steps]


def _error(label: str, issues: list[ConfigIssue]) -> ExperimentError:
    return ExperimentError(format_issues(label, issues, separator=" / "), issues)


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


def _train_config(merged: dict[str, Any], defaults: Mapping[str, Any], train: Mapping[str, Any], where: str, name: str,
                  root: Any) -> tuple[Any, list[ConfigIssue]]:
    """The configuration's TrainConfig, or the issues, each at the key that set it (the configuration's train, else defaults)."""
    from crowdnav.agents.training.config import TrainConfig

    try:
        return TrainConfig.model_validate(merged), []
    except ValidationError as error:
        issues = []
        for issue in validation_issues(error, merged, TrainConfig):
            path = f"{where}.{issue.path}" if _holds(train, issue.path) or not _holds(defaults, issue.path) else f"defaults.{issue.path}"
            issues.append(ConfigIssue(path, f"{issue.message} (configuration '{name}')", yaml_line(root, path)))
        return None, issues


def _holds(document: Any, dotted: str) -> bool:
    """Whether ``document`` has a value at the first key of ``dotted`` (and the keys below it that are mappings)."""
    node = document
    for part in dotted.split(".") if dotted else ():
        if isinstance(node, Mapping) and part in node:
            node = node[part]
        elif isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        else:
            return node is not document
    return bool(dotted)


def _check_environment(label: str, item: Configuration, where: str, root: Any) -> None:
    """Build the environment the runs will train in: scenario, modalities, sensors, overrides, reward weights."""
    from crowdnav.evaluation.robot_rollout import ROBOTS_AGENTS, robot_count

    from crowdnav.envs import CrowdNavEnv
    from crowdnav.scenario import ScenarioError

    config = item.config
    try:
        CrowdNavEnv(config.scenario, modalities=config.modalities, sensors=config.sensors, overrides=config.overrides,
                    reward_weights=config.reward_weights).close()
        if config.agents == ROBOTS_AGENTS and robot_count({"scenario": config.scenario, "overrides": config.overrides}) < 2:
            raise ValueError(f"agents: robots needs a scenario with several robots (robots:), and {config.scenario!r} has one")
    except (ScenarioError, ValueError) as error:
        detail = " / ".join(str(error).splitlines())
        raise _error(label, [ConfigIssue(where, f"environment: {detail} (configuration '{item.name}')", yaml_line(root, where))]) from None
