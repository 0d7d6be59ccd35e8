"""``crowdnav scenario``: list the library, validate files, print the JSON Schema."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from crowdnav.cli.common import CliError, add_override_option, format_table, parse_overrides


def register(groups: argparse._SubParsersAction) -> None:
    parser = groups.add_parser("scenario", help="list, validate and describe scenario files")
    commands = parser.add_subparsers(dest="scenario_command", metavar="SUBCOMMAND", required=True)

    listing = commands.add_parser("list", help="the library scenarios with their descriptions")
    listing.set_defaults(handler=list_command)

    validate = commands.add_parser(
        "validate",
        help="check scenario files or library names; exit status 1 if any is invalid",
        description="Load each scenario as an environment would (schema, geometry, modality names) and report every "
                    "problem with file, line and field.",
    )
    validate.add_argument("scenarios", nargs="+", metavar="FILE_OR_NAME", help="a YAML file or a library scenario name")
    add_override_option(validate)
    validate.set_defaults(handler=validate_command)

    schema = commands.add_parser("schema", help="print the JSON Schema of scenario files (for editors)")
    schema.add_argument("--output", "-o", type=Path, metavar="FILE", help="write the schema to FILE instead of stdout")
    schema.set_defaults(handler=schema_command)


def list_command(args: argparse.Namespace) -> int:
    from crowdnav.scenario.library import library_descriptions

    rows = sorted(library_descriptions().items())
    print(format_table(("NAME", "DESCRIPTION"), rows))
    return 0


def validate_command(args: argparse.Namespace) -> int:
    from crowdnav.envs.core import load_env_world
    from crowdnav.scenario import ScenarioError
    from crowdnav.scenario.library import resolve

    overrides = parse_overrides(args.overrides)
    invalid = 0
    for source in args.scenarios:
        try:
            load_env_world(source, overrides)
        except ScenarioError as error:
            invalid += 1
            print(error.report(), file=sys.stderr)
            continue
        print(f"OK {resolve(source)}")
    if invalid and len(args.scenarios) > 1:
        print(f"{invalid} of {len(args.scenarios)} scenarios are invalid", file=sys.stderr)
    return 1 if invalid else 0


def schema_command(args: argparse.Namespace) -> int:
    from crowdnav.scenario.schema import scenario_json_schema

    text = json.dumps(scenario_json_schema(), indent=2) + "\n"
    if args.output is None:
        sys.stdout.write(text)
        return 0
    try:
        args.output.write_text(text, encoding="utf-8")
    except OSError as error:
        raise CliError(f"cannot write {args.output}: {error.strerror or error}") from None
    print(f"wrote {args.output}", file=sys.stderr)
    return 0
