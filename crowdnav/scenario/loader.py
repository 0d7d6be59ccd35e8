"""Load a scenario: YAML with line numbers -> overrides -> schema -> consistency checks.

Every failure becomes a :class:`ScenarioError` naming the file, the dotted path and, where
the YAML node can be found, the line. The loader is pure (text in, :class:`Scenario` out):
the geometry is checked when the world is compiled (:func:`crowdnav.worlds.compiled.load_world`) and
modality names when the sensors are built; :meth:`LoadedScenario.error` lets those later
checks report their problems with the same file and lines.
"""

from __future__ import annotations

import copy
import difflib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from crowdnav.config_errors import YamlProblem, read_yaml, yaml_line
from crowdnav.paths import safe_stem
from crowdnav.scenario import library
from crowdnav.scenario.crowd import Humans
from crowdnav.scenario.errors import ScenarioError, ScenarioIssue, show
from crowdnav.scenario.messages import schema_issues
from crowdnav.scenario.schema import Scenario
from crowdnav.yaml_input import MAX_DEPTH, MAX_VALUES, YamlLimitError, check_value, read_text_file

Overrides = Mapping[str, Any]
MAX_PATH_CHARACTERS = 1_000
"""Longest dotted override path (a scenario's deepest field is a few dozen characters)."""


@dataclass(frozen=True)
class LoadedScenario:
    """A validated scenario and where it came from, to report problems found after loading."""

    scenario: Scenario
    label: str
    """The file (or library file), ``<mapping>``, or the scenario's name."""
    root: yaml.Node | None = None
    """The YAML node tree of the file, for line numbers (None without a file)."""
    override_paths: frozenset[str] = frozenset()

    def error(self, issues: Sequence[ScenarioIssue]) -> ScenarioError:
        """A ScenarioError for ``issues`` found later (geometry, modality names), with file and lines like the loader's."""
        return ScenarioError(self.label, [_with_line(issue, self.root, set(self.override_paths)) for issue in issues])


def load_scenario(source: str | Path | Mapping[str, Any], overrides: Overrides | None = None) -> Scenario:
    """Load and validate a scenario (YAML, schema, consistency between fields).

    ``source`` is a library name (``"room_furniture"``), a path to a YAML file, or an
    already-parsed mapping. ``overrides`` maps dotted paths to values, e.g.
    ``{"humans.count": 10, "walls.0.thickness": 0.2}``; they are validated like the file.
    The geometry is checked when the world is compiled (:func:`crowdnav.worlds.compiled.load_world`).
    """
    return read_scenario(source, overrides).scenario


def read_scenario(source: str | Path | Mapping[str, Any] | Scenario, overrides: Overrides | None = None) -> LoadedScenario:
    """:func:`load_scenario`, keeping the file's label and YAML tree (:class:`LoadedScenario`).

    A :class:`Scenario` is taken as it is, or validated again with ``overrides`` applied.
    """
    if isinstance(source, Scenario):
        if not overrides:
            return LoadedScenario(source, source.name or "<scenario>")
        source = source.model_dump()
    if isinstance(source, Mapping):
        label = "<mapping>"
        _check_bounded(label, "", source, "the scenario mapping")  # before copying: deepcopy recurses
        document, root = copy.deepcopy(dict(source)), None
    else:
        path = library.resolve(source)
        label = str(path)
        if path.is_dir():
            expected = "is a directory; expected a scenario YAML file or a library scenario name"
            raise ScenarioError(label, [ScenarioIssue("", expected)])
        if not path.exists():  # a FIFO or device is refused by name when read
            raise _not_found(source, path)
        document, root = _read_yaml(path)
    override_paths = set()
    for dotted, value in _checked_overrides(label, overrides).items():
        _apply_override(label, document, dotted, value)
        override_paths.add(dotted)
    if override_paths:  # each override was within the limits; together they must be too
        _check_bounded(label, "", document, "the scenario with its overrides")
    if isinstance(source, (str, Path)) and document.get("name") is None:
        document["name"] = safe_stem(library.resolve(source).stem)
    scenario = _validate_schema(label, document, root, override_paths)
    loaded = LoadedScenario(scenario, label, root, frozenset(override_paths))
    issues = consistency_issues(scenario)
    if issues:
        raise loaded.error(issues)
    return loaded


