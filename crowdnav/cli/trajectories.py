"""``crowdnav trajectories``: the test episodes of results or of any policy, as a tidy CSV and TrajNet++ ndjson."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from crowdnav.cli.common import CliError, add_override_option, parse_overrides


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``trajectories``."""
    traj = subparsers.add_parser(
        "trajectories", help="export test episodes (of results or of any policy): per-step CSV and TrajNet++ ndjson",
        description="SOURCE is a results folder or a POLICY. A results folder (one run, an experiment, or a whole "
                    "results folder of `crowdnav benchmark` and `crowdnav evaluate`): each finished result's test episodes "
                    "are played again from what it scored (a module:function POLICY only when --import names it: no code a results "
                    "folder names runs otherwise; test episodes are deterministic; a replay whose outcomes differ "
                    "from the recorded ones is an error) and written to RUN/trajectories/evaluation_K (benchmark runs), "
                    "baseline or evaluate (.csv and .ndjson). A POLICY (any form `crowdnav evaluate` takes) plays the "
                    "--scenario's test episodes, written to OUT/<policy>__<scenario>__seeds<A>-<B>. Every respawned human "
                    "starts a new track (docs/evaluation.md#trajectories).",
    )
    traj.add_argument("source", metavar="SOURCE", help="a results folder, or a POLICY (run folder or checkpoint, SB3 .zip, "
                                                       "module:function, baseline:NAME)")
    traj.add_argument("--import", dest="imports", action="append", default=[], metavar="MODULE:FUNCTION",
                      help="results: a module:function POLICY a `crowdnav evaluate` result scored, to import again for its replay "
                           "(from the current folder or PYTHONPATH; it runs that code). Never imported otherwise: crowdnav runs "
                           "no code a results folder names (repeatable)")
    traj.add_argument("--evaluation", type=int, metavar="K", help="results: which evaluation of a benchmark run, 0-based (default: the last)")
    traj.add_argument("--scenario", metavar="NAME_OR_PATH", help="POLICY: library scenario name or YAML file (default: a crowdnav run's own)")
    traj.add_argument("--modalities", metavar="KEYS", help="POLICY: comma-separated observation keys (default: the scenario's)")
    traj.add_argument("--episodes", type=int, default=20, metavar="N", help="POLICY: test episodes (default: %(default)s)")
    traj.add_argument("--test-seed-base", type=int, default=0, metavar="S", help="POLICY: seed of the first test episode (default: %(default)s)")
    traj.add_argument("--out", default="trajectories", metavar="DIR", help="POLICY: output folder (default: %(default)s)")
    traj.add_argument("--force", action="store_true", help="POLICY: replace files of this name that hold other episodes (another "
                                                           "policy, --set or --modalities under the same name); same episodes are kept")
    add_override_option(traj)
    traj.set_defaults(handler=trajectories_command)


def trajectories_command(args: argparse.Namespace) -> int:
    from crowdnav.evaluation.storage import META_FILE
    from crowdnav.evaluation.trajectories import finished_results

    source = Path(args.source)
    results = finished_results(source) if source.is_dir() else []
    policy_options = [f"--{name.replace('_', '-')}" for name in ("scenario", "modalities") if getattr(args, name)]
    if results:
        if policy_options or args.overrides:
            raise CliError(f"{source} is a results folder: its results replay with their own settings "
                           f"({', '.join(policy_options or ['--override'])} is for a POLICY)")
        return _replay(results, args.evaluation, args.imports)
    if source.is_dir() and (source / META_FILE).is_file():
        raise CliError(f"{source}: an unfinished run (meta.json without a complete status or test_episodes.csv); finish it first")
    if args.evaluation is not None:
        raise CliError(f"--evaluation is for results folders; {args.source} is not one (no finished run in it)")
    if args.imports:
        raise CliError(f"--import is for results folders; {args.source} is not one (a POLICY given here is imported as named)")
    return _record(args)


def _replay(results: list[Path], evaluation: int | None, imports: list[str]) -> int:
    from crowdnav.evaluation.storage import META_FILE, ResultsError, read_json
    from crowdnav.evaluation.trajectories import ReplayMismatchError, replay_evaluation, result_label, write_trajectories
    from crowdnav.paths import OutputPathError, inside

    scored = {str(read_json(run / META_FILE).get("policy_source")) for run in results}
    unused = [name for name in imports if name not in scored]
    if unused:
        raise CliError(f"--import {unused[0]}: no result here scored it (a `crowdnav evaluate` result's POLICY, as its meta.json names it)")
    for run in results:
        try:
            # inside the run folder for real: a planted trajectories/ symlink must not send the files elsewhere
            stem = inside(run, f"trajectories/{result_label(run, evaluation)}")
            episodes = replay_evaluation(run, evaluation, imports=imports)
        except (ResultsError, ReplayMismatchError, OutputPathError) as error:
            raise CliError(str(error)) from None
        for path in write_trajectories(episodes, stem):
            print(f"wrote {path}")
    return 0


def _record(args: argparse.Namespace) -> int:
    from crowdnav.evaluation.evaluate import PolicyError
    from crowdnav.evaluation.trajectories import record_policy, write_trajectories
    from crowdnav.scenario import ScenarioError

    if args.episodes < 1:
        raise CliError(f"--episodes must be at least 1, got {args.episodes}")
    from crowdnav.agents.training.seeding import check_test_seeds

    try:  # the held-out seeds evaluate plays: never a run's training seeds
        check_test_seeds(args.test_seed_base, args.episodes)
    except ValueError as error:
        raise CliError(f"--test-seed-base / --episodes: {error}") from None
    modalities = [key.strip() for key in args.modalities.split(",") if key.strip()] if args.modalities else None
    try:
        episodes = record_policy(args.source, args.scenario, modalities=modalities, episodes=args.episodes,
                                 test_seed_base=args.test_seed_base, overrides=parse_overrides(args.overrides))
    except (PolicyError, ScenarioError, ValueError) as error:
        raise CliError(str(error).splitlines()[0]) from None
    last = args.test_seed_base + args.episodes - 1
    scenario = f"__{_name(Path(args.scenario).stem)}" if args.scenario else ""  # none: a crowdnav run's own scenario
    stem = Path(args.out) / f"{_name(args.source)}{scenario}__seeds{args.test_seed_base}-{last}"
    targets = [stem.with_name(stem.name + suffix) for suffix in (".csv", ".ndjson")]
    if any(path.exists() for path in targets) and not args.force:
        # the name carries neither --set nor --modalities: never replace other episodes silently
        incoming = write_trajectories(episodes, stem.with_name(stem.name + ".incoming"))
        same = all(old.is_file() and old.read_bytes() == new.read_bytes() for old, new in zip(targets, incoming, strict=True))
        for path in incoming:
            path.unlink()
        if not same:
            raise CliError(f"{targets[0]} exists with other episodes (another policy, --set or --modalities under this name); "
                           "--force replaces it, or write to another --out")
        for path in targets:
            print(f"kept {path} (the same episodes)")
        return 0
    for path in write_trajectories(episodes, stem):
        print(f"wrote {path}")
    return 0


def _name(text: str) -> str:
    """A file-name-safe form of a POLICY or scenario (``runs/sac`` -> ``runs_sac``)."""
    text = text.removesuffix(".zip").rstrip("/")
    return re.sub(r"[^A-Za-z0-9_.-]", "_", text).strip("._-")[:80] or "policy"
