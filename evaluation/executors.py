"""Executors: where the runs of a benchmark happen.

Every executor takes the list of :class:`Job` s (one per (configuration, seed) run) and yields
one outcome per job as the runs finish, in any order:

* ``serial``: one run after the other in this process (for debugging: breakpoints, tracebacks);
* ``local`` (the default): a pool of ``workers`` spawned processes on this machine;
* ``ray``: one Ray task per run, on a local Ray or an existing cluster
  (:mod:`crowdnav.evaluation.ray_executor`, needs the ray extra, ``pip install -e ".[ray]"``).

An outcome is :func:`crowdnav.evaluation.runner.run_unit`'s summary (``status`` ``"done"`` or
``"skipped"``) or a failure record (``status`` ``"failed"``, ``error``: one line, ``log``: the
traceback's file). Both carry ``attempts``: how many times this sweep started the run (0 when it
was finished before; more than 1 when the Ray executor retried it after its worker died).
A failing run never stops the others. The jobs, the executor interface and the guarded run
live in :mod:`crowdnav.evaluation.jobs`, which the Ray executor shares.
"""

from __future__ import annotations

import os
import signal
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from pathlib import Path
from typing import Any

from crowdnav.evaluation.jobs import (  # Executor, ExecutorError, Job and run_name are re-exported for callers of this module
    Executor,
    ExecutorError,
    Job,
    failure_record,
    on_interrupt,
    run_guarded,
    run_name,
)

from crowdnav.errors import install_line

__all__ = ["EXECUTORS", "Executor", "ExecutorError", "Job", "LocalExecutor", "SerialExecutor", "make_executor", "run_name"]

EXECUTORS = ("local", "serial", "ray")
"""Names accepted by :func:`make_executor` (and ``crowdnav benchmark --executor``)."""


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
        pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=get_context("spawn"), initializer=_init_worker,
                                   initargs=(os.getpid(),))
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
    (see :class:`crowdnav.evaluation.ray_executor.RayExecutor`); giving them to another executor is an error.
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
        raise ExecutorError(f"the ray executor needs Ray, which is not installed: {install_line('ray')}") from None
    return RayExecutor(workers=workers, address=address, storage=storage, gpus_per_run=gpus_per_run or 0.0,
                       retries=3 if retries is None else retries)


def _init_worker(parent: int | None = None) -> None:
    """One torch thread per worker (the pool already uses every core); remember a Ctrl-C; die with the parent.

    A worker outliving a killed sweep would go on writing its run while the next sweep resumes
    it; on Linux the kernel now kills the worker when the sweep's process dies (and a run folder's
    writer lock refuses a second writer everywhere).
    """
    if parent is not None:
        _die_with_parent(parent)
    os.environ["OMP_NUM_THREADS"] = "1"
    import torch

    torch.set_num_threads(1)
    signal.signal(signal.SIGINT, on_interrupt)


PR_SET_PDEATHSIG = 1
"""Linux prctl options: the signal a process gets when its parent dies, and reading it back."""


def _die_with_parent(parent: int) -> None:
    """Ask Linux to SIGKILL this process when its parent dies (elsewhere: nothing, the writer lock still guards runs)."""
    import ctypes
    import sys

    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):  # no prctl in this libc: the writer lock still guards runs
        return
    if os.getppid() != parent:  # the parent died before the request took effect
        os._exit(1)