def _not_found(source: str | Path, path: Path) -> ScenarioError:
    if path.parent != library.library_dir() or isinstance(source, Path):
        return ScenarioError(str(path), [ScenarioIssue("", "file not found")])
    names = library.library_names()
    close = difflib.get_close_matches(str(source), names, n=1)
    hint = f"did you mean '{close[0]}'? " if close else ""
    message = f"no such file or library scenario; {hint}library scenarios: {', '.join(names)}"
    return ScenarioError(str(source), [ScenarioIssue("", message)])


def _checked_overrides(label: str, overrides: Overrides | None) -> Overrides:
    """``overrides`` within the limits a file has (:mod:`crowdnav.yaml_input`), whoever passed them:
    ``--set``, a training config or experiment, an env's ``overrides=`` or options."""
    if overrides is None:
        return {}
    if not isinstance(overrides, Mapping):
        message = f"overrides must be a mapping of dotted paths to values, got {type(overrides).__name__}"
        raise ScenarioError(label, [ScenarioIssue("", message)])
    if len(overrides) > MAX_VALUES:
        raise ScenarioError(label, [ScenarioIssue("", f"{len(overrides):,} overrides; expected at most {MAX_VALUES:,}")])
    for dotted, value in overrides.items():
        if not isinstance(dotted, str) or not dotted:
            raise ScenarioError(label, [ScenarioIssue("", f"override paths must be dotted field names, got {show(dotted)}")])
        if not dotted.isprintable():  # a newline in the path would break the one-line report
            raise ScenarioError(label, [ScenarioIssue("", f"override path {show(dotted)} holds control characters; expected a dotted field name")])
        if len(dotted) > MAX_PATH_CHARACTERS or dotted.count(".") >= MAX_DEPTH:
            message = (f"override path of {len(dotted):,} characters and {dotted.count('.') + 1:,} parts; "
                       f"expected at most {MAX_PATH_CHARACTERS:,} characters and {MAX_DEPTH} parts")
            raise ScenarioError(label, [ScenarioIssue(dotted[:60] + "...", message)])
        _check_bounded(label, dotted, value, "the override value")
    return overrides


def _check_bounded(label: str, path: str, value: Any, what: str) -> None:
    try:
        check_value(value, what)
    except YamlLimitError as error:
        raise ScenarioError(label, [ScenarioIssue(path, str(error))]) from None


def _read_yaml(path: Path) -> tuple[dict[str, Any], yaml.Node | None]:
    label = str(path)
    try:
        text = read_text_file(path)  # a regular UTF-8 file of bounded size
    except YamlLimitError as error:
        raise ScenarioError(label, [ScenarioIssue("", str(error), error.line)]) from None
    try:
        document, root = read_yaml(text)  # bounded cost, one error style
    except YamlProblem as problem:
        raise ScenarioError(label, [ScenarioIssue("", problem.issue.message, problem.issue.line)]) from None
    if not isinstance(document, dict):
        kind = "an empty file" if document is None else type(document).__name__
        raise ScenarioError(label, [ScenarioIssue("", f"expected a mapping of scenario fields at the top level, got {kind}", 1)])
    duplicates = _duplicate_keys(root, "")
    if duplicates:
        raise ScenarioError(label, duplicates)
    return document, root


