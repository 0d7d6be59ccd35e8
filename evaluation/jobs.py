"""Jobs and what every executor shares: one run per job, guarded so that a failing run never stops the others.

:mod:`crowdnav.evaluation.executors` (serial, local process pool, :func:`make_executor`) and
:mod:`crowdnav.evaluation.ray_executor` (one Ray task per run) both build on this module, so neither
imports the other at module level except the factory's lazy import of Ray's.
"""

from __future__ import annotations

import traceback
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from crowdnav.evaluation.progress import episodes_on_disk
from crowdnav.evaluation.protocol import Protocol
from crowdnav.evaluation.runner import OUTCOMES, run_unit
from crowdnav.evaluation.storage import run_name as storage_run_name

from crowdnav.errors import CrowdNavError


class ExecutorError(CrowdNavError, ValueError):
    """An executor that cannot start: Ray missing, a cluster that cannot be reached, bad options."""


@dataclass(frozen=True)
class Job:
    """One run to carry out: its :class:`crowdnav.evaluation.runner.UnitSpec` as a dict, and its folder in the results."""

    spec: dict[str, Any]
    out_dir: str
    unit: Any = field(default=None, compare=False, repr=False)
    """The :class:`~crowdnav.evaluation.runner.UnitSpec` itself, carrying its validated TrainConfig (None: run_unit validates ``spec``)."""

    @property
    def name(self) -> str:
        return run_name(self.spec)

    @property
    def protocol(self) -> Protocol:
        return Protocol(**self.spec["protocol"])


def run_name(record: dict[str, Any]) -> str:
    """``configuration/seed_N``, as runs are named in messages (``record``: a run's spec or outcome)."""
    return storage_run_name(record["configuration"], record["seed"])


class Executor:
    """Runs jobs and yields their outcomes as they finish; subclasses implement :meth:`run`."""

    name = "executor"

    def run(self, jobs: Sequence[Job], *, verbose: bool = False) -> Iterator[dict[str, Any]]:
        """One outcome per job. ``verbose``: print a line after each evaluation (for logs, when there is no progress bar)."""
        raise NotImplementedError

    def episodes_done(self, job: Job) -> int:
        """Episodes (training and test) ``job`` has done so far, for the progress bar."""
        return episodes_on_disk(job.out_dir, job.protocol)

    def describe(self) -> str:
        """Where the runs go, for the first line of ``crowdnav benchmark``."""
        return self.name


_interrupted = False
"""Set in a worker by Ctrl-C: the runs already queued to it then return at once instead of starting."""


def on_interrupt(signum: int, frame: Any) -> None:
    global _interrupted
    _interrupted = True
    raise KeyboardInterrupt


def run_guarded(spec: dict[str, Any], out_dir: str, verbose: bool = False, unit: Any = None) -> dict[str, Any]:
    """:func:`run_unit` that returns a failure record (traceback in OUT/error.log) instead of raising.

    ``verbose``: print a line after each evaluation (for logs; not with a progress bar).
    """
    def report(event: str, data: dict[str, Any]) -> None:
        if verbose and event == "evaluated":
            print(describe_evaluation(spec, data), flush=True)

    if _interrupted:
        return failure_record(spec, out_dir, "not started: interrupted", None)
    try:
        summary = run_unit(unit if unit is not None else spec, out_dir, on_event=report)
    except Exception as error:  # one failed run must not stop the others
        return failure_record(spec, out_dir, one_line(error), write_error_log(out_dir, traceback.format_exc()), attempts=1)
    return {**summary, "attempts": 0 if summary["status"] == "skipped" else 1}


def describe_evaluation(spec: dict[str, Any], data: dict[str, Any]) -> str:
    """The line a verbose benchmark prints after an evaluation (run_unit's ``evaluated`` event)."""
    rates = ", ".join(f"{outcome} {data.get(outcome, 0.0):.0%}" for outcome in OUTCOMES)
    after = f"{data['training_steps']} env steps" if "training_steps" in data else f"{data['training_episodes']} episodes"
    return f"run {run_name(spec)}: evaluation {data['evaluation']} after {after}: {rates}"


def one_line(error: BaseException) -> str:
    return " ".join(f"{type(error).__name__}: {error}".split())


def write_error_log(out_dir: str | Path, text: str) -> Path:
    """The traceback of a failed run, in OUT/error.log."""
    log = Path(out_dir) / "error.log"
    from crowdnav.files import atomic_write_text

    return atomic_write_text(log, text)  # makes the folder; a link at OUT/error.log is replaced, never written through


def failure_record(spec: dict[str, Any], out_dir: str, message: str, log: Path | None, *, attempts: int = 0) -> dict[str, Any]:
    """The outcome of a run that failed: ``error`` is one line, ``log`` the traceback's file (or ``-``)."""
    return {"experiment": spec["experiment"], "configuration": spec["configuration"], "seed": spec["seed"],
            "status": "failed", "error": message, "log": str(log) if log else "-", "out": out_dir, "attempts": attempts}
