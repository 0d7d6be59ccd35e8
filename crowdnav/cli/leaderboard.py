"""``crowdnav evaluate`` and ``crowdnav leaderboard``: any policy on fixed test episodes (a scenario's, or a track's) and its rank.

Scripted policies (``baseline:NAME``, ``module:function``) evaluate and rank, with ``--track``,
in the core install: nothing on their path imports torch or pandas. Learned policies load
torch when they load; ``leaderboard`` without ``--track`` reads benchmark results with pandas.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from crowdnav.cli.common import CliError, add_override_option, parse_overrides


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``leaderboard`` and ``evaluate``."""
    board = subparsers.add_parser(
        "leaderboard", help="rank the configurations of results folders, or the entries of a track (markdown and CSV)",
        description="One row per configuration: final rates, IQM of final success with a bootstrap CI, area under "
                    "the success curve, social metrics, env steps and wall time. The same results give the same files. "
                    "With --track NAME: the track's reference results and every `crowdnav evaluate --track NAME` result "
                    "below RESULTS_DIR, ranked by success with paired statistics (McNemar's exact test) on the shared "
                    "episodes; results of another version of the track are refused.",
    )
    board.add_argument("results", nargs="*", metavar="RESULTS_DIR", help="folders written by `crowdnav benchmark` or `crowdnav evaluate`")
    board.add_argument("--out", metavar="PATH", help="output path without extension (default: RESULTS_DIR/leaderboard, first folder; "
                                                     "with --track: RESULTS_DIR/leaderboard_<track>)")
    board.add_argument("--track", metavar="NAME", help="rank the entries of this track (crowdnav track list)")
    board.add_argument("--reference", action="append", default=[], metavar="DIR",
                       help="--track: reference results to rank against (default: the clone's docs/results/tracks/<track>)")
    board.add_argument("--html", metavar="PATH", help="--track: also write a self-contained HTML page of the leaderboard "
                                                      "(a frame per entry, viewable offline)")
    board.add_argument("--challenger", metavar="NAME", help="--track: the entry the paired columns compare every row with (its name "
                                                            "or label; default: your best entry that is not a scripted baseline)")
    board.set_defaults(handler=leaderboard_command)

    evaluate = subparsers.add_parser(
        "evaluate", help="evaluate any policy on a scenario's or a track's fixed test episodes, ranked by `crowdnav leaderboard`",
        description="POLICY: a crowdnav run folder or checkpoint (a shared robot policy, train --agents robots, drives every "
                    "robot: one row per robot per episode; on a track, the first robot), an SB3 model .zip, module:function "
                    "(one observation dict -> 2 numbers), or baseline:NAME (straight, social_force, orca, predictive, oracle). Plays the test "
                    "episodes with seeds --test-seed-base, +1, ... (or the track's) and writes "
                    "OUT/evaluate/<name>--<scenario>/seeds_<first>-<last>/ in the protocol's format (docs/evaluate.md); "
                    "existing results are kept unless --force.",
    )
    evaluate.add_argument("policy", metavar="POLICY")
    where = evaluate.add_mutually_exclusive_group(required=True)
    where.add_argument("--scenario", metavar="NAME_OR_PATH", help="library scenario name or YAML file")
    where.add_argument("--track", metavar="NAME", help="a track (crowdnav track list): its scenario, time limit, episodes and seeds")
    evaluate.add_argument("--modalities", metavar="KEYS", help="comma-separated observation keys (default: the scenario's)")
    evaluate.add_argument("--episodes", type=int, metavar="N", help="test episodes (default: 20, or the track's; 500 for final rankings)")
    evaluate.add_argument("--test-seed-base", type=int, metavar="S", help="seed of the first test episode (default: 0, or the track's)")
    evaluate.add_argument("--name", metavar="NAME", help="configuration name in the results (default: from POLICY)")
    evaluate.add_argument("--out", default="results", metavar="DIR", help="results folder (default: %(default)s)")
    evaluate.add_argument("--force", action="store_true", help="replace this policy's results on this scenario and test set")
    evaluate.add_argument("--traceback", action="store_true", help="show the full traceback when the policy raises")
    evaluate.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    add_override_option(evaluate)
    evaluate.set_defaults(handler=evaluate_command)


def leaderboard_command(args: argparse.Namespace) -> int:
    if args.track:
        return track_leaderboard_command(args)
    if args.reference or args.html or args.challenger:
        raise CliError("--reference, --html and --challenger rank a track's entries: add --track NAME")
    if not args.results:
        raise CliError("name the results folders to rank (RESULTS_DIR ...), or a track (--track NAME)")
    from crowdnav.evaluation.leaderboard import write_leaderboard
    from crowdnav.evaluation.storage import ResultsError

    out = Path(args.out) if args.out else Path(args.results[0]) / "leaderboard"
    try:
        table, paths = write_leaderboard([Path(path) for path in args.results], out)
    except (ResultsError, OSError) as error:
        raise CliError(str(error)) from None
    for path in paths:
        print(f"wrote {path}")
    for gap in table.attrs.get("missing", []):  # named under the markdown table too
        print(f"crowdnav: not in the leaderboard: {gap.describe(folder=True)}", file=sys.stderr)
    return 0


