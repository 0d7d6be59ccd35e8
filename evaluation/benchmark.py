"""Run a whole experiment: every (configuration, seed) unit through an executor, then the report.

``run_experiment`` writes into ``RESULTS/<experiment name>/``: experiment.yaml (the resolved
experiment; a folder holding another experiment's results is refused), the pre-trained
encoder if the experiment needs one, one folder per run (see :mod:`crowdnav.evaluation.storage`),
and, once runs have finished, the curves (curves.png/.pdf), the leaderboard
(leaderboard.md/.csv) and a video of the best configuration's final policy (videos/).

Each run is :func:`crowdnav.evaluation.runner.run_unit`, carried out by an executor
(:mod:`crowdnav.evaluation.executors`: in this process, in a local process pool, or as Ray tasks). A run
that fails is reported and leaves the others alone; running the same command again skips the
finished runs and resumes the others from their checkpoints.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from crowdnav.evaluation.baselines import evaluate_experiment_baselines
from crowdnav.evaluation.executors import make_executor
from crowdnav.evaluation.experiment import Experiment, ExperimentError
from crowdnav.evaluation.jobs import Executor, Job, run_name
from crowdnav.evaluation.progress import ProgressBar
from crowdnav.evaluation.protocol import UNIT_NAMES, protocol_unit
from crowdnav.evaluation.storage import (
    EXPERIMENT_FILE,
    META_FILE,
    TRAIN_DIR,
    ResultsError,
    atomic_write_text,
    encoder_folder,
    experiment_folder,
    pretrained_encoder_path,
)
from crowdnav.evaluation.unit_spec import PRETRAINED

from crowdnav.files import discard_leftovers, staging_beside, swap_folder
from crowdnav.sim.simulator import OUTCOMES


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
    executor: str = ""
    """The executor's name (serial, local, ray)."""

    @property
    def retried(self) -> list[dict[str, Any]]:
        """The runs (finished or failed) that were started more than once: their worker died and the executor retried them."""
        return [outcome for outcome in self.summaries + self.failures if outcome.get("attempts", 0) > 1]

    def summary_lines(self) -> list[str]:
        """The sweep's summary: counts, then the finished, retried and failed runs by name."""
        skipped = sum(summary["status"] == "skipped" for summary in self.summaries)
        lines = [f"{len(self.summaries)} runs finished ({skipped} already done), {len(self.retried)} retried, "
                 f"{len(self.failures)} failed, in {self.seconds:.0f} s"]
        for title, outcomes, detail in (
            ("finished", self.summaries, lambda o: {"skipped": " (already done)", "repaired": " (repaired)"}.get(o["status"], "")),
            ("retried", self.retried, lambda o: f" ({o['attempts']} attempts{', failed' if o['status'] == 'failed' else ''})"),
            ("failed", self.failures, lambda o: f" ({o['error']}; traceback: {o['log']})"),
        ):
            if outcomes:
                lines.append(f"{title}: " + ", ".join(f"{run_name(o)}{detail(o)}" for o in sorted(outcomes, key=run_name)))
        return lines


def run_experiment(experiment: Experiment, results: str | Path = "results", *, workers: int = 1, executor: Executor | None = None,
                   progress: bool = True, video: bool = True, log: Callable[[str], None] = print) -> BenchmarkReport:
    """Run (or resume) every unit of ``experiment`` under ``results/<name>`` and write the report files.

    ``executor``: where the runs happen (:func:`crowdnav.evaluation.executors.make_executor`); default:
    this process when ``workers`` is 1, else a local pool of ``workers`` processes.
    """
    started = time.perf_counter()
    if executor is None:
        executor = make_executor("serial" if workers <= 1 else "local", workers=workers)
    folder = experiment_folder(results, experiment.name)
    claim_folder(folder, experiment)
    if experiment.needs_encoder():
        pretrain(experiment, folder, log)
    for baseline in evaluate_experiment_baselines(experiment, folder):  # seconds: the bar the learned runs must clear
        log(baseline if isinstance(baseline, str) else describe_baseline(baseline))
    jobs = [Job(spec.to_dict(), str(out_dir), spec) for spec, out_dir in experiment.units(folder)]
    report = BenchmarkReport(folder, executor=executor.name)
    monitor = ProgressBar(jobs, experiment.protocol, executor.episodes_done, title=f"benchmark {experiment.name}", enabled=progress)
    try:
        for outcome in executor.run(jobs, verbose=not progress):
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
    run = f"run {run_name(outcome)}"
    if outcome.get("attempts", 0) > 1:
        run += f" (attempt {outcome['attempts']})"
    if outcome["status"] == "failed":
        return f"{run} failed: {outcome['error']} (traceback: {outcome['log']})"
    # a run finished before out_of_bounds existed has no final_out_of_bounds: it had none
    rates = ", ".join(f"{name} {outcome.get(f'final_{name}', 0.0):.0%}" for name in OUTCOMES)
    repairs = f" (found {'; '.join(outcome['repairs'])})" if outcome.get("repairs") else ""
    return f"{run} {outcome['status']}{repairs}: final {rates}; {outcome['env_steps']} env steps, {outcome['wall_time_s']:.0f} s"


