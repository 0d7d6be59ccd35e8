"""The ``crowdnav`` command line (also ``python -m crowdnav``).

Every command group lives in its own module of this package and exposes
``register(subparsers)``: it adds its parser and sets ``handler`` (``(args) -> int``) on
each leaf command. To add a group (train, render, benchmark, ...), write its module and
append its ``register`` to :func:`command_groups`. The CLI is the top floor: a handler imports
the layer it runs (the environment core, crowdnav.agents, crowdnav.evaluation) when it runs,
so that ``crowdnav --help`` and the scenario tools load neither torch nor pygame.
"""

from __future__ import annotations

import argparse
import errno
import importlib.util
import os
import sys
from collections.abc import Callable, Sequence

from crowdnav.cli import benchmark, export, leaderboard, render, scenario, schema, track, train, trajectories
from crowdnav.errors import CrowdNavError, install_line

# Packages that only an extra installs (pyproject.toml), so a command run on the core install
# names the extra to add instead of failing with a traceback.
EXTRA_OF_MODULE = {"torch": "train", "stable_baselines3": "train", "matplotlib": "train", "pandas": "bench", "seaborn": "bench", "ray": "ray",
                   "onnx": "onnx", "onnxruntime": "onnx", "scipy": "fit"}
EXTRA_OF_COMMAND = {"train": "train", "collect-dataset": "train", "pretrain-encoder": "train", "benchmark": "bench", "plot": "bench",
                    "leaderboard": "bench", "trajectories": "bench", "evaluate": "bench", "export": "onnx"}
# What each command's layer needs, checked before it starts: a benchmark's worker processes would
# otherwise each fail on the missing import, after the command had already begun.
NEEDS = {"train": ("torch", "stable_baselines3"), "collect-dataset": ("torch",), "pretrain-encoder": ("torch", "matplotlib"),
         "benchmark": ("torch", "stable_baselines3", "pandas", "seaborn", "matplotlib"), "plot": ("pandas", "seaborn", "matplotlib"),
         "trajectories": ("torch", "stable_baselines3", "pandas"), "export": ("torch", "stable_baselines3", "onnx")}
# `evaluate` and `leaderboard` check on their own path: scripted policies evaluate and rank a track in the core install
# (+ orca for baseline:orca), a learned policy loads torch when it loads, a benchmark leaderboard reads pandas.


def _require(modules: Sequence[str]) -> None:
    """ModuleNotFoundError for the first of ``modules`` that is not installed (found without importing it)."""
    for module in modules:
        if importlib.util.find_spec(module) is None:
            raise ModuleNotFoundError(f"No module named {module!r}", name=module)


def command_groups() -> tuple[Callable[[argparse._SubParsersAction[argparse.ArgumentParser]], None], ...]:
    """Registration functions of the command groups, in the order ``--help`` lists them."""
    return (scenario.register, train.register, render.register, benchmark.register, leaderboard.register, track.register,
            trajectories.register, export.register, schema.register)


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with every command group registered."""
    from crowdnav import __version__

    parser = argparse.ArgumentParser(
        prog="crowdnav", description="Train and benchmark robots navigating among people."
    )
    parser.add_argument("--version", action="version", version=f"crowdnav {__version__}")
    groups = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for register in command_groups():
        register(groups)
    return parser


_FILE_SYSTEM_ERRORS = {errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOTDIR, errno.EISDIR, errno.EEXIST, errno.ENOSPC, errno.EDQUOT,
                       errno.ENAMETOOLONG}
"""Errors of the output location rather than of crowdnav: reported in one line by every command."""


def one_line(error: BaseException) -> str:
    """``str(error)`` on one line: a report of several lines (a scenario's issues) joined with '; '."""
    return "; ".join(line.strip() for line in str(error).splitlines() if line.strip()) or type(error).__name__


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status (0 ok, 1 failure, 2 usage error)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # --help, --version and usage errors
        return exit_.code if isinstance(exit_.code, int) else 0 if exit_.code is None else 2
    try:
        _require(NEEDS.get(args.command, ()))
        status: int = args.handler(args)  # every leaf command sets a handler (args) -> int
        return status
    except CrowdNavError as error:  # CliError, and whatever crowdnav raises on purpose that a command let through: one line
        print(f"crowdnav: error: {one_line(error)}", file=sys.stderr)
        return 1
    except ModuleNotFoundError as error:
        extra = EXTRA_OF_MODULE.get((error.name or "").split(".")[0])
        if extra is None:
            raise
        if extra != "ray":  # benchmark needs bench even where torch is the first thing missing
            extra = EXTRA_OF_COMMAND.get(args.command, extra)
        print(f"crowdnav: error: `crowdnav {args.command}` needs {error.name}, which the core install leaves out: "
              f"{install_line(extra)}", file=sys.stderr)
        return 1
    except BrokenPipeError:  # output piped into `head` and the like, which stopped reading
        # Python flushes stdout again at exit; send that flush to devnull so it cannot fail too.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except OSError as error:  # the file system said no (read-only, a file where a folder goes, full disk): one line
        if error.errno not in _FILE_SYSTEM_ERRORS:
            raise
        where = f" {error.filename}" if error.filename else ""
        print(f"crowdnav: error: cannot write{where}: {error.strerror or error}; choose another --out or free the path",
              file=sys.stderr)
        return 1