def _duplicate_keys(node: yaml.Node, path: str, seen: set[int] | None = None) -> list[ScenarioIssue]:
    """YAML silently keeps the last of two equal keys; for a config file that is always a mistake.

    Each distinct node is visited once: an aliased node is one object however often it is used.
    """
    seen = set() if seen is None else seen
    if id(node) in seen:
        return []
    seen.add(id(node))
    issues = []
    if isinstance(node, yaml.MappingNode):
        first_line: dict[str, int] = {}
        for key, value in node.value:
            name = str(key.value)
            child = f"{path}.{name}" if path else name
            line = key.start_mark.line + 1
            if name in first_line and name != "<<":
                message = f"duplicate key '{name}' (first given at line {first_line[name]}); expected it once"
                issues.append(ScenarioIssue(child, message, line))
            first_line.setdefault(name, line)
            issues.extend(_duplicate_keys(value, child, seen))
    elif isinstance(node, yaml.SequenceNode):
        for index, item in enumerate(node.value):
            issues.extend(_duplicate_keys(item, f"{path}.{index}" if path else str(index), seen))
    return issues


def _apply_override(label: str, document: dict[str, Any], dotted: str, value: Any) -> None:
    parts = dotted.split(".")
    node: Any = document
    for depth, part in enumerate(parts[:-1]):
        key: Any = int(part) if isinstance(node, list) and part.isdigit() else part
        try:
            child = node[key]
        except (KeyError, IndexError, TypeError):
            if isinstance(node, dict) and not parts[depth + 1].isdigit():
                child = node[key] = {}
            else:
                where = ".".join(parts[: depth + 1])
                raise ScenarioError(label, [ScenarioIssue(dotted, f"override path does not exist at '{where}'")]) from None
        node = child
    last = parts[-1]
    if isinstance(node, list):
        if not last.isdigit() or int(last) >= len(node):
            message = f"override index '{last}' is not in the list (length {len(node)})"
            raise ScenarioError(label, [ScenarioIssue(dotted, message)])
        node[int(last)] = value
    elif isinstance(node, dict):
        node[last] = value
    else:
        where = ".".join(parts[:-1])
        message = f"override path goes through '{where}', which holds {show(node)}, not a mapping or list"
        raise ScenarioError(label, [ScenarioIssue(dotted, message)])


def _validate_schema(label: str, document: dict[str, Any], root: yaml.Node | None, override_paths: set[str]) -> Scenario:
    try:
        return Scenario.model_validate(document)
    except ValidationError as error:
        issues = schema_issues(error, document)
        raise ScenarioError(label, [_with_line(issue, root, override_paths) for issue in issues]) from None


def _with_line(issue: ScenarioIssue, root: yaml.Node | None, override_paths: set[str]) -> ScenarioIssue:
    """Attach the YAML line; an issue inside an overridden value has no line in the file."""
    if any(issue.path == p or issue.path.startswith(p + ".") for p in override_paths):
        return ScenarioIssue(issue.path, f"{issue.message} (from override)", None)
    inner = sorted(p for p in override_paths if issue.path and p.startswith(issue.path + "."))
    suffix = f" (with override {', '.join(inner)})" if inner else ""
    return ScenarioIssue(issue.path, issue.message + suffix, yaml_line(root, issue.path))


def consistency_issues(scenario: Scenario) -> list[ScenarioIssue]:
    """Cross-field rules that the per-field schema cannot express (modality names: when the sensors are built)."""
    issues = []
    humans = scenario.humans
    for path, robot in zip(scenario.robot_paths, scenario.robot_specs, strict=True):
        issues += _robot_issues(scenario, path, robot)
    for path, group in humans.crowd:
        if group.max_count > 0 and not group.spawn:
            issues.append(ScenarioIssue(f"{path}.spawn", f"expected at least one spawn region when {path}.count > 0"))
        if group.max_count > 0 and not group.standing and group.goal_rule == "sample" and not group.goal:
            issues.append(ScenarioIssue(f"{path}.goal", "expected at least one goal region when goal_rule is 'sample'"))
        if group.standing and group.circle_radius is not None and group.max_count > 1:
            chord = 2 * group.circle_radius * math.sin(math.pi / group.max_count)
            if chord < 2 * humans.radius:
                issues.append(ScenarioIssue(f"{path}.circle_radius", (
                    f"{group.max_count} humans of radius {humans.radius:g} m overlap on a circle of radius {group.circle_radius:g} m; "
                    f"expected at least {humans.radius / math.sin(math.pi / group.max_count):.2f} m")))
    # Humans are pushed back out of walls after each (sub-)step; moving less than their radius per
    # sub-step guarantees their centre never crosses a wall before that happens (human_substeps).
    human_step = humans_step_length(scenario)
    if humans.max_count > 0 and human_step >= MAX_HUMAN_SUBSTEPS * humans.radius:
        issues.append(ScenarioIssue(
            _fastest_speed_field(humans),
            f"humans move up to {human_step:g} m per step (preferred_speed max * max_speed_factor * time_step); "
            f"expected less than {MAX_HUMAN_SUBSTEPS} times their radius {humans.radius:g} m (at most {MAX_HUMAN_SUBSTEPS} sub-steps "
            "of less than the radius each): lower preferred_speed or time_step",
        ))
    return issues


