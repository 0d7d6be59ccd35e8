"""The Ray executor: every (configuration, seed) run is one Ray task, on a local Ray or an existing cluster.

This is the only module that imports Ray (the ray extra: ``pip install -e ".[ray]"``); the rest of crowdnav
never does. Without ``address`` it starts a local Ray (``workers`` CPUs, default: all cores);
with one (``HOST:PORT`` of a head started by ``ray start --head``) it joins that cluster.
crowdnav must be importable by the cluster's workers (installed on every node).

* A task declares ``num_cpus=1`` and ``gpus_per_run`` GPUs, runs with one torch thread, and does
  :func:`crowdnav.evaluation.runner.run_unit` in its working folder under the storage root
  (:mod:`crowdnav.evaluation.transfer`; default root: the results folder, so on a local Ray or a shared
  file system the run writes straight into the results). A run done elsewhere comes back as
  bytes that the driver unpacks into the results: the results never rely on a shared file system.
  Such a run arrives without its replay buffer (train/checkpoint/replay_buffer.npz), which only
  serves to resume training and can weigh hundreds of MB; everything else is as a local run's.
* A task whose worker dies (killed, out of memory, node lost) is retried up to ``retries``
  times by Ray and resumes from its last checkpoint when it can reach it. A run that raises is
  not retried: it comes back as a failure record, its traceback in ``<run>/error.log``.
* Finished runs in the results are skipped before anything is submitted.
* The tasks report their progress (episodes done, evaluations) and their attempts to a small
  actor; the driver reads it for the progress bar and to count retries.
"""

from __future__ import annotations

import os
import platform
import socket
import threading
import time
import traceback
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import ray
from crowdnav.evaluation.jobs import (
    Executor,
    ExecutorError,
    Job,
    describe_evaluation,
    failure_record,
    one_line,
    run_guarded,
    write_error_log,
)
from crowdnav.evaluation.progress import episodes_on_disk, run_episodes
from crowdnav.evaluation.protocol import Protocol
from crowdnav.evaluation.runner import PRETRAINED, run_unit
from crowdnav.evaluation.storage import (
    ENCODER_FILE,
    META_FILE,
    SPEC_FILE,
    TRAIN_DIR,
    ResultsError,
    encoder_folder,
    experiment_of,
    read_json,
    relative_run_path,
    results_root_of,
)
from crowdnav.evaluation.transfer import claim_storage, pack_folder, remove_work_folder, unpack_folder, work_folder
from crowdnav.evaluation.unit_spec import run_identity

THREADS_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
"""Environment of the tasks: one thread each (Ray already runs one task per CPU)."""
POLL_SECONDS = 0.5
"""How often the driver collects the tasks' progress, and a task reads its episode count."""


