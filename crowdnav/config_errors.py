"""One error style for every configuration file crowdnav reads: scenarios, training configs, experiments.

All three are pydantic models (:mod:`crowdnav.scenario.schema`, :mod:`crowdnav.agents.training.config`,
:mod:`crowdnav.evaluation.experiment`). A failed validation becomes a list of
:class:`ConfigIssue`, each printed as::

    FILE:LINE: dotted.field.path: what was expected, got WHAT; did you mean 'X'?

Pydantic reports locations with union-branch tags (``robot.start.rectangle.min``) and messages
written for programmers ("Input should be a valid dictionary or instance of World");
:func:`validation_issues` maps each error onto the document's own dotted path and says what was
expected in the file's vocabulary. :func:`yaml_line` finds the line of a dotted path in the
``yaml.compose`` tree of the file.
"""

from __future__ import annotations

import re
import typing
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ValidationError
from pydantic.fields import FieldInfo
from pydantic_core import ErrorDetails

from crowdnav.errors import CrowdNavError
from crowdnav.suggest import did_you_mean
from crowdnav.yaml_input import YamlLimitError, read_bounded_yaml


def show(value: Any) -> str:
    """A value as the YAML author wrote it (lists, not tuples), shortened for messages."""
    text = repr(list(value) if isinstance(value, tuple) else value)
    return text if len(text) <= 80 else text[:77] + "..."


@dataclass(frozen=True)
class ConfigIssue:
    """One problem found in a configuration document."""

    path: str
    """Dotted location inside the document, e.g. ``humans.count`` ('' for the whole document)."""
    message: str
    """What is wrong and what was expected."""
    line: int | None = None
    """1-based line in the YAML file, when it can be found."""


def format_issue(source: str, issue: ConfigIssue) -> str:
    """``source:line: path: message`` (line and path left out when unknown)."""
    where = source if issue.line is None else f"{source}:{issue.line}"
    field = f" {issue.path}:" if issue.path else ""
    return f"{where}:{field} {issue.message}"


def format_issues(source: str, issues: Iterable[ConfigIssue], separator: str = "\n") -> str:
    return separator.join(format_issue(source, issue) for issue in issues)


class FieldProblems(CrowdNavError, ValueError):
    """Raised by a model validator for cross-field rules: ``(dotted path, message)`` pairs.

    Pydantic reports a model validator's error at the model itself; :func:`validation_issues`
    unpacks this one onto the fields it names, so they get their own path and line.
    """

    def __init__(self, problems: Sequence[tuple[str, str]]):
        self.problems = list(problems)
        super().__init__("; ".join(f"{path}: {message}" for path, message in self.problems))


def yaml_line(root: yaml.Node | None, dotted: str) -> int | None:
    """1-based line of the deepest YAML node on the path ``dotted`` (``yaml.compose`` tree), or None without a tree."""
    if root is None:
        return None
    node, line = root, int(root.start_mark.line) + 1
    for part in filter(None, dotted.split(".")):
        if isinstance(node, yaml.MappingNode):
            match = [(k, v) for k, v in node.value if k.value == part]
            if not match:
                break
            key, node = match[0]
            line = key.start_mark.line + 1
        elif isinstance(node, yaml.SequenceNode) and part.isdigit() and int(part) < len(node.value):
            node = node.value[int(part)]
            line = node.start_mark.line + 1
        else:
            break
    return line


def read_yaml(text: str) -> tuple[Any, yaml.Node | None]:
    """``(document, node tree)`` of a YAML text at a bounded cost (:mod:`crowdnav.yaml_input`);
    malformed YAML or a text over the limits is turned into one :class:`ConfigIssue`."""
    try:
        return read_bounded_yaml(text)
    except YamlLimitError as error:
        raise YamlProblem(ConfigIssue("", str(error), error.line)) from None
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        line = None if mark is None else mark.line + 1
        raise YamlProblem(ConfigIssue("", f"malformed YAML: {getattr(error, 'problem', None) or error}", line)) from None


