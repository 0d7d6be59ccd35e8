"""``crowdnav scenario from-recording FILE``: write a scenario whose crowd replays a recording (:mod:`crowdnav.crowd.scene`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import yaml

from crowdnav.cli import scenario_fit
from crowdnav.cli.common import RECORDING_FORMATS, CliError
from crowdnav.files import atomic_write_text


def register(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = commands.add_parser(
        "from-recording", help="write a scenario whose crowd replays a recording (ETH/UCY obsmat, frame id x y, TrajNet++)",
        description="Read a recording and write a scenario around it: world bounds from the data (1 m margin), spawn and goal "
                    "areas where people enter and leave, a robot route across the people's main flow, humans.model: replay "
                    "on the file (docs/scenarios.md#recorded-crowds). Check it with `crowdnav scenario validate` and look at it "
                    "with `crowdnav render SCENARIO --episodes 1`.",
    )
    parser.add_argument("file", metavar="FILE", help="the recording")
    parser.add_argument("--format", choices=RECORDING_FORMATS, default="auto", help="the file's layout (default: auto, from the name and columns)")
    parser.add_argument("--annotation-step", type=float, default=0.4, metavar="S",
                        help="seconds between two annotations (default 0.4, ETH/UCY; a TrajNet++ scene's fps overrides it)")
    parser.add_argument("--time-step", type=float, default=0.2, metavar="S", help="the scenario's time step (default 0.2 s)")
    parser.add_argument("--max-steps", type=int, default=None, metavar="N",
                        help="steps per episode (default: the recording's length, at most 150)")
    parser.add_argument("--react-within", type=float, default=None, metavar="M",
                        help="recorded people within M metres of the robot react to it (default: pure replay)")
    parser.add_argument("--out", "-o", type=Path, default=None, metavar="FILE",
                        help="write the scenario to FILE (refused if it exists); default: print it")
    parser.set_defaults(handler=from_recording_command)
    scenario_fit.register(commands)  # `scenario fit` reads the same recordings


def from_recording_command(args: argparse.Namespace) -> int:
    from crowdnav.crowd.scene import scenario_from_recording

    for name in ("annotation_step", "time_step", "react_within"):
        value = getattr(args, name)
        if value is not None and not (value > 0 and value < float("inf")):
            raise CliError(f"--{name.replace('_', '-')}: expected a number > 0, got {value:g}")
    if args.max_steps is not None and args.max_steps < 1:
        raise CliError(f"--max-steps: expected at least 1, got {args.max_steps}")
    if args.out is not None and (args.out.exists() or args.out.is_symlink()):  # a dangling link too: "exists" follows it
        raise CliError(f"--out: {args.out} exists; choose another file or delete it")
    try:
        scenario = scenario_from_recording(args.file, args.format, args.annotation_step, out=args.out, time_step=args.time_step,
                                           max_steps=args.max_steps)
    except ValueError as error:  # RecordingError (one line, FILE:LINE) and a recording with nobody on the time grid
        raise CliError(str(error).splitlines()[0]) from None
    if args.react_within is not None:
        scenario["humans"]["replay"]["react_within"] = args.react_within
    header = (f"# Written by `crowdnav scenario from-recording {Path(args.file).name}`: the world, the areas and the robot's\n"
              "# route come from the recording (docs/scenarios.md#recorded-crowds); edit them freely.\n")
    text = header + yaml.safe_dump(scenario, sort_keys=False, default_flow_style=None, width=120)
    if args.out is None:
        sys.stdout.write(text)
        return 0
    atomic_write_text(args.out, text)  # never through a link planted after the check above
    print(f"wrote {args.out}: {scenario['humans']['count']} places, world {scenario['world']['min']} to {scenario['world']['max']}")
    return 0
