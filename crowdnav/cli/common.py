"""Helpers shared by the command groups."""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from typing import Any

import yaml

from crowdnav.errors import CrowdNavError
from crowdnav.yaml_input import YamlLimitError, parse_value

RECORDING_FORMATS = ("auto", "obsmat", "frames", "trajnet")
"""``--format`` of the recording commands: :data:`crowdnav.crowd.recording.RecordingFormat` (not imported: the CLI loads fast)."""


class CliError(CrowdNavError, Exception):
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
    """``["humans.count=20"]`` -> ``{"humans.count": 20}``; values are parsed as YAML.

    A value is read like a file (:mod:`crowdnav.yaml_input`): the same size, depth and alias
    limits, and YAML 1.2 numbers (``1e-6`` is a number, ``010`` stays text). The path's own
    limits are checked where it is applied (:func:`crowdnav.scenario.loader.read_scenario`).
    """
    overrides = {}
    for item in items:
        path, sep, text = item.partition("=")
        if not sep or not path.strip():
            raise CliError(f"--set expects PATH=VALUE, e.g. humans.count=20; got {_short(item)}")
        path = path.strip()
        try:
            overrides[path] = parse_value(text)
        except YamlLimitError as error:
            raise CliError(f"--set {_short(path)}: the value {error}") from None
        except yaml.YAMLError as error:
            problem = str(getattr(error, "problem", None) or error).splitlines()[0]  # one line, whatever PyYAML says
            raise CliError(f"--set {_short(path)}: value {_short(text)} is not valid YAML ({problem})") from None
    return overrides


def _short(text: str) -> str:
    """``repr(text)``, cut to 80 characters: a long value must not flood the one-line error."""
    shown = repr(text)
    return shown if len(shown) <= 80 else shown[:77] + "..."


def add_reward_options(parser: argparse.ArgumentParser) -> None:
    """``--reward PRESET`` and ``--reward-weight TERM=VALUE`` (repeatable); read them with :func:`reward_options`."""
    from crowdnav.scenario.reward_presets import REWARD_PRESETS, REWARD_TERMS

    parser.add_argument(
        "--reward", metavar="PRESET", choices=tuple(REWARD_PRESETS),
        help=f"reward preset: {', '.join(REWARD_PRESETS)} (default: the scenario's, else 'default'; docs/agents.md#reward)",
    )
    parser.add_argument(
        "--reward-weight", dest="reward_weights", metavar="TERM=VALUE", action="append", default=[], type=reward_weight,
        help=f"override one reward weight on top of the preset, repeatable, e.g. --reward-weight social=-50 "
             f"(terms: {', '.join(REWARD_TERMS)})",
    )


def reward_weight(text: str) -> tuple[str, float]:
    """``"social=-50"`` -> ``("social", -50.0)``; a usage error (exit status 2) naming the valid terms otherwise."""
    from crowdnav.scenario.reward_presets import REWARD_TERMS, unknown_term_message

    term, sep, value = (part.strip() for part in text.partition("="))
    if not sep or not term:
        raise argparse.ArgumentTypeError(f"expected TERM=VALUE, e.g. social=-50; got {text!r}")
    if term not in REWARD_TERMS:
        raise argparse.ArgumentTypeError(unknown_term_message(term))
    try:
        weight = float(value)
    except ValueError:
        weight = math.nan
    if not math.isfinite(weight):
        raise argparse.ArgumentTypeError(f"{term}: expected a finite number, got {value!r}")
    return term, weight


def reward_options(args: argparse.Namespace) -> dict[str, Any]:
    """``--reward`` and ``--reward-weight`` as a reward-weights mapping, e.g. ``{"preset": "paper", "social": -50.0}``."""
    weights: dict[str, Any] = {} if args.reward is None else {"preset": args.reward}
    weights.update(args.reward_weights)
    return weights


def format_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """Left-aligned columns separated by two spaces; the last column is not padded."""
    widths = [max(len(str(row[i])) for row in [header, *rows]) for i in range(len(header) - 1)]
    lines = []
    for row in [header, *rows]:
        cells = [str(cell).ljust(width) for cell, width in zip(row[:-1], widths, strict=True)] + [str(row[-1])]
        lines.append("  ".join(cells).rstrip())
    return "\n".join(lines)
