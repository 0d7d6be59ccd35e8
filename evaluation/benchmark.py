"""Run a whole experiment: every (configuration, seed) unit in a local process pool, then the report.

``run_experiment`` writes into ``RESULTS/<experiment name>/``: experiment.yaml (the resolved
experiment; a folder holding another experiment's results is refused), the pre-trained
encoder if the experiment needs one, one folder per run (see :mod:`evaluation.storage`),
and, once runs have finished, the curves (curves.png/.pdf), the leaderboard
(leaderboard.md/.csv) and a video of the best configuration's final policy (videos/).

Each run is :func:`evaluation.runner.run_unit` in a worker process (spawn context, one torch
thread each). A run that fails is reported and leaves the others alone; running the same
command again skips the finished runs and resumes the others from their checkpoints.
"""

from __future__ import annotations

import os
import shutil
import signal
import threading
import time
import traceback
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import yaml

from evaluation.experiment import Experiment
from evaluation.runner import run_unit
from evaluation.storage import (
    EVALUATIONS_DIR,
    EXPERIMENT_FILE,
    META_FILE,
    TRAIN_DIR,
    ResultsError,
    atomic_write_text,
)


@dataclass
class BenchmarkReport:
    """What :func:`run_experiment` did and wrote."""

    folder: Path
    summaries: list[dict[str, Any]] = field(default_factory=list)
    """One :func:`run_unit` summary per run that finished (or was already finished)."""
    failures: list[dict[str, Any]] = field(default_factory=list)
    """configuration, seed, error (one line) and log (the traceback's file) per failed run."""
    outputs: list[Path] = field(default_factory=list)
    """Curves, leaderboard and video files written."""
    seconds: float = 0.0


def run_experiment(experiment: Experiment, results: str | Path = "results", *, workers: int = 1, progress: bool = True,
                   video: bool = True, log: Callable[[str], None] = print) -> BenchmarkReport:
    """Run (or resume) every unit of ``experiment`` under ``results/<name>`` and write the report files."""
    started = time.perf_counter()
    folder = Path(results) / experiment.name
    claim_folder(folder, experiment)
    if experiment.needs_encoder():
        pretrain(experiment, folder, log)
    units = experiment.units(folder)
    report = BenchmarkReport(folder)
    monitor = _Progress(units, experiment, enabled=progress)
    try:
        for outcome in _execute(units, workers, verbose=not progress):
            (report.failures if outcome.get("status") == "failed" else report.summaries).append(outcome)
            monitor.finished(outcome)
            monitor.write(describe_outcome(outcome), log)
    finally:
        monitor.close()
    if report.summaries:
        report.outputs = write_report(folder, video=video and not report.failures, log=log)
    report.seconds = time.perf_counter() - started
    return report


def describe_outcome(outcome: dict[str, Any]) -> str:
    """One line about a finished (or failed) run."""
    run = f"run {outcome['configuration']}/seed_{outcome['seed']}"
    if outcome["status"] == "failed":
        return f"{run} failed: {outcome['error']} (traceback: {outcome['log']})"
    return (f"{run} {outcome['status']}: final success {outcome['final_success']:.0%}, collision {outcome['final_collision']:.0%}, "
            f"truncated {outcome['final_truncated']:.0%}; {outcome['env_steps']} env steps, {outcome['wall_time_s']:.0f} s")


def claim_folder(folder: Path, experiment: Experiment) -> None:
    """Write experiment.yaml, or check that ``folder`` holds this experiment (more seeds may be added)."""
    path = folder / EXPERIMENT_FILE
    wanted = experiment.to_dict()
    if path.is_file():
        try:
            existing = yaml.safe_load(path.read_text(encoding="utf-8"))
        except yaml.YAMLError:
            raise ResultsError(f"{path}: unreadable; remove it or use another --out") from None
        if not isinstance(existing, dict):
            raise ResultsError(f"{path}: not an experiment record; remove it or use another --out")
        comparable = {**existing, "protocol": {**existing.get("protocol", {}), "seeds": experiment.protocol.seeds}}
        if comparable != wanted:
            changed = sorted(key for key in wanted if comparable.get(key) != wanted[key])
            raise ResultsError(f"{folder} holds results of a different version of experiment '{experiment.name}' "
                               f"({', '.join(changed)} differ); use another --out or remove {folder}")
        wanted["protocol"]["seeds"] = max(existing["protocol"]["seeds"], experiment.protocol.seeds)
    atomic_write_text(path, yaml.safe_dump(wanted, sort_keys=False))


