"""``crowdnav benchmark`` and ``crowdnav plot``: the evaluation protocol and its curves (``leaderboard`` and ``evaluate``: leaderboard.py)."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from crowdnav.cli.common import CliError


def _shipped() -> list[str]:
    """The shipped experiments' names, read from the package's folder (without importing the evaluation layer)."""
    from importlib.resources import files

    return sorted(entry.name[: -len(".yaml")] for entry in files("crowdnav.evaluation").joinpath("experiments").iterdir()
                  if entry.name.endswith(".yaml"))


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``benchmark`` and ``plot``."""
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
                             "other in this process (debugging); ray: one Ray task per run (pip install -e \".[ray]\" in crowdnav's clone; "
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
