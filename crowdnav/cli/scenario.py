"""``crowdnav scenario``: list the library, validate and describe files, print the JSON Schema."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from crowdnav.cli import scenario_recording as from_recording
from crowdnav.cli.common import CliError, add_override_option, format_table, parse_overrides
from crowdnav.cli.schema import schema_command


def register(groups: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = groups.add_parser("scenario", help="list, validate and describe scenario files")
    commands = parser.add_subparsers(dest="scenario_command", metavar="SUBCOMMAND", required=True)

    listing = commands.add_parser("list", help="the library scenarios with their descriptions")
    listing.set_defaults(handler=list_command)

    validate = commands.add_parser(
        "validate",
        help="check scenario files or library names; exit status 1 if any is invalid",
        description="Load each scenario as an environment would (schema, geometry, modality names, the crowd models: a "
                    "replayed recording is read and its places counted) and report every problem with file, line and field.",
    )
    validate.add_argument("scenarios", nargs="+", metavar="FILE_OR_NAME", help="a YAML file or a library scenario name")
    add_override_option(validate)
    validate.set_defaults(handler=validate_command)

    describe = commands.add_parser("describe", help="summarise a scenario: world, obstacles, robot, crowd groups, sensors",
                                   description="Load the scenario as an environment would and print what an episode holds.")
    describe.add_argument("scenario", metavar="FILE_OR_NAME", help="a YAML file or a library scenario name")
    add_override_option(describe)
    describe.set_defaults(handler=describe_command)

    from_recording.register(commands)

    schema = commands.add_parser("schema", help="print the JSON Schema of scenario files (for editors)")
    schema.add_argument("--output", "-o", type=Path, metavar="FILE", help="write the schema to FILE instead of stdout")
    schema.set_defaults(handler=schema_command, kind="scenario")  # the same command as `crowdnav schema scenario`


def list_command(args: argparse.Namespace) -> int:
    from crowdnav.scenario.library import library_descriptions

    rows = sorted(library_descriptions().items())
    print(format_table(("NAME", "DESCRIPTION"), rows))
    return 0


def validate_command(args: argparse.Namespace) -> int:
    from crowdnav.envs.core import load_env_world
    from crowdnav.scenario import ScenarioError
    from crowdnav.scenario.library import resolve
    from crowdnav.sim.simulator import Simulator

    overrides = parse_overrides(args.overrides)
    invalid = 0
    for source in args.scenarios:
        try:
            world, _ = load_env_world(source, overrides)
            Simulator(world)  # the environment's own build: its crowd models' checks (a replay's recording and places) too
        except ScenarioError as error:
            invalid += 1
            print(error.report(), file=sys.stderr)
            continue
        print(f"OK {resolve(source)}")
    if invalid and len(args.scenarios) > 1:
        print(f"{invalid} of {len(args.scenarios)} scenarios are invalid", file=sys.stderr)
    return 1 if invalid else 0


def _region(region: object) -> str:
    kind = getattr(region, "type", "?")
    if kind == "rectangle":
        return f"rectangle {tuple(region.min)}-{tuple(region.max)}"  # type: ignore[attr-defined]
    if kind == "circle":
        return f"circle at {tuple(region.center)} r {region.radius}" + (" (perimeter)" if getattr(region, "perimeter", False) else "")  # type: ignore[attr-defined]
    return str(kind)


def _regions(regions: object) -> str:
    items = regions if isinstance(regions, list | tuple) else [regions]
    return ", ".join(_region(region) for region in items) or "-"


def describe_lines(world: object) -> list[str]:
    """The summary ``crowdnav scenario describe`` prints, one fact per line."""
    scenario = world.scenario  # type: ignore[attr-defined]
    obstacles = world.obstacles  # type: ignore[attr-defined]
    area, humans = scenario.world, scenario.humans
    low, high = tuple(area.min), tuple(area.max)
    lines = [f"{scenario.name}: {scenario.description}".rstrip(": "),
             f"world: {high[0] - low[0]:g} m x {high[1] - low[1]:g} m from {low} to {high}, "
             + ("boundary walls" if area.boundary_walls else "open (leaving it ends the episode)")
             + (f", floor polygon of {len(area.points)} points" if area.points else ""),
             f"obstacles: {len(scenario.walls)} walls, {len(scenario.furniture)} pieces of furniture "
             f"({obstacles.polygon_count} polygons, {obstacles.disc_count} discs once compiled)",
             *(f"robot: {'' if scenario.robots is None else f'{name}, '}{robot.kinematics}, radius {robot.radius:g} m, "
               f"max speed {robot.max_speed:g} m/s; start {_regions(robot.start)}; goal {_regions(robot.goal)} (radius {robot.goal_radius:g} m)"
               for name, robot in zip(scenario.robot_names, scenario.robot_specs, strict=True)),
             f"time: step {scenario.time_step:g} s, at most {scenario.max_steps} steps ({scenario.max_steps * scenario.time_step:g} s)",
             f"humans: up to {humans.max_count}, model {humans.model}, {'see' if humans.see_robot else 'do not see'} the robot"]
    for _, group in humans.crowd:
        speed = group.preferred_speed if group.behaviour != "stand" else None
        count = f"{group.count[0]}-{group.count[1]}" if isinstance(group.count, list | tuple) else str(group.count)
        lines.append(f"  group {group.name}: {count} {group.behaviour}"
                     + (f" at {speed[0]:g}-{speed[1]:g} m/s" if speed else "")
                     + (f", goal rule {group.goal_rule}, on goal {group.on_goal}" if group.behaviour != "stand" else ""))
    lines.append(f"modalities: {', '.join(scenario.sensors.modalities)}")
    return lines


def describe_command(args: argparse.Namespace) -> int:
    from crowdnav.envs.core import load_env_world
    from crowdnav.scenario import ScenarioError

    try:
        world, _ = load_env_world(args.scenario, parse_overrides(args.overrides))
    except ScenarioError as error:
        raise CliError(str(error).splitlines()[0]) from None
    print("\n".join(describe_lines(world)))
    return 0