def pretrain(experiment: Experiment, folder: Path, log: Callable[[str], None]) -> Path:
    """The experiment's pre-trained LEOG encoder (trained once, then reused)."""
    from evaluation.runner import pretrained_encoder_path

    target = pretrained_encoder_path(folder)
    if target.is_file():
        return target
    import torch

    from agents import collect_grids, pretrain_encoder

    settings = experiment.pretrain_encoder
    extractor = experiment.configurations[0].train.get("extractor", {})
    sensors = next((c.train.get("sensors") for c in experiment.configurations if c.train.get("sensors")), None)
    log(f"pre-training the LEOG encoder on {settings['grids']} grids of {settings['scenario']} ...")
    torch.set_num_threads(max(1, min(4, os.cpu_count() or 1)))
    grids = collect_grids(settings["scenario"], settings["grids"], seed=settings["seed"], every=settings["every"], sensors=sensors)
    staging = target.parent.with_name(target.parent.name + ".partial")
    shutil.rmtree(staging, ignore_errors=True)
    # the encoder must have the agents' LEOG architecture: leog_channels -> channels, ...
    architecture = {key.removeprefix("leog_"): extractor[key] for key in ("leog_channels", "leog_kernels", "leog_strides", "leog_latent")
                    if key in extractor}
    result = pretrain_encoder(grids, staging, epochs=settings["epochs"], seed=settings["seed"], **architecture)
    staging.rename(target.parent)
    log(f"encoder: held-out loss {result.initial_val_loss:.4f} -> {result.final_val_loss:.4f}, saved to {target}")
    return target


def _execute(units: list, workers: int, verbose: bool):
    """Yield one outcome per unit as they finish: in this process (workers == 1) or in a spawn pool."""
    jobs = [(spec.to_dict(), str(out_dir), verbose) for spec, out_dir in units]
    if workers <= 1:
        for job in jobs:
            yield run_guarded(*job)
        return
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn"), initializer=_init_worker)
    try:
        futures = {pool.submit(run_guarded, *job): job for job in jobs}
        for future in as_completed(futures):
            try:
                yield future.result()
            except Exception as error:  # the worker process died (killed, out of memory): the others go on
                spec, out_dir, _ = futures[future]
                yield _failure(spec, out_dir, f"worker process died: {type(error).__name__}: {error}", None)
    finally:  # on Ctrl-C, do not start the queued runs (the running ones stop with it and resume next time)
        pool.shutdown(wait=True, cancel_futures=True)


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


def run_guarded(spec: dict[str, Any], out_dir: str, verbose: bool = False) -> dict[str, Any]:
    """:func:`run_unit` that returns a failure record (traceback in OUT/error.log) instead of raising.

    ``verbose``: print a line after each evaluation (for logs; not with a progress bar).
    """
    def report(event: str, data: dict[str, Any]) -> None:
        if verbose and event == "evaluated":
            print(f"run {spec['configuration']}/seed_{spec['seed']}: evaluation {data['evaluation']} after "
                  f"{data['training_episodes']} episodes: success {data['success']:.0%}, collision {data['collision']:.0%}, "
                  f"truncated {data['truncated']:.0%}", flush=True)

    if _interrupted:
        return _failure(spec, out_dir, "not started: interrupted", None)
    try:
        return run_unit(spec, out_dir, on_event=report)
    except Exception as error:  # one failed run must not stop the others
        log = Path(out_dir) / "error.log"
        log.parent.mkdir(parents=True, exist_ok=True)
        log.write_text(traceback.format_exc(), encoding="utf-8")
        message = " ".join(f"{type(error).__name__}: {error}".split())
        return _failure(spec, out_dir, message, log)


def _failure(spec: dict[str, Any], out_dir: str, message: str, log: Path | None) -> dict[str, Any]:
    return {"experiment": spec["experiment"], "configuration": spec["configuration"], "seed": spec["seed"],
            "status": "failed", "error": message, "log": str(log) if log else "-", "out": out_dir}


