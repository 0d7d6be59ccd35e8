"""``crowdnav benchmark``, ``crowdnav plot`` and ``crowdnav leaderboard``: the evaluation protocol and its report."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from crowdnav.cli.common import CliError, add_override_option, parse_overrides


def _shipped() -> list[str]:
    """The shipped experiments' names, read from the package's folder (without importing the evaluation layer)."""
    from importlib.resources import files

    return sorted(entry.name[: -len(".yaml")] for entry in files("crowdnav.evaluation").joinpath("experiments").iterdir()
                  if entry.name.endswith(".yaml"))


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``benchmark``, ``plot`` and ``leaderboard``."""
    parser = subparsers.add_parser(
        "benchmark", help="train and evaluate every configuration x seed of an experiment (resumable)",
        description="Run an experiment (the paper's protocol: evaluate on held-out test episodes every N training "
                    "episodes) and write per-episode results, learning curves, a leaderboard and a video of the "
                    "best final policy to OUT/<experiment>. Re-running skips finished runs and resumes the others.",
    )
    parser.add_argument("experiment", nargs="?", metavar="EXPERIMENT.yaml",
                        help=f"experiment file, or the name of a shipped one ({', '.join(_shipped())}); "
                             "default: the main job (default)")
    parser.add_argument("--out", default="results", metavar="DIR", help="results folder (default: results/)")
    parser.add_argument("--seeds", type=int, metavar="N", help="runs per configuration (default: the experiment's)")
    parser.add_argument("--workers", type=int, metavar="N",
                        help="parallel runs, one process (or Ray task) and one torch thread each (default: min(2, cores); "
                             "with --executor ray --address: as many as the cluster's CPUs allow)")
    parser.add_argument("--executor", choices=("local", "serial", "ray"), default="local",
                        help="where the runs happen: local (default): a pool of --workers processes; serial: one after the "
                             "other in this process (debugging); ray: one Ray task per run (pip install 'crowdnav[ray]'; "
                             "see docs/cluster.md)")
    parser.add_argument("--address", metavar="HOST:PORT",
                        help="ray: join the Ray cluster whose head is at HOST:PORT (default: start a local Ray)")
    parser.add_argument("--storage", metavar="DIR",
                        help="ray: where the tasks run and keep their checkpoints for resuming, a folder every node sees "
                             "(default: the --out folder; a node that does not see it uses its temp folder)")
    parser.add_argument("--gpus-per-run", type=float, metavar="G",
                        help="ray: GPUs each run reserves, fractions allowed (default: 0)")
    parser.add_argument("--retries", type=int, metavar="N",
                        help="ray: times a run whose worker died is started again (default: 3)")
    parser.add_argument("--quick", action="store_true",
                        help="smoke run: 20 training episodes, evaluations every 10 on 5 test episodes, 1 seed; "
                             "written to OUT/<experiment>-quick")
    parser.add_argument("--no-video", action="store_true", help="do not render the video of the final policy")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    parser.set_defaults(handler=benchmark)

    plot = subparsers.add_parser(
        "plot", help="draw the success / collision / out_of_bounds / truncated curves of a results folder",
        description="One figure per experiment (PNG and PDF): the rates along training, mean over seeds and a band "
                    "(clipped to [0, 1]) of a sliding window of test episodes. Written next to experiment.yaml unless --out is given.",
    )
    plot.add_argument("results", metavar="RESULTS_DIR", help="a folder written by `crowdnav benchmark`")
    plot.add_argument("--out", metavar="PATH", help="output path without extension (one experiment only)")
    plot.add_argument("--band", choices=["std", "ci"], default="std",
                      help="band around the mean over seeds: one standard deviation (the paper's style) or the 95%% bootstrap CI "
                           "of the mean (default: %(default)s)")
    plot.set_defaults(handler=plot_command)

    board = subparsers.add_parser(
        "leaderboard", help="rank the configurations of results folders (markdown and CSV)",
        description="One row per configuration: final rates, IQM of final success with a bootstrap CI, area under "
                    "the success curve, social metrics, env steps and wall time. The same results give the same files.",
    )
    board.add_argument("results", nargs="+", metavar="RESULTS_DIR", help="folders written by `crowdnav benchmark`")
    board.add_argument("--out", metavar="PATH", help="output path without extension (default: RESULTS_DIR/leaderboard, first folder)")
    board.set_defaults(handler=leaderboard_command)

    evaluate = subparsers.add_parser(
        "evaluate", help="evaluate any policy on a scenario's fixed test episodes, ranked by `crowdnav leaderboard`",
        description="POLICY: a crowdnav run folder or checkpoint, an SB3 model .zip, module:function (one observation dict "
                    "-> 2 numbers), or baseline:straight / baseline:social_force. Plays the test episodes with seeds "
                    "--test-seed-base, +1, ... and writes OUT/evaluate/<name>--<scenario>/seeds_<first>-<last>/ in the "
                    "protocol's format (docs/evaluate.md); existing results are kept unless --force.",
    )
    evaluate.add_argument("policy", metavar="POLICY")
    evaluate.add_argument("--scenario", required=True, metavar="NAME_OR_PATH", help="library scenario name or YAML file")
    evaluate.add_argument("--modalities", metavar="KEYS", help="comma-separated observation keys (default: the scenario's)")
    evaluate.add_argument("--episodes", type=int, default=20, metavar="N", help="test episodes (default: %(default)s; 500 for final rankings)")
    evaluate.add_argument("--test-seed-base", type=int, default=0, metavar="S", help="seed of the first test episode (default: %(default)s)")
    evaluate.add_argument("--name", metavar="NAME", help="configuration name in the results (default: from POLICY)")
    evaluate.add_argument("--out", default="results", metavar="DIR", help="results folder (default: %(default)s)")
    evaluate.add_argument("--force", action="store_true", help="replace this policy's results on this scenario and test set")
    evaluate.add_argument("--traceback", action="store_true", help="show the full traceback when the policy raises")
    evaluate.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    add_override_option(evaluate)
    evaluate.set_defaults(handler=evaluate_command)