def describe_baseline(folder: Path) -> str:
    """One line about a scripted baseline's rates on the test episodes."""
    from crowdnav.evaluation.storage import read_json

    meta = read_json(folder / META_FILE)
    rates = ", ".join(f"{outcome} {rate:.0%}" for outcome, rate in sorted(meta["final"].items(), key=lambda item: item[0] != "success"))
    # a baseline driving every robot has one row per robot per test episode
    episodes = "robot episodes" if (meta.get("env") or {}).get("agents") == "robots" else "test episodes"
    return f"baseline {meta['label']}: {rates} on the {meta['test_episodes']} {episodes}"


def claim_folder(folder: Path, experiment: Experiment) -> None:
    """Write experiment.yaml, or check that ``folder`` holds this experiment.

    Only what every run shares must match: the protocol (more seeds may be added; a budget in
    another unit, episodes or env steps, is another protocol) and the encoder pre-training. A
    new description or label, an added or edited configuration leaves the finished runs alone:
    each run checks its own spec (:func:`crowdnav.evaluation.runner.run_unit` starts an edited
    configuration's runs afresh and keeps the old ones aside).
    """
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
        changed = sorted(key for key in ("protocol", "pretrain_encoder") if comparable.get(key) != wanted[key])
        if changed:
            was, now = protocol_unit(comparable["protocol"]), experiment.protocol.unit  # older records have no unit: episodes
            unit = f": its budget is in {UNIT_NAMES[was]}, this one's in {UNIT_NAMES[now]}" if was != now else ""
            raise ResultsError(f"{folder} holds results of a different version of experiment '{experiment.name}' "
                               f"({', '.join(changed)} differ{unit}); use another --out or remove {folder}")
        wanted["protocol"]["seeds"] = max(existing["protocol"]["seeds"], experiment.protocol.seeds)
    atomic_write_text(path, yaml.safe_dump(wanted, sort_keys=False))


def pretrain(experiment: Experiment, folder: Path, log: Callable[[str], None]) -> Path:
    """The experiment's pre-trained LEOG encoder (trained once, then reused)."""
    target = pretrained_encoder_path(folder)
    if target.is_file():
        return target
    import torch
    from crowdnav.agents import collect_grids, pretrain_encoder

    settings = experiment.pretrain_encoder
    if settings is None:  # a configuration names the pre-trained encoder by hand, and no section says how to train it
        raise ExperimentError(f"experiment '{experiment.name}': encoder.weights is {PRETRAINED} but there is no pretrain_encoder section")
    extractor = experiment.configurations[0].train.get("extractor", {})
    sensors = next((c.train.get("sensors") for c in experiment.configurations if c.train.get("sensors")), None)
    log(f"pre-training the LEOG encoder on {settings['grids']} grids of {settings['scenario']} ...")
    torch.set_num_threads(max(1, min(4, os.cpu_count() or 1)))
    grids = collect_grids(settings["scenario"], settings["grids"], seed=settings["seed"], every=settings["every"], sensors=sensors)
    discard_leftovers(encoder_folder(folder))  # a killed pre-training's staging folder
    staging = staging_beside(encoder_folder(folder))
    # the encoder must have the agents' LEOG architecture: leog_channels -> channels, ...
    architecture = {key.removeprefix("leog_"): extractor[key] for key in ("leog_channels", "leog_kernels", "leog_strides", "leog_latent")
                    if key in extractor}
    result = pretrain_encoder(grids, staging, epochs=settings["epochs"], seed=settings["seed"], **architecture)
    swap_folder(staging, encoder_folder(folder))
    log(f"encoder: held-out loss {result.initial_val_loss:.4f} -> {result.final_val_loss:.4f}, saved to {target}")
    return target


def write_report(folder: Path, *, video: bool = True, log: Callable[[str], None] = print) -> list[Path]:
    """Curves, leaderboard and (optionally) a video of the best configuration's final policy, in ``folder``."""
    from crowdnav.evaluation.curves import plot_curves
    from crowdnav.evaluation.leaderboard import write_leaderboard

    outputs = plot_curves([folder], folder / "curves")
    table, written = write_leaderboard([folder], folder / "leaderboard")
    outputs += written
    for gap in table.attrs.get("missing", []):  # named in leaderboard.md too
        log(f"not in the leaderboard: {gap.describe(folder=True)}")
    if video:
        best = table[table["kind"] == "learned"].iloc[0]  # rows are sorted by final success
        try:
            outputs += render_final_policy(folder / best["configuration"], folder / "videos")
        except Exception as error:  # the results stand without the video; say why it is missing
            log(f"video skipped: {type(error).__name__}: {error}")
    return outputs


def render_final_policy(configuration_dir: Path, out: Path) -> list[Path]:
    """A video of the first seed's final policy on the first test episode."""
    from crowdnav.agents.runs.folder import checkpoint_dir
    from crowdnav.agents.runs.render import render_policy
    from crowdnav.evaluation.storage import read_json

    runs = sorted(path for path in configuration_dir.iterdir() if (path / META_FILE).is_file())
    meta = read_json(runs[0] / META_FILE)
    checkpoint = checkpoint_dir(runs[0] / TRAIN_DIR)
    test_seed = meta["protocol"]["test_seed_base"]
    paths = render_policy(meta["config"]["scenario"], str(checkpoint), episodes=1, seed=test_seed, out=out, progress=False)
    named = out / f"{meta['configuration']}_{runs[0].name}_final_test{test_seed}{paths[0].suffix}"
    paths[0].replace(named)
    return [named]