MAX_HUMAN_SUBSTEPS = 4
"""Most sub-steps a step splits the humans' motion into: humans may move up to this many radii per step (4 x 0.3 m at
0.2 s: 6 m/s, three times a brisk walk); faster ones are refused at load."""


def humans_step_length(scenario: Scenario) -> float:
    """The farthest a human can move in one step (m): preferred_speed max * max_speed_factor * time_step."""
    humans = scenario.humans
    return humans.max_preferred_speed * humans.social_force.max_speed_factor * scenario.time_step


def human_substeps(scenario: Scenario) -> int:
    """Sub-steps of the humans' motion per step: the fewest that move each human less than its radius per sub-step.

    1 whenever a step moves them less than their radius (every scenario loadable before sub-steps existed: the same
    episodes bit for bit); a loaded scenario needs at most :data:`MAX_HUMAN_SUBSTEPS`.
    """
    step, radius = humans_step_length(scenario), scenario.humans.radius
    if scenario.humans.max_count == 0 or step < radius:
        return 1
    count = math.floor(step / radius) + 1
    while step / count >= radius:  # a quotient rounded up to a whole number
        count += 1
    return count


def _robot_issues(scenario: Scenario, path: str, robot: Any) -> list[ScenarioIssue]:
    """The cross-field rules of one robot written at ``path`` (``robot`` or ``robots.<i>``)."""
    issues = []
    if robot.kinematics == "unicycle" and robot.max_angular_speed is None:
        issues.append(ScenarioIssue(f"{path}.max_angular_speed", "expected a maximum angular speed (rad/s) for unicycle kinematics"))
    if robot.kinematics == "holonomic" and robot.max_angular_speed is not None:
        issues.append(ScenarioIssue(
            f"{path}.max_angular_speed", "only applies to unicycle kinematics; remove it or set kinematics: unicycle"))
    # A body moving less than its diameter per step cannot jump across an edge unnoticed,
    # which keeps collision checks at step ends exact.
    robot_step = robot.max_speed * scenario.time_step
    if robot_step >= 2 * robot.radius:
        issues.append(ScenarioIssue(
            f"{path}.max_speed",
            f"robot moves up to {robot_step:g} m per step (max_speed * time_step); expected less than its diameter "
            f"{2 * robot.radius:g} m: lower max_speed or time_step",
        ))
    if robot.start_heading not in ("random", "toward_goal") and not math.isfinite(float(robot.start_heading)):
        issues.append(ScenarioIssue(f"{path}.start_heading", "expected 'random', 'toward_goal' or a finite angle in degrees"))
    return issues


def _fastest_speed_field(humans: Humans) -> str:
    """Where the fastest walking speed is written: a group's own preferred_speed, or the shared one."""
    for i, group in enumerate(humans.groups):
        own = group.preferred_speed
        if own is not None and not group.standing and own[1] == humans.max_preferred_speed:
            return f"humans.groups.{i}.preferred_speed"
    return "humans.preferred_speed"