def benchmark(args: argparse.Namespace) -> int:
    from crowdnav.evaluation.executors import ExecutorError, make_executor
    from crowdnav.evaluation.experiment import ExperimentError, load_experiment
    from crowdnav.evaluation.storage import ResultsError

    for option in ("workers", "retries", "gpus_per_run"):
        value, least = getattr(args, option), 0 if option != "workers" else 1
        if value is not None and value < least:
            raise CliError(f"--{option.replace('_', '-')} must be at least {least}, got {value:g}")
    ray_options = [f"--{name.replace('_', '-')}" for name in ("address", "storage", "gpus_per_run", "retries")
                   if getattr(args, name) is not None]
    if ray_options and args.executor != "ray":
        raise CliError(f"{', '.join(ray_options)}: option(s) of --executor ray, not of --executor {args.executor}")
    workers = args.workers
    if workers is None and not (args.executor == "ray" and args.address):
        workers = min(2, os.cpu_count() or 1)
    try:
        executor = make_executor(args.executor, workers=workers, address=args.address, storage=args.storage,
                                 gpus_per_run=args.gpus_per_run, retries=args.retries)
    except ExecutorError as error:
        raise CliError(str(error)) from None
    if args.seeds is not None and args.seeds < 1:
        raise CliError(f"--seeds must be at least 1, got {args.seeds}")
    try:
        experiment = load_experiment(args.experiment)
    except ExperimentError as error:
        raise CliError(str(error)) from None
    experiment = experiment.with_options(seeds=args.seeds, quick_protocol=args.quick)
    if args.quick:
        from dataclasses import replace

        experiment = replace(experiment, name=f"{experiment.name}-quick")
    from crowdnav.evaluation.benchmark import run_experiment
    from crowdnav.evaluation.storage import experiment_folder

    protocol = experiment.protocol
    print(f"experiment {experiment.name}: {len(experiment.configurations)} configurations x {protocol.seeds} seeds, "
          f"{protocol.describe_budget()} of training, {protocol.evaluations} evaluations of {protocol.test_episodes} "
          f"test episodes; executor {executor.describe()}", flush=True)
    from crowdnav.cli.signals import interrupt_on_sigterm

    # SIGTERM (kill, timeout, a cluster's preemption) stops the sweep as Ctrl-C does, its workers included
    with interrupt_on_sigterm(children=True) as stopped:
        try:
            report = run_experiment(experiment, args.out, executor=executor, progress=not args.no_progress,
                                    video=not args.no_video, log=lambda line: print(line, flush=True))
        except (ResultsError, ExperimentError, ExecutorError) as error:
            raise CliError(str(error)) from None
        except KeyboardInterrupt:
            print(f"crowdnav: interrupted; run the same command again to resume from {experiment_folder(args.out, experiment.name)}",
                  file=sys.stderr)
            return stopped.exit_status
    for line in report.summary_lines():
        print(line)
    for path in report.outputs:
        print(f"wrote {path}")
    print(f"results: {report.folder}")
    if report.failures:
        print(f"crowdnav: error: {len(report.failures)} run(s) failed; run the same command again to resume them", file=sys.stderr)
        return 1
    return 0


