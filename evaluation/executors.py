"""Executors: where the runs of a benchmark happen.

Every executor takes the list of :class:`Job` s (one per (configuration, seed) run) and yields
one outcome per job as the runs finish, in any order:

* ``serial``: one run after the other in this process (for debugging: breakpoints, tracebacks);
* ``local`` (the default): a pool of ``workers`` spawned processes on this machine;
* ``ray``: one Ray task per run, on a local Ray or an existing cluster
  (:mod:`evaluation.ray_executor`, needs ``pip install "crowdnav[ray]"``).

An outcome is :func:`evaluation.runner.run_unit`'s summary (``status`` ``"done"`` or
``"skipped"``) or a failure record (``status`` ``"failed"``, ``error``: one line, ``log``: the
traceback's file). Both carry ``attempts``: how many times this sweep started the run (0 when it
was finished before; more than 1 when the Ray executor retried it after its worker died).
A failing run never stops the others.
"""

from __future__ import annotations

import os
import signal
import traceback
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import Any

from crowdnav.evaluation.progress import episodes_on_disk
from crowdnav.evaluation.protocol import Protocol
from crowdnav.evaluation.runner import OUTCOMES, run_unit

EXECUTORS = ("local", "serial", "ray")
"""Names accepted by :func:`make_executor` (and ``crowdnav benchmark --executor``)."""


class ExecutorError(ValueError):
    """An executor that cannot start: Ray missing, a cluster that cannot be reached, bad options."""


@dataclass(frozen=True)
class Job:
    """One run to carry out: its :class:`evaluation.runner.UnitSpec` as a dict, and its folder in the results."""

    spec: dict[str, Any]
    out_dir: str
    unit: Any = field(default=None, compare=False, repr=False)
    """The :class:`~evaluation.runner.UnitSpec` itself, carrying its validated TrainConfig (None: run_unit validates ``spec``)."""

    @property
    def name(self) -> str:
        return run_name(self.spec)

    @property
    def protocol(self) -> Protocol:
        return Protocol(**self.spec["protocol"])


def run_name(record: dict[str, Any]) -> str:
    """``configuration/seed_N``, as runs are named in messages (``record``: a run's spec or outcome)."""
    return f"{record['configuration']}/seed_{record['seed']}"


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
        """Where the runs go, for the benchmark's first line."""
        return self.name


class SerialExecutor(Executor):
    """The runs one after the other, in this process."""

    name = "serial"

    def run(self, jobs: Sequence[Job], *, verbose: bool = False) -> Iterator[dict[str, Any]]:
        for job in jobs:
            yield run_guarded(job.spec, job.out_dir, verbose, job.unit)


class LocalExecutor(Executor):
    """A pool of ``workers`` spawned processes, one torch thread each."""

    name = "local"

    def __init__(self, workers: int):
        if workers < 1:
            raise ExecutorError(f"workers must be at least 1, got {workers}")
        self.workers = workers

    def describe(self) -> str:
        return f"local, {self.workers} worker process(es)"

    def run(self, jobs: Sequence[Job], *, verbose: bool = False) -> Iterator[dict[str, Any]]:
        pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=get_context("spawn"), initializer=_init_worker)
        try:
            futures = {pool.submit(run_guarded, job.spec, job.out_dir, verbose, job.unit): job for job in jobs}
            for future in as_completed(futures):
                try:
                    yield future.result()
                except Exception as error:  # the worker process died (killed, out of memory): the others go on
                    job = futures[future]
                    yield failure_record(job.spec, job.out_dir, f"worker process died: {type(error).__name__}: {error}", None)
        finally:  # on Ctrl-C, do not start the queued runs (the running ones stop with it and resume next time)
            pool.shutdown(wait=True, cancel_futures=True)


def make_executor(kind: str = "local", *, workers: int | None = None, address: str | None = None, storage: str | Path | None = None,
                  gpus_per_run: float | None = None, retries: int | None = None) -> Executor:
    """The executor called ``kind`` (see :data:`EXECUTORS`).

    ``workers``: parallel runs (local: processes, default 1; ray: at most this many runs at a
    time, default: as many as the cluster's CPUs allow). ``address``, ``storage``,
    ``gpus_per_run`` (default 0) and ``retries`` (default 3) are the Ray executor's
    (see :class:`evaluation.ray_executor.RayExecutor`); giving them to another executor is an error.
    """
    if kind not in EXECUTORS:
        raise ExecutorError(f"unknown executor {kind!r} (expected one of: {', '.join(EXECUTORS)})")
    if kind != "ray":
        given = [name for name, value in (("address", address), ("storage", storage), ("gpus_per_run", gpus_per_run),
                                          ("retries", retries)) if value is not None]
        if given:
            raise ExecutorError(f"{', '.join(given)}: option(s) of the ray executor only, not of the {kind} executor")
    if kind == "serial":
        return SerialExecutor()
    if kind == "local":
        return LocalExecutor(min(2, os.cpu_count() or 1) if workers is None else workers)
    try:
        from crowdnav.evaluation.ray_executor import RayExecutor
    except ImportError as error:
        if error.name is None or error.name.split(".")[0] != "ray":
            raise
        raise ExecutorError("the ray executor needs Ray, which is not installed: pip install 'crowdnav[ray]'") from None
    return RayExecutor(workers=workers, address=address, storage=storage, gpus_per_run=gpus_per_run or 0.0,
                       retries=3 if retries is None else retries)


_interrupted = False
"""Set in a worker by Ctrl-C: the runs already queued to it then return at once instead of starting."""


def _init_worker() -> None:
    """One torch thread per worker (the pool already uses every core); remember a Ctrl-C."""
    os.environ["OMP_NUM_THREADS"] = "1"
    import torch

    torch.set_num_threads(1)
    signal.signal(signal.SIGINT, _on_interrupt)


def _on_interrupt(signum: int, frame: Any) -> None:
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
    return f"run {run_name(spec)}: evaluation {data['evaluation']} after {data['training_episodes']} episodes: {rates}"


def one_line(error: BaseException) -> str:
    return " ".join(f"{type(error).__name__}: {error}".split())


def write_error_log(out_dir: str | Path, text: str) -> Path:
    """The traceback of a failed run, in OUT/error.log."""
    log = Path(out_dir) / "error.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    log.write_text(text, encoding="utf-8")
    return log


def failure_record(spec: dict[str, Any], out_dir: str, message: str, log: Path | None, *, attempts: int = 0) -> dict[str, Any]:
    """The outcome of a run that failed: ``error`` is one line, ``log`` the traceback's file (or ``-``)."""
    return {"experiment": spec["experiment"], "configuration": spec["configuration"], "seed": spec["seed"],
            "status": "failed", "error": message, "log": str(log) if log else "-", "out": out_dir, "attempts": attempts}