def write_report(folder: Path, *, video: bool = True, log: Callable[[str], None] = print) -> list[Path]:
    """Curves, leaderboard and (optionally) a video of the best configuration's final policy, in ``folder``."""
    from evaluation.curves import plot_curves
    from evaluation.leaderboard import write_leaderboard

    outputs = plot_curves([folder], folder / "curves")
    table, written = write_leaderboard([folder], folder / "leaderboard")
    outputs += written
    if video:
        best = table.iloc[0]  # rows are sorted by final success
        try:
            outputs += render_final_policy(folder / best["configuration"], folder / "videos")
        except Exception as error:  # the results stand without the video; say why it is missing
            log(f"video skipped: {type(error).__name__}: {error}")
    return outputs


def render_final_policy(configuration_dir: Path, out: Path) -> list[Path]:
    """A video of the first seed's final policy on the first test episode."""
    from crowdnav.rendering.episodes import render_episodes
    from evaluation.storage import read_json

    runs = sorted(path for path in configuration_dir.iterdir() if (path / META_FILE).is_file())
    meta = read_json(runs[0] / META_FILE)
    checkpoint = runs[0] / TRAIN_DIR / "checkpoint"
    test_seed = meta["protocol"]["test_seed_base"]
    paths = render_episodes(meta["config"]["scenario"], str(checkpoint), episodes=1, seed=test_seed, out=out, progress=False)
    named = out / f"{meta['configuration']}_{runs[0].name}_final_test{test_seed}{paths[0].suffix}"
    paths[0].replace(named)
    return [named]


class _Progress:
    """A progress bar over all runs' episodes (training and test), read from the files the runs write."""

    def __init__(self, units: list, experiment: Experiment, *, enabled: bool, interval: float = 1.0):
        protocol = experiment.protocol
        self.folders = [out_dir for _, out_dir in units]
        self.train_episodes, self.test_total = protocol.train_episodes, protocol.evaluations * protocol.test_episodes
        self.test_episodes = protocol.test_episodes
        self.runs, self.done, self.failed = len(units), 0, 0
        self.bar = None
        self._stop = threading.Event()
        if enabled:
            from tqdm import tqdm

            self.bar = tqdm(total=self.runs * (self.train_episodes + self.test_total), unit="ep", desc=f"benchmark {experiment.name}",
                            dynamic_ncols=True)
            self._refresh()
            self._thread = threading.Thread(target=self._poll, args=(interval,), daemon=True)
            self._thread.start()

    def _episodes(self, folder: Path) -> int:
        if (folder / META_FILE).is_file():
            return self.train_episodes + self.test_total
        trained = 0
        log = folder / TRAIN_DIR / "episodes.csv"
        if log.is_file():
            lines = log.read_text(encoding="utf-8").splitlines()
            if len(lines) > 1:
                first = lines[-1].split(",", 1)[0]
                trained = int(first) + 1 if first.isdigit() else 0
        evaluations = len(list((folder / EVALUATIONS_DIR).glob("evaluation_*.csv"))) if (folder / EVALUATIONS_DIR).is_dir() else 0
        return min(trained, self.train_episodes) + evaluations * self.test_episodes

    def _refresh(self) -> None:
        if self.bar is None:
            return
        total = sum(self._episodes(folder) for folder in self.folders)
        self.bar.n = total
        self.bar.set_postfix_str(f"runs {self.done}/{self.runs} done" + (f", {self.failed} failed" if self.failed else ""), refresh=False)
        self.bar.refresh()

    def _poll(self, interval: float) -> None:
        while not self._stop.wait(interval):
            try:
                self._refresh()
            except (OSError, ValueError):  # a file being replaced while read: next time
                pass

    def finished(self, outcome: dict[str, Any]) -> None:
        if outcome.get("status") == "failed":
            self.failed += 1
        else:
            self.done += 1
        self._refresh()

    def write(self, line: str, log: Callable[[str], None]) -> None:
        """A line above the progress bar (or to ``log`` without one)."""
        if self.bar is not None:
            self.bar.write(line)
        else:
            log(line)

    def close(self) -> None:
        self._stop.set()
        if self.bar is not None:
            self._thread.join()
            self._refresh()
            self.bar.close()