class RayExecutor(Executor):
    """Runs each job as a Ray task (see the module docstring)."""

    name = "ray"

    def __init__(self, *, workers: int | None = None, address: str | None = None, storage: str | Path | None = None,
                 gpus_per_run: float = 0.0, retries: int = 3):
        if workers is not None and workers < 1:
            raise ExecutorError(f"workers must be at least 1, got {workers}")
        if gpus_per_run < 0:
            raise ExecutorError(f"GPUs per run must be >= 0, got {gpus_per_run}")
        if retries < 0:
            raise ExecutorError(f"retries must be >= 0, got {retries}")
        self.workers, self.address, self.gpus_per_run, self.retries = workers, address, gpus_per_run, retries
        self.storage = Path(storage).resolve() if storage is not None else None
        self._episodes: dict[str, int] = {}
        self._attempts: dict[str, int] = {}

    def describe(self) -> str:
        where = f"Ray cluster at {self.address}" if self.address else f"local Ray with {self.workers or os.cpu_count()} CPUs"
        limit = f", at most {self.workers} runs at a time" if self.address and self.workers else ""
        return f"ray, {where}{limit}, {self.gpus_per_run:g} GPU(s) and 1 CPU per run, {self.retries} retries"

    def episodes_done(self, job: Job) -> int:
        return self._episodes.get(job.name, 0)

    def run(self, jobs: Sequence[Job], *, verbose: bool = False) -> Iterator[dict[str, Any]]:
        jobs = [Job(job.spec, str(Path(job.out_dir).resolve()), job.unit) for job in jobs]  # the tasks run in other folders
        todo = []
        for job in jobs:  # finished runs (and folders of other runs) are handled here, without a task
            if (Path(job.out_dir) / META_FILE).is_file() or _holds_other_run(job):
                outcome = {**run_guarded(job.spec, job.out_dir), "attempts": 0}
                self._episodes[job.name] = run_episodes(job.protocol) if outcome["status"] != "failed" else 0
                yield outcome
            else:
                todo.append(job)
        if not todo:
            return
        connected_here = self._connect()
        try:
            yield from self._run(todo, verbose)
        finally:
            if connected_here:
                ray.shutdown()

    def _connect(self) -> bool:
        """Join the cluster (or start a local Ray); False when this process was already connected."""
        if ray.is_initialized():
            return False
        options: dict[str, Any] = {"runtime_env": {"env_vars": THREADS_ENV}, "logging_level": "WARNING", "log_to_driver": False}
        if self.address:
            _check_reachable(self.address)
        try:
            if self.address:
                ray.init(address=self.address, **options)
            else:
                ray.init(address="local", num_cpus=self.workers, include_dashboard=False, **options)
        except (ConnectionError, RuntimeError, ValueError) as error:
            if not self.address:
                raise ExecutorError(f"cannot start a local Ray: {one_line(error)}") from None
            raise ExecutorError(f"cannot join the Ray cluster at {self.address}: {one_line(error)}; if the cluster uses token "
                                "authentication, give this process its token: RAY_AUTH_MODE=token and ~/.ray/auth_token or "
                                "RAY_AUTH_TOKEN (see docs/cluster.md)") from None
        return True

    def _run(self, jobs: list[Job], verbose: bool) -> Iterator[dict[str, Any]]:
        root = self.storage or results_root_of(jobs[0].out_dir)  # default: the results folder itself
        storage_id = claim_storage(root)
        # mypy ignores a class decorator's type: it sees _Board, not the ActorClass @ray.remote made of it
        board = _Board.options(num_cpus=0).remote()  # type: ignore[attr-defined]
        encoders = _encoder_files(jobs)
        resources = {"num_cpus": 1, "num_gpus": self.gpus_per_run, "max_retries": self.retries, "retry_exceptions": False}
        queue = list(jobs)
        pending: dict[ray.ObjectRef[dict[str, Any]], Job] = {}
        limit = self.workers if self.address and self.workers else len(jobs)
        try:
            while queue or pending:
                while queue and len(pending) < limit:
                    job = queue.pop(0)
                    ref = _run_task.options(name=f"crowdnav {job.name}", **resources).remote(
                        job.unit if job.unit is not None else job.spec, job.out_dir, str(root), storage_id,
                        encoders.get(_experiment_dir(job)), board)
                    pending[ref] = job
                ready, _ = ray.wait(list(pending), num_returns=1, timeout=POLL_SECONDS)
                self._read_board(board, verbose)
                for ref in ready:
                    job = pending.pop(ref)
                    outcome = self._collect(ref, job)
                    if outcome["status"] != "failed":
                        self._episodes[job.name] = run_episodes(job.protocol)
                    yield outcome
        finally:  # Ctrl-C or an error: stop the runs still going (they resume from their checkpoints next time)
            try:
                for ref in pending:
                    ray.cancel(ref, force=True)
                ray.kill(board)
            except ray.exceptions.RayError:  # the cluster is gone already
                pass

    def _read_board(self, board: Any, verbose: bool) -> None:
        try:
            episodes, attempts, events = ray.get(board.drain.remote())
        except ray.exceptions.RayError:  # the board is lost (its node died): the runs go on without progress reports
            return
        self._episodes.update(episodes)
        self._attempts.update(attempts)
        for spec, data in events if verbose else ():
            print(describe_evaluation(spec, data), flush=True)

    def _collect(self, ref: Any, job: Job) -> dict[str, Any]:
        """The outcome of a finished task, its run unpacked into the results when it was done elsewhere."""
        try:
            result = ray.get(ref)
        except ray.exceptions.RayTaskError as error:  # an error outside run_unit (storage, transfer): a bug, not retried
            log = write_error_log(job.out_dir, str(error))
            return failure_record(job.spec, job.out_dir, one_line(getattr(error, "cause", None) or error), log,
                                  attempts=self._attempts.get(job.name, 1))
        except ray.exceptions.RayError as error:  # the worker (or its node) died once more than the retries allow
            attempts = self._attempts.get(job.name, 0)
            log = write_error_log(job.out_dir, f"{type(error).__name__}: {error}\n")
            return failure_record(job.spec, job.out_dir, f"worker died ({attempts} attempt(s)): {one_line(error)}", log,
                                  attempts=attempts)
        files, work_dir, shared = result.pop("files"), Path(result.pop("work_dir")), result.pop("shared")
        tracebacks = result.pop("traceback", None)
        result["attempts"] = max(result["attempts"], self._attempts.get(job.name, 0))
        result["out"] = job.out_dir
        if result["status"] == "failed":
            if tracebacks is not None and work_dir != Path(job.out_dir):
                result["log"] = str(write_error_log(job.out_dir, tracebacks))
            return result
        if files is not None:
            try:
                unpack_folder(files, job.out_dir, META_FILE)
            except (OSError, ResultsError) as error:  # disk full, permissions: this run is lost to the results, not the others
                log = write_error_log(job.out_dir, traceback.format_exc())
                return failure_record(job.spec, job.out_dir, f"cannot move the finished run into the results: {one_line(error)}",
                                      log, attempts=result["attempts"])
            if shared:  # the working copy is in the storage the driver sees: no longer needed
                remove_work_folder(work_dir)
        return result


