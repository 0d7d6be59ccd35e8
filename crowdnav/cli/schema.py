"""``crowdnav schema scenario|train|experiment``: the JSON Schema of each configuration file kind.

All three file kinds are pydantic models, so their schemas come from ``model_json_schema()``:
field names, types, defaults, allowed names (algorithms, encoder modes) and the one-line
description of every field. Editors use them (yaml-language-server), and so can other tools.
The models are imported inside the handler: ``crowdnav --help`` stays light.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from crowdnav.cli.common import CliError
from crowdnav.files import atomic_write_text

if TYPE_CHECKING:
    from pydantic import BaseModel

KINDS = {
    "scenario": "a scenario file (scenarios/*.yaml)",
    "train": "a training config (crowdnav train --config)",
    "experiment": "an experiment file (crowdnav benchmark; evaluation/experiments/*.yaml)",
}


def register(groups: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = groups.add_parser(
        "schema", help="print the JSON Schema of a scenario, training config or experiment file",
        description="Print the JSON Schema of one configuration file kind: "
                    + "; ".join(f"{kind}: {what}" for kind, what in KINDS.items()) + ".",
    )
    parser.add_argument("kind", choices=tuple(KINDS), help="which file kind")
    parser.add_argument("--output", "-o", type=Path, metavar="FILE", help="write the schema to FILE instead of stdout")
    parser.set_defaults(handler=schema_command)


def json_schema(kind: str) -> dict[str, Any]:
    """The JSON Schema of file kind ``kind`` (one of :data:`KINDS`)."""
    from crowdnav.scenario.schema import JSON_SCHEMA_DIALECT, scenario_json_schema

    if kind == "scenario":
        return scenario_json_schema()
    model: type[BaseModel]
    if kind == "train":
        from crowdnav.agents.training.config import TrainConfig

        model, title = TrainConfig, "crowdnav training config"
    elif kind == "experiment":
        from crowdnav.evaluation.experiment import ExperimentFile

        model, title = ExperimentFile, "crowdnav experiment"
    else:
        raise ValueError(f"unknown file kind {kind!r}; expected one of: {', '.join(KINDS)}")
    schema = model.model_json_schema()
    schema.pop("title", None)
    return {"$schema": JSON_SCHEMA_DIALECT, "title": title, **schema}


def schema_command(args: argparse.Namespace) -> int:
    """Print (or write to ``args.output``) the JSON Schema of ``args.kind``: ``crowdnav schema KIND`` and ``crowdnav scenario schema``."""
    text = json.dumps(json_schema(args.kind), indent=2) + "\n"
    if args.output is None:
        sys.stdout.write(text)
        return 0
    if not args.output.parent.is_dir():  # as before: no folders made for it (the atomic write would make them)
        raise CliError(f"cannot write {args.output}: no folder {args.output.parent}")
    try:
        atomic_write_text(args.output, text)  # replaces a link at OUTPUT, never writes through it
    except OSError as error:
        raise CliError(f"cannot write {args.output}: {error.strerror or error}") from None
    print(f"wrote {args.output}", file=sys.stderr)
    return 0
