"""Helpers shared by the command groups."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

import yaml


class CliError(Exception):
    """A user mistake a command reports as one line on stderr (exit status 1), never as a traceback."""


def add_override_option(parser: argparse.ArgumentParser) -> None:
    """``--set PATH=VALUE`` (repeatable): scenario overrides, values written in YAML."""
    parser.add_argument(
        "--set",
        dest="overrides",
        metavar="PATH=VALUE",
        action="append",
        default=[],
        help="override a scenario field, e.g. --set humans.count=20 --set humans.preferred_speed=[0.5,1.0]",
    )


def parse_overrides(items: Sequence[str]) -> dict[str, Any]:
    """``["humans.count=20"]`` -> ``{"humans.count": 20}``; values are parsed as YAML."""
    overrides = {}
    for item in items:
        path, sep, text = item.partition("=")
        if not sep or not path.strip():
            raise CliError(f"--set expects PATH=VALUE, e.g. humans.count=20; got {item!r}")
        try:
            overrides[path.strip()] = yaml.safe_load(text)
        except yaml.YAMLError as error:
            problem = getattr(error, "problem", None) or error
            raise CliError(f"--set {path.strip()}: value {text!r} is not valid YAML ({problem})") from None
    return overrides


def format_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """Left-aligned columns separated by two spaces; the last column is not padded."""
    widths = [max(len(str(row[i])) for row in [header, *rows]) for i in range(len(header) - 1)]
    lines = []
    for row in [header, *rows]:
        cells = [str(cell).ljust(width) for cell, width in zip(row[:-1], widths, strict=True)] + [str(row[-1])]
        lines.append("  ".join(cells).rstrip())
    return "\n".join(lines)