def _check_reachable(address: str, timeout: float = 10.0) -> None:
    """ExecutorError unless a ``HOST:PORT`` address accepts connections (ray.init would retry for minutes)."""
    host, _, port = address.rpartition(":")
    if "://" in address or not host or not port.isdigit():  # ray://, auto, ...: Ray's own checks
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as error:
        raise ExecutorError(f"cannot reach the Ray head at {address} ({error.strerror or error}); start it with "
                            "`ray start --head --port=PORT` and give --address HOST:PORT (see docs/cluster.md)") from None


def _holds_other_run(job: Job) -> bool:
    """Whether the job's results folder already belongs to another run (run_unit refuses it with a clear message)."""
    path = Path(job.out_dir) / SPEC_FILE
    try:
        return path.is_file() and run_identity(read_json(path)) != run_identity(job.spec)
    except ValueError:
        return True


def _experiment_dir(job: Job) -> str:
    return str(experiment_of(job.out_dir))


def _encoder_files(jobs: Sequence[Job]) -> dict[str, Any]:
    """Experiment folder -> object ref of its packed pre-trained encoder folder, for the runs that use it."""
    refs = {}
    for job in jobs:
        weights = job.spec["train"].get("encoder", {}).get("weights")
        folder = _experiment_dir(job)
        if weights == PRETRAINED and folder not in refs:
            refs[folder] = ray.put(pack_folder(encoder_folder(folder)))
    return refs


@ray.remote
class _Board:
    """Where the tasks report: episodes done and attempts per run, and evaluation events; the driver drains it."""

    def __init__(self) -> None:
        self.episodes: dict[str, int] = {}
        self.attempts: dict[str, int] = {}
        self.events: list[tuple[dict[str, Any], dict[str, Any]]] = []

    def started(self, name: str) -> int:
        """A task (or a retry of it) starts the run ``name``; returns its attempt number."""
        self.attempts[name] = self.attempts.get(name, 0) + 1
        return self.attempts[name]

    def progress(self, name: str, episodes: int) -> None:
        self.episodes[name] = episodes

    def evaluated(self, spec: dict[str, Any], data: dict[str, Any]) -> None:
        self.events.append((spec, data))

    def drain(self) -> tuple[dict[str, int], dict[str, int], list[tuple[dict[str, Any], dict[str, Any]]]]:
        events, self.events = self.events, []
        return dict(self.episodes), dict(self.attempts), events

    def alive(self) -> bool:
        """The tasks' heartbeat: the board lives as long as the driver that created it."""
        return True


