"""The scenario library shipped in ``scenarios/`` and name resolution."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import yaml


def library_dir() -> Path:
    """Folder holding the library's YAML files (works for source trees and installed wheels)."""
    return Path(str(resources.files("crowdnav.scenarios")))


def library_names() -> list[str]:
    """Names of the library scenarios, sorted (``room_furniture`` for ``room_furniture.yaml``)."""
    return sorted(path.stem for path in library_dir().glob("*.yaml"))


def library_descriptions() -> dict[str, str]:
    """Name -> one-line description of every library scenario."""
    out = {}
    for name in library_names():
        with open(library_dir() / f"{name}.yaml", encoding="utf-8") as handle:
            document = yaml.safe_load(handle) or {}
        out[name] = str(document.get("description", ""))
    return out


def camel_name(name: str) -> str:
    """``room_furniture`` -> ``RoomFurniture`` (the Gymnasium id stem)."""
    return "".join(part.capitalize() for part in name.split("_") if part)


def resolve(source: str | Path) -> Path:
    """A library name or a path to a YAML file -> the file's path (existence is checked by the loader)."""
    text = str(source)
    looks_like_path = isinstance(source, Path) or text.endswith((".yaml", ".yml")) or "/" in text or "\\" in text
    if looks_like_path:
        return Path(text).expanduser()
    return library_dir() / f"{text}.yaml"
