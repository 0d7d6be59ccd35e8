"""``crowdnav track list | show NAME | check [NAME...] | reference NAME [--agents DIR [--played | --chosen-on-validation]]``.

The named, versioned test sets to rank on.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from crowdnav.cli.common import CliError

if TYPE_CHECKING:
    from crowdnav.evaluation.track import Track


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``track`` and its subcommands."""
    parser = subparsers.add_parser(
        "track", help="the tracks: named, versioned test sets (scenario, time limit, test seeds, allowed observations)",
        description="A track fixes what a policy is ranked on: the scenario and its overrides, the time limit, the test "
                    "episodes and seeds, the observation keys allowed, and a version (docs/evaluation.md#tracks). "
                    "Evaluate with `crowdnav evaluate POLICY --track NAME`, rank with `crowdnav leaderboard --track NAME`.",
    )
    commands = parser.add_subparsers(dest="track_command", metavar="SUBCOMMAND", required=True)
    listing = commands.add_parser("list", help="the shipped tracks, one line each")
    listing.set_defaults(handler=list_command)
    show = commands.add_parser("show", help="everything a track fixes")
    show.add_argument("name", metavar="NAME")
    show.set_defaults(handler=show_command)
    check = commands.add_parser("check", help="play each track's fingerprint episodes and compare with the stored fingerprint",
                                description="Exit 1 when a track's episodes changed: bump its version and store the printed fingerprint.")
    check.add_argument("names", nargs="*", metavar="NAME", help="default: every shipped track")
    check.set_defaults(handler=check_command)
    reference = commands.add_parser(
        "reference", help="play every scripted baseline on a track, or add trained reference agents, as small per-episode CSVs to publish",
        description="Writes OUT/<track>/baseline_<name>.csv and reference.json (straight, social_force, orca where pyrvo is "
                    "installed, onboard where the track allows its tracker, predictive, oracle where it does not refuse the "
                    "track). Resumable and idempotent: a baseline this commit already wrote is kept. With --baseline, plays "
                    "only those named and keeps the others as published (their rows and commit). Refuses a checkout with "
                    "uncommitted changes. With --agents, plays "
                    "nothing: it adds each training seed of a finished `crowdnav benchmark` configuration (its final "
                    "evaluation's episodes) as agent_<experiment>_<configuration>_seed<K>.csv, after checking that the "
                    "experiment ran the track's setting, from a clean commit, with every seed finished (at least 3). With "
                    "--played, each seed's final policy is played on the track instead, whose setting may differ from its "
                    "training's in the sensing only (sensors.*, e.g. figure4_lidar_tracker for a run trained on figure4).",
    )
    reference.add_argument("name", metavar="NAME")
    reference.add_argument("--agents", action="append", default=[], metavar="RESULTS_DIR/CONFIGURATION",
                           help="add this experiment configuration's seeds as reference agents (repeatable); the baselines "
                                "already there are kept")
    reference.add_argument("--played", action="store_true",
                           help="with --agents: play each seed's final policy (the snapshot its final evaluation played) on the "
                                "track's episodes with the track's setting, instead of copying its recorded final evaluation; the "
                                "track may differ from the training's setting in the sensing only (keys under sensors., e.g. "
                                "sensors.tracker), which the entry records (trained_setting) and its label says")
    reference.add_argument("--chosen-on-validation", action="store_true",
                           help="with --agents: each seed's test evaluation at the snapshot the declared early-stopping rule keeps "
                                "(most successes on validation episodes 500,000-500,299, ties to the later; the table "
                                "benchmarks/validation_choice.py stored, nothing played), as entries of their own (..._validated_seed<K>) "
                                "beside the final evaluation's")
    reference.add_argument("--baseline", action="append", default=None, metavar="NAME", dest="baselines",
                           help="play only this reference baseline (repeatable), e.g. one added since the track's results "
                                "were published; the other baselines are kept as published")
    reference.add_argument("--out", default="docs/results/tracks", metavar="DIR", help="default: %(default)s")
    reference.add_argument("--force", action="store_true", help="play every baseline again (with --agents: replace a different result)")
    reference.add_argument("--allow-dirty", action="store_true", help="write from a checkout with uncommitted changes (marked +dirty)")
    reference.set_defaults(handler=reference_command)


def _track(name: str, check_fingerprint: bool = True) -> Track:
    from crowdnav.evaluation.track import TrackError, load_track

    try:
        return load_track(name, check_fingerprint=check_fingerprint)
    except TrackError as error:
        raise CliError(str(error)) from None


def list_command(args: argparse.Namespace) -> int:
    from crowdnav.evaluation.track import load_track, shipped_tracks

    tracks = [load_track(name) for name in shipped_tracks()]
    width = max(len(track.label) for track in tracks)
    for track in tracks:
        print(f"{track.label:<{width}}  {track.test_episodes:>4} episodes  {track.description}")
    return 0


def show_command(args: argparse.Namespace) -> int:
    track = _track(args.name)
    for line in track.describe():
        print(line)
    return 0


def check_command(args: argparse.Namespace) -> int:
    from crowdnav.evaluation.track import fingerprint, shipped_tracks

    changed = 0
    for name in args.names or shipped_tracks():
        track = _track(name, check_fingerprint=False)  # comparing it is what check does, and says so
        now = fingerprint(track)
        if now == track.fingerprint:
            print(f"{track.label}: fingerprint {now} unchanged")
        else:
            changed += 1
            print(f"{track.label}: its episodes changed (fingerprint {now}, stored {track.fingerprint}): bump version to "
                  f"{track.version + 1} and set fingerprint: \"{now}\" in {track.source}, then regenerate its reference results")
    return 1 if changed else 0


def reference_command(args: argparse.Namespace) -> int:
    from crowdnav.evaluation.track import TrackError
    from crowdnav.evaluation.track_agents import write_agents
    from crowdnav.evaluation.track_reference import write_reference

    track = _track(args.name)
    if args.played and not args.agents:
        raise CliError("--played plays the trained policies of --agents RESULTS_DIR/CONFIGURATION: name one")
    if args.chosen_on_validation and not args.agents:
        raise CliError("--chosen-on-validation reads the runs of --agents RESULTS_DIR/CONFIGURATION: name one")
    if args.agents and args.baselines:
        raise CliError("--agents adds reference agents and plays nothing; --baseline plays baselines: one or the other")
    try:
        if args.agents:
            folder = write_agents(track, args.agents, args.out, allow_dirty=args.allow_dirty, force=args.force, played=args.played,
                                  chosen=args.chosen_on_validation, log=lambda line: print(line, flush=True))
        else:
            folder = write_reference(track, args.out, allow_dirty=args.allow_dirty, force=args.force, only=args.baselines,
                                     log=lambda line: print(line, flush=True))
    except TrackError as error:
        raise CliError(str(error)) from None
    print(f"wrote {folder}; rank against it with: crowdnav leaderboard --track {track.name} --reference {folder} RESULTS")
    return 0