class YamlProblem(CrowdNavError, ValueError):
    """A text that is not YAML; ``issue`` says where."""

    def __init__(self, issue: ConfigIssue):
        self.issue = issue
        super().__init__(issue.message)


# ------------------------------------------------------------------ pydantic errors -> issues

_MAPPING_ERRORS = {"model_type", "model_attributes_type", "dict_type"}
_TYPE_WORDS = {
    "int_type": "an integer", "int_parsing": "an integer", "int_from_float": "an integer",
    "float_type": "a number", "float_parsing": "a number",
    "bool_type": "true or false", "bool_parsing": "true or false",
    "string_type": "a string",
}
_BOUNDS = {"greater_than_equal": (">=", "ge"), "greater_than": (">", "gt"), "less_than_equal": ("<=", "le"), "less_than": ("<", "lt")}


def validation_issues(error: ValidationError, document: Any, model: type[BaseModel]) -> list[ConfigIssue]:
    """One issue per document path (``model`` validated ``document``); alternatives for one path joined with '; or'."""
    grouped: dict[str, list[str]] = {}
    for item in error.errors(include_url=False):
        problems = item.get("ctx", {}).get("error")
        if isinstance(problems, FieldProblems):
            prefix = ".".join(str(part) for part in _document_parts(item, document))
            pairs = [(f"{prefix}.{path}" if prefix else path, message) for path, message in problems.problems]
        else:
            pairs = [describe(item, document, model)]
        for path, message in pairs:
            messages = grouped.setdefault(path, [])
            if message not in messages:
                messages.append(message)
    return [ConfigIssue(path, "; or ".join(messages)) for path, messages in grouped.items()]


def describe(item: ErrorDetails, document: Any, model: type[BaseModel]) -> tuple[str, str]:
    """Turn one pydantic error into (dotted path, message)."""
    parts = _document_parts(item, document)
    path = ".".join(str(part) for part in parts)
    kind, ctx = item["type"], item.get("ctx", {})
    got = f", got {show(item.get('input'))}"
    field = _walk(model, document, parts)[0] if parts else None
    nullable = " or null" if field is not None and _allows_none(field.annotation) else ""
    if kind == "extra_forbidden":
        parent = _walk(model, document, parts[:-1])[1] if len(parts) > 1 else model
        allowed = sorted(parent.model_fields) if parent is not None else []
        expected = f" (expected one of: {', '.join(allowed)})" if allowed else ""
        return path, f"unknown key '{parts[-1]}'{did_you_mean(parts[-1], allowed)}{expected}"
    if kind == "missing":
        about = f" ({field.description.rstrip('.')})" if field is not None and field.description else ""
        return path, f"required field is missing{about}"
    if kind == "union_tag_invalid":
        return path, f"unknown type {show(item['input'].get('type'))} (expected one of: {ctx.get('expected_tags', '')})"
    if kind == "union_tag_not_found":
        tags = ", ".join(repr(tag) for tag in _union_tags(field))
        return path, f"expected a 'type' key, one of: {tags}"
    if kind in _MAPPING_ERRORS:
        return path, f"expected a mapping of fields (key: value){got}"
    if kind == "list_type":
        return path, f"expected {_list_words(field)}{nullable}{got}"
    if kind == "literal_error":
        valid = re.findall(r"'((?:[^'\\]|\\.)*)'", str(ctx.get("expected", "")))
        listed = ", ".join(repr(value) for value in valid) or ctx.get("expected", "")
        return path, f"expected one of {listed}{got}{did_you_mean(item.get('input'), valid)}"
    if kind in _TYPE_WORDS:
        return path, f"expected {_TYPE_WORDS[kind]}{nullable}{got}"
    if kind in _BOUNDS:
        symbol, key = _BOUNDS[kind]
        bound = ctx.get(key)
        bound = f"{bound:g}" if isinstance(bound, float) else bound
        return path, f"expected {_number_words(field)} {symbol} {bound}{got}"
    if kind in ("too_short", "too_long"):
        bound = f"at least {ctx['min_length']}" if kind == "too_short" else f"at most {ctx['max_length']}"
        return path, f"expected {bound} items, got {ctx.get('actual_length')}: {show(item.get('input'))}"
    message = item["msg"]
    if message.startswith("Keys should be strings"):
        return path, f"expected field names (text) as keys{got}"
    if message.startswith("Value error, "):
        return path, message[len("Value error, ") :]
    if message.startswith("Input should be "):
        # "Input should be a finite number" -> "expected a finite number"
        wanted = message[len("Input should be ") :].split(", unable to")[0]
        return path, f"expected {wanted}{got}"
    return path, f"{message[0].lower()}{message[1:]}{got}"