def track_leaderboard_command(args: argparse.Namespace) -> int:
    from crowdnav.evaluation.storage import atomic_write_text
    from crowdnav.evaluation.track import TrackError, load_track
    from crowdnav.evaluation.track_leaderboard import default_reference, rank, read_entries, to_csv, to_markdown

    try:
        track = load_track(args.track)
        references = [Path(path) for path in args.reference] or [found for found in [default_reference(track)] if found is not None]
        if not references:
            print(f"crowdnav: no reference results of track {track.name} here (a clone's docs/results/tracks/{track.name}, or "
                  "--reference DIR): ranking the results named alone", file=sys.stderr)
        skipped: list[str] = []  # a folder with none of the track's results is refused; others passed over are named
        entries = read_entries(track, references) + read_entries(track, [Path(path) for path in args.results], require=True, skipped=skipped)
        board = rank(track, entries, challenger=args.challenger)
    except TrackError as error:
        raise CliError(str(error)) from None
    for line in skipped:
        print(f"crowdnav: not of track {track.label}, left out: {line}", file=sys.stderr)
    markdown = to_markdown(board)
    print(markdown, end="")
    out = Path(args.out) if args.out else (Path(args.results[0]) if args.results else Path(".")) / f"leaderboard_{track.name}"
    for path in (atomic_write_text(out.with_name(out.name + ".md"), markdown), atomic_write_text(out.with_name(out.name + ".csv"), to_csv(board))):
        print(f"wrote {path}")
    if args.html:
        from crowdnav.evaluation.track_page import write_page

        print(f"wrote {write_page(board, Path(args.html))}")
    return 0


def evaluate_command(args: argparse.Namespace) -> int:
    from crowdnav.agents.runs.folder import RunBusyError
    from crowdnav.evaluation.evaluate import PolicyError, ResultsExistError, evaluate_policy
    from crowdnav.evaluation.track import TrackError, load_track
    from crowdnav.scenario import ScenarioError

    modalities = [key.strip() for key in args.modalities.split(",") if key.strip()] if args.modalities else None
    if args.policy.startswith("baseline:"):
        from crowdnav.evaluation.baselines import unknown_baseline

        refused = unknown_baseline(args.policy.removeprefix("baseline:"))
        if refused:
            raise CliError(refused)
    track = None
    if args.track:
        taken = [option for option, value in (("--episodes", args.episodes), ("--test-seed-base", args.test_seed_base), ("--set", args.overrides))
                 if value not in (None, [])]
        if taken:
            raise CliError(f"{', '.join(taken)}: a track fixes its test episodes and scenario; leave {'them' if len(taken) > 1 else 'it'} out")
        try:
            track = load_track(args.track)
        except TrackError as error:
            raise CliError(str(error)) from None
    episodes = args.episodes if args.episodes is not None else (track.test_episodes if track else 20)
    seed_base = args.test_seed_base if args.test_seed_base is not None else (track.test_seed_base if track else 0)
    if episodes < 1:
        raise CliError(f"--episodes must be at least 1, got {episodes}")
    from crowdnav.agents.training.seeding import check_test_seeds

    try:
        check_test_seeds(seed_base, episodes)
    except ValueError as error:
        raise CliError(f"--test-seed-base / --episodes: {error}") from None
    from crowdnav.cli.signals import interrupt_on_sigterm

    with interrupt_on_sigterm() as stopped:  # SIGTERM stops it as Ctrl-C does: one line, nothing half-written
        try:
            folder = evaluate_policy(args.policy, args.scenario, args.out, modalities=modalities, episodes=episodes,
                                     test_seed_base=seed_base, overrides=parse_overrides(args.overrides), name=args.name,
                                     force=args.force, progress=not args.no_progress, track=track)
        except PolicyError as error:
            if args.traceback and error.__cause__ is not None:
                import traceback

                traceback.print_exception(error.__cause__)
            raise CliError(str(error).splitlines()[0]) from None
        except (ResultsExistError, RunBusyError, ScenarioError, TrackError, ValueError) as error:
            raise CliError(str(error).splitlines()[0]) from None
        except KeyboardInterrupt:
            print("crowdnav: interrupted before the results were written; run the same command again", file=sys.stderr)
            return stopped.exit_status
    from crowdnav.evaluation.storage import META_FILE, read_json

    meta = read_json(folder / META_FILE)
    robots = meta.get("robots") or []
    # a shared robot policy: rates over every robot's row, or (a track) the first robot's, the others the track's social-force robots
    played = f" x {len(robots)} robots ({', '.join(robots)})" if len(robots) > 1 else f" (it drives {robots[0]})" if robots else ""
    print(f"{args.policy}: " + ", ".join(f"{outcome} {rate:.0%}" for outcome, rate in meta["final"].items()) + f" on {episodes} test episodes"
          + played + (f" of track {track.label}" if track else ""))
    rank = f"crowdnav leaderboard --track {track.name} {args.out}" if track else f"crowdnav leaderboard {args.out}"
    print(f"wrote {folder}; rank with: {rank}")
    return 0
