"""``crowdnav scenario fit RECORDING``: fit the social force to recorded people (:mod:`crowdnav.crowd.fit`)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from crowdnav.cli.common import RECORDING_FORMATS, CliError
from crowdnav.files import atomic_write_text


def register(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = commands.add_parser(
        "fit", help="fit the humans' social force to a recording (ETH/UCY obsmat, frame id x y, TrajNet++) and compare it",
        description="Fit preferred speeds, relaxation time, human repulsion strength and range and anisotropy to the first part "
                    "of a recording (bounded Nelder-Mead on ADE) and print, for the held-out last part, the speed, distance and "
                    "straightness statistics and ADE/FDE of the recording, the default humans, the fit and constant velocity "
                    "(docs/simulator.md#fitting-the-social-force-to-people). Needs the fit extra (scipy).",
    )
    parser.add_argument("recording", nargs="?", metavar="RECORDING", help="an ETH/UCY obsmat.txt, a frame id x y file or TrajNet++ ndjson")
    parser.add_argument("--format", choices=RECORDING_FORMATS, default="auto", help="the file's layout (default: auto)")
    parser.add_argument("--annotation-step", type=float, default=0.4, metavar="S", help="seconds between annotations (ETH/UCY: 0.4)")
    parser.add_argument("--time-step", type=float, default=None, metavar="S", help="the grid's step (default: the annotation step)")
    parser.add_argument("--horizon", type=float, default=4.8, metavar="S", help="seconds simulated from each recorded state (default 4.8)")
    parser.add_argument("--stride", type=int, default=2, metavar="N", help="grid steps between two windows' starts (default 2)")
    parser.add_argument("--held-out", type=float, default=0.3, metavar="SHARE",
                        help="the last SHARE of the recording's time is held out for the figures (default 0.3)")
    parser.add_argument("--isotropic", action="store_true",
                        help="fix anisotropy at 1 (crowdnav's humans), so the fitted values are the ones a scenario runs")
    parser.add_argument("--max-rollouts", type=int, default=400, metavar="N", help="the optimiser's budget of rollouts (default 400)")
    parser.add_argument("--synthetic", type=Path, metavar="FILE",
                        help="first write a synthetic obsmat recording (the fit's own model, known parameters) to FILE and fit it")
    parser.add_argument("--out", "-o", type=Path, default=None, metavar="FILE", help="also write the table to FILE")
    parser.set_defaults(handler=fit_command)


def fit_command(args: argparse.Namespace) -> int:
    from crowdnav.crowd.fit import report, write_synthetic_obsmat
    from crowdnav.crowd.fit_model import cut_windows, split

    for name in ("annotation_step", "time_step", "horizon"):
        value = getattr(args, name)
        if value is not None and not (value > 0 and math.isfinite(value)):
            raise CliError(f"--{name.replace('_', '-')}: expected a number > 0, got {value:g}")
    if not 0 < args.held_out < 1:
        raise CliError(f"--held-out: expected a share between 0 and 1, got {args.held_out:g}")
    if args.stride < 1 or args.max_rollouts < 1:
        raise CliError(f"--stride and --max-rollouts: expected at least 1, got {args.stride} and {args.max_rollouts}")
    if (args.recording is None) == (args.synthetic is None):
        raise CliError("expected a RECORDING or --synthetic FILE (one of them)")
    if args.synthetic is not None:
        write_synthetic_obsmat(args.synthetic)
    recording = str(args.synthetic if args.synthetic is not None else args.recording)
    try:
        windows = cut_windows(recording, args.format, args.annotation_step, args.time_step, args.horizon, args.stride)
        train, test = split(windows, args.held_out)
    except ValueError as error:  # RecordingError (one line, FILE:LINE), too short a recording
        raise CliError(str(error).splitlines()[0]) from None
    table = report(train, test, Path(recording).name, {"anisotropy": 1.0} if args.isotropic else None, args.max_rollouts)
    sys.stdout.write(table)
    if args.out is not None:
        atomic_write_text(args.out, table)
    return 0