def plot_command(args: argparse.Namespace) -> int:
    from crowdnav.evaluation.curves import plot_curves
    from crowdnav.evaluation.storage import ResultsError

    try:
        paths = plot_curves([Path(args.results)], args.out, band=args.band)
    except ResultsError as error:
        raise CliError(str(error)) from None
    for path in paths:
        print(f"wrote {path}")
    return 0


def leaderboard_command(args: argparse.Namespace) -> int:
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


def evaluate_command(args: argparse.Namespace) -> int:
    from crowdnav.agents.run_folder import RunBusyError
    from crowdnav.evaluation.evaluate import PolicyError, ResultsExistError, evaluate_policy
    from crowdnav.scenario import ScenarioError

    modalities = [key.strip() for key in args.modalities.split(",") if key.strip()] if args.modalities else None
    if args.episodes < 1:
        raise CliError(f"--episodes must be at least 1, got {args.episodes}")
    from crowdnav.agents.seeding import check_test_seeds

    try:
        check_test_seeds(args.test_seed_base, args.episodes)
    except ValueError as error:
        raise CliError(f"--test-seed-base / --episodes: {error}") from None
    from crowdnav.cli.signals import interrupt_on_sigterm

    with interrupt_on_sigterm() as stopped:  # SIGTERM stops it as Ctrl-C does: one line, nothing half-written
        try:
            folder = evaluate_policy(args.policy, args.scenario, args.out, modalities=modalities, episodes=args.episodes,
                                     test_seed_base=args.test_seed_base, overrides=parse_overrides(args.overrides), name=args.name,
                                     force=args.force, progress=not args.no_progress)
        except PolicyError as error:
            if args.traceback and error.__cause__ is not None:
                import traceback

                traceback.print_exception(error.__cause__)
            raise CliError(str(error).splitlines()[0]) from None
        except (ResultsExistError, RunBusyError, ScenarioError, ValueError) as error:
            raise CliError(str(error).splitlines()[0]) from None
        except KeyboardInterrupt:
            print("crowdnav: interrupted before the results were written; run the same command again", file=sys.stderr)
            return stopped.exit_status
    from crowdnav.evaluation.storage import META_FILE, read_json

    final = read_json(folder / META_FILE)["final"]
    print(f"{args.policy}: " + ", ".join(f"{outcome} {rate:.0%}" for outcome, rate in final.items()) + f" on {args.episodes} test episodes")
    print(f"wrote {folder}; rank with: crowdnav leaderboard {args.out}")
    return 0