@ray.remote
def _run_task(unit: Any, out_dir: str, storage: str, storage_id: str, encoder: bytes | None, board: Any) -> dict[str, Any]:
    """One run in its working folder; returns the summary (or failure record), with the run packed when it lies elsewhere.

    ``unit``: the validated UnitSpec (its TrainConfig travels with it: not validated again on the
    worker), or its dict.
    """
    import torch

    torch.set_num_threads(1)
    spec = unit if isinstance(unit, dict) else unit.to_dict()
    job = Job(spec, out_dir)
    name = job.name
    try:
        attempt = ray.get(board.started.remote(name))
    except ray.exceptions.RayError:  # the board is lost: the run matters more than its attempt count
        attempt = 0
    work_dir, shared = work_folder(storage, storage_id, relative_run_path(out_dir))
    if encoder is not None:
        unpack_folder(encoder, encoder_folder(experiment_of(work_dir)), ENCODER_FILE)
    reporter = _ProgressReporter(board, name, work_dir, job.protocol, on_driver_lost=_exit_with_driver)

    def on_event(event: str, data: dict[str, Any]) -> None:
        if event == "evaluated":
            board.evaluated.remote(spec, data)

    base = {"attempts": attempt, "work_dir": str(work_dir), "shared": shared, "files": None, "node": platform.node()}
    try:
        summary = run_unit(unit, work_dir, on_event=on_event)
    except Exception as error:  # a bug or bad input: reported, not retried (retrying would fail the same way)
        text = traceback.format_exc()
        log = write_error_log(work_dir, text)
        return {**failure_record(spec, str(work_dir), one_line(error), log, attempts=attempt), **base, "traceback": text}
    finally:
        reporter.stop()
    if work_dir != Path(out_dir):
        from crowdnav.agents.runs.folder import replay_buffer_file
        from crowdnav.agents.runs.resume_state import REPLAY_ARRAYS

        # The replay buffer only serves to resume training, which a finished run never does, and can weigh hundreds of MB
        # (replay_buffer.npz; replay_buffer.pkl from an older crowdnav).
        old = replay_buffer_file(TRAIN_DIR)
        base["files"] = pack_folder(work_dir, skip=(old.as_posix(), (old.parent / REPLAY_ARRAYS).as_posix()))
        if not shared:  # a node-local copy: nobody else can reach it, and the driver now gets the run
            remove_work_folder(work_dir)
    return {**summary, **base}


DRIVER_CHECK_SECONDS = 2.0
"""How often a task asks whether its driver (through the board actor) still lives."""


def _exit_with_driver() -> None:
    """The driver is gone (killed, preempted): stop this task now, as a kill would; its checkpoint resumes it later.

    Ray itself reaps a dead job's tasks only after its health checks time out (about 90 s
    measured), training all the while for nobody and holding the CPUs.
    """
    os._exit(75)


class _ProgressReporter:
    """A thread of the task that sends the run's episode count to the board whenever it changes, and
    calls ``on_driver_lost`` once the board (which dies with the driver) is gone."""

    def __init__(self, board: Any, name: str, folder: Path, protocol: Protocol, on_driver_lost: Any = None):
        self.board, self.name, self.folder, self.protocol = board, name, folder, protocol
        self.on_driver_lost = on_driver_lost
        self._checked = time.monotonic()
        self.last = -1
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def _send(self) -> None:
        try:
            episodes = episodes_on_disk(self.folder, self.protocol)
        except (OSError, ValueError):  # a file being replaced while read: next time
            return
        if episodes != self.last:
            self.board.progress.remote(self.name, episodes)
            self.last = episodes

    def _loop(self) -> None:
        while not self._stop.wait(POLL_SECONDS):
            self._send()
            if self.on_driver_lost is not None and time.monotonic() - self._checked >= DRIVER_CHECK_SECONDS:
                self._checked = time.monotonic()
                if not self.driver_alive():
                    self.on_driver_lost()

    def driver_alive(self) -> bool:
        """False only when the board actor is dead (its driver gone); a slow answer is not a death."""
        try:
            ray.get(self.board.alive.remote(), timeout=DRIVER_CHECK_SECONDS)
        except ray.exceptions.RayActorError:
            return False
        except ray.exceptions.GetTimeoutError:
            return True
        return True

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()
        self._send()

