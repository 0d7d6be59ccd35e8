"""Pydantic validation errors rewritten for scenario authors.

Pydantic reports locations with union-branch tags (``robot.start.rectangle.min``) and
messages written for programmers ("Input should be a valid dictionary or instance of
World"). This module maps each error onto the document's own dotted path and says what
was expected, in the vocabulary of the scenario format.
"""

from __future__ import annotations

import difflib
import typing
from typing import Any

from pydantic import BaseModel, ValidationError
from pydantic.fields import FieldInfo

from crowdnav.scenario.errors import ScenarioIssue, show
from crowdnav.scenario.schema import Scenario

_MAPPING_ERRORS = {"model_type", "model_attributes_type", "dict_type"}


def schema_issues(error: ValidationError, document: dict) -> list[ScenarioIssue]:
    """One issue per document path; alternatives for the same path are joined with '; or'."""
    grouped: dict[str, list[str]] = {}
    for item in error.errors(include_url=False):
        path, message = describe(item, document)
        messages = grouped.setdefault(path, [])
        if message not in messages:
            messages.append(message)
    return [ScenarioIssue(path, "; or ".join(messages)) for path, messages in grouped.items()]


def describe(item: dict[str, Any], document: dict) -> tuple[str, str]:
    """Turn one pydantic error into (dotted path, message)."""
    parts = _document_parts(item, document)
    path = ".".join(str(part) for part in parts)
    kind, ctx = item["type"], item.get("ctx", {})
    got = f", got {show(item.get('input'))}"
    if kind == "extra_forbidden":
        allowed = sorted(model.model_fields) if (model := _walk(document, parts[:-1])[1]) else []
        close = difflib.get_close_matches(str(parts[-1]), allowed, n=1)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        expected = f" (expected one of: {', '.join(allowed)})" if allowed else ""
        return path, f"unknown key '{parts[-1]}'{hint}{expected}"
    if kind == "missing":
        field = _walk(document, parts)[0]
        about = f" ({field.description.rstrip('.')})" if field is not None and field.description else ""
        return path, f"required field is missing{about}"
    if kind == "union_tag_invalid":
        return path, f"unknown type {show(item['input'].get('type'))} (expected one of: {ctx.get('expected_tags', '')})"
    if kind == "union_tag_not_found":
        tags = ", ".join(repr(tag) for tag in _union_tags(_walk(document, parts)[0]))
        return path, f"expected a 'type' key, one of: {tags}"
    if kind in _MAPPING_ERRORS:
        return path, f"expected a mapping of fields (key: value){got}"
    if kind == "list_type":
        return path, f"expected a list{got}"
    if kind in ("too_short", "too_long"):
        bound = f"at least {ctx['min_length']}" if kind == "too_short" else f"at most {ctx['max_length']}"
        return path, f"expected {bound} items, got {ctx.get('actual_length')}: {show(item.get('input'))}"
    message = item["msg"]
    if message.startswith("Keys should be strings"):
        return path, f"expected field names (text) as keys{got}"
    if message.startswith("Value error, "):
        return path, message[len("Value error, ") :]
    if message.startswith("Input should be "):
        # "Input should be a valid number, unable to parse string as a number" -> "expected a valid number"
        wanted = message[len("Input should be ") :].split(", unable to")[0]
        if wanted.startswith(("greater", "less")):
            wanted = f"a value {wanted}"
        return path, f"expected {wanted}{got}"
    return path, f"{message[0].lower()}{message[1:]}{got}"


def _document_parts(item: dict[str, Any], document: dict) -> list[str | int]:
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


def _walk(document: dict, parts: list[str | int]) -> tuple[FieldInfo | None, type[BaseModel] | None]:
    """The schema field holding the value at ``parts``, and the model that value must be.

    Unions of models (regions, furniture) are resolved with the document's ``type`` keys.
    """
    model: type[BaseModel] | None = Scenario
    field: FieldInfo | None = None
    node: Any = document
    for part in parts:
        if isinstance(part, int):
            node = node[part] if isinstance(node, list) and part < len(node) else None
            continue
        field = model.model_fields.get(part) if model is not None else None
        if field is None:
            return None, None
        node = node.get(part) if isinstance(node, dict) else None
        model = _model_in(field.annotation, node)
    return field, model


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
    tags = []
    for model in _models_in(field.annotation):
        tag = model.model_fields.get("type")
        if tag is not None:
            tags.extend(typing.get_args(tag.annotation))
    return tags