def _document_parts(item: ErrorDetails, document: Any) -> list[str | int]:
    """The error's location without union-branch tags such as 'rectangle' or 'int'."""
    parts: list[str | int] = []
    node: Any = document
    for component in item["loc"]:
        if isinstance(node, dict) and component in node:
            parts.append(component)
            node = node[component]
        elif isinstance(node, list) and isinstance(component, int) and component < len(node):
            parts.append(component)
            node = node[component]
        elif item["type"] == "missing" and component == item["loc"][-1]:
            parts.append(component)
    return parts


def _walk(model: type[BaseModel], document: Any, parts: list[str | int]) -> tuple[FieldInfo | None, type[BaseModel] | None]:
    """The schema field holding the value at ``parts``, and the model that value must be.

    Unions of models (scenario regions, furniture) are resolved with the document's ``type`` keys.
    """
    current: type[BaseModel] | None = model
    field: FieldInfo | None = None
    node: Any = document
    for part in parts:
        if isinstance(part, int):
            node = node[part] if isinstance(node, list) and part < len(node) else None
            continue
        field = current.model_fields.get(part) if current is not None else None
        if field is None:
            return None, None
        node = node.get(part) if isinstance(node, dict) else None
        current = _model_in(field.annotation, node)
    return field, current


def _model_in(annotation: Any, data: Any) -> type[BaseModel] | None:
    candidates = _models_in(annotation)
    if len(candidates) > 1 and isinstance(data, dict):
        for candidate in candidates:
            tag = candidate.model_fields.get("type")
            if tag is not None and data.get("type") in typing.get_args(tag.annotation):
                return candidate
    return candidates[0] if candidates else None


def _models_in(annotation: Any) -> list[type[BaseModel]]:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [model for arg in typing.get_args(annotation) for model in _models_in(arg)]


def _union_tags(field: FieldInfo | None) -> list[str]:
    """The ``type`` values accepted by a field holding a tagged union (regions, furniture)."""
    if field is None:
        return []
    tags: list[str] = []
    for model in _models_in(field.annotation):
        tag = model.model_fields.get("type")
        if tag is not None:
            tags.extend(typing.get_args(tag.annotation))
    return tags


def _allows_none(annotation: Any) -> bool:
    return type(None) in typing.get_args(annotation)


def _base(annotation: Any) -> Any:
    """``int | None`` -> ``int``; ``Annotated[int, ...]`` -> ``int``."""
    args = [arg for arg in typing.get_args(annotation) if arg is not type(None)]
    if typing.get_origin(annotation) is typing.Annotated or (args and _allows_none(annotation) and len(args) == 1):
        return _base(args[0])
    return annotation


def _number_words(field: FieldInfo | None) -> str:
    base: Any = _base(field.annotation) if field is not None else None
    if typing.get_origin(base) is list and typing.get_args(base):  # an item of a list field
        base = _base(typing.get_args(base)[0])
    return {int: "an integer", float: "a number"}.get(base, "a value")


def _list_words(field: FieldInfo | None) -> str:
    base = _base(field.annotation) if field is not None else None
    if typing.get_origin(base) is list and typing.get_args(base):
        item = _base(typing.get_args(base)[0])
        if typing.get_origin(item) is Literal or item is str:
            return "a list of strings"
        return {int: "a list of integers", float: "a list of numbers"}.get(item, "a list")
    return "a list"
