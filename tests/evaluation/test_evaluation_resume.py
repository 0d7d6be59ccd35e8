"""run_unit: idempotent, resumable after a crash in evaluation or a killed process, nothing lost or duplicated."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import crowdnav.evaluation.runner as runner_module
import pandas as pd
import pytest
from crowdnav.evaluation.benchmark import run_experiment
from crowdnav.evaluation.experiment import experiment_from_mapping
from crowdnav.evaluation.runner import run_unit
from crowdnav.evaluation.storage import ResultsError

from tests.evaluation.evaluation_tiny import tiny_experiment_document, tiny_unit_spec
from tests.paths import REPO


def check_complete(out: Path, spec: dict) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Every test episode of every evaluation once, every training episode once, meta.json consistent."""
    protocol = spec["protocol"]
    evaluations = protocol["train_episodes"] // protocol["eval_every"]
    tests = pd.read_csv(out / "test_episodes.csv", keep_default_na=False, na_values=["nan"])
    assert len(tests) == evaluations * protocol["test_episodes"]
    assert not tests.duplicated(["evaluation", "test_episode"]).any()
    assert sorted(tests["evaluation"].unique()) == list(range(evaluations))
    assert list(tests["training_episodes"].unique()) == list(range(protocol["eval_every"], protocol["train_episodes"] + 1,
                                                                   protocol["eval_every"]))
    assert set(tests["test_seed"]) == set(range(protocol["test_episodes"]))
    training = pd.read_csv(out / "training_episodes.csv")
    assert list(training["episode"]) == list(range(protocol["train_episodes"]))
    meta = json.loads((out / "meta.json").read_text())
    assert meta["status"] == "complete" and meta["test_episodes"] == len(tests)
    assert meta["env_steps"]["test"] == tests["steps"].sum()
    assert meta["env_steps"]["train"] == training["timesteps"].iloc[-1]
    return tests, training


class Crash(Exception):
    pass


def test_crash_during_evaluation_resumes_without_redoing_or_losing_evaluations(tmp_path):
    spec = tiny_unit_spec()

    def crash_after_first(event, data):
        if event == "evaluated" and data["evaluation"] == 0:
            raise Crash

    with pytest.raises(Crash):
        run_unit(spec, tmp_path, on_event=crash_after_first)
    first = tmp_path / "evaluations" / "evaluation_000.csv"
    written = first.stat().st_mtime_ns
    assert not (tmp_path / "meta.json").exists() and not (tmp_path / "evaluations" / "evaluation_001.csv").exists()
    (tmp_path / "error.log").write_text("Traceback of the crash\n")  # what an executor leaves after a failed run

    events = []
    summary = run_unit(spec, tmp_path, on_event=lambda event, data: events.append((event, data["evaluation"], data["training_episodes"])))
    assert events == [("evaluated", 1, 4)]  # no training, evaluation 0 not redone
    assert first.stat().st_mtime_ns == written
    assert summary["status"] == "done" and summary["resumed"]
    check_complete(tmp_path, spec)
    assert json.loads((tmp_path / "meta.json").read_text())["sessions"] == 2
    assert not (tmp_path / "error.log").exists()  # the finished run keeps no stale traceback


def test_meta_names_the_commit_the_run_started_with_and_those_of_its_resumes(tmp_path, monkeypatch):
    spec = tiny_unit_spec()

    def crash_after_training(event, data):
        if event == "trained":
            raise Crash

    monkeypatch.setattr(runner_module, "git_commit", lambda: "started")
    with pytest.raises(Crash):
        run_unit(spec, tmp_path, on_event=crash_after_training)
    monkeypatch.setattr(runner_module, "git_commit", lambda: "resumed")
    run_unit(spec, tmp_path)
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert meta["git_commit"] == "started" and meta["git_commits"] == ["started", "resumed"] and meta["sessions"] == 2


def test_finished_run_is_skipped_and_left_untouched(tmp_path):
    spec = tiny_unit_spec()
    run_unit(spec, tmp_path)
    stamps = {path: path.stat().st_mtime_ns for path in tmp_path.rglob("*") if path.is_file()}
    summary = run_unit(spec, tmp_path)
    assert summary["status"] == "skipped"
    assert {path: path.stat().st_mtime_ns for path in tmp_path.rglob("*") if path.is_file()} == stamps


def test_folder_of_another_run_is_refused(tmp_path):
    (tmp_path / "spec.json").write_text(json.dumps(tiny_unit_spec(seed=1)))
    with pytest.raises(ResultsError, match="holds a different run \\(its seed differ"):
        run_unit(tiny_unit_spec(seed=0), tmp_path)


_CHILD = """
import json, sys
from crowdnav.evaluation.benchmark import run_experiment
from crowdnav.evaluation.experiment import experiment_from_mapping
from crowdnav.evaluation.runner import run_unit
run_unit(json.loads(sys.argv[1]), sys.argv[2])
"""


def test_killed_process_resumes_training_from_its_checkpoint_without_duplicate_or_lost_rows(tmp_path):
    spec = tiny_unit_spec(train_episodes=12, eval_every=2)
    spec["train"]["num_envs"] = 1  # one env: seeds in episode order, a checkpoint every 2 episodes (batched: test_training_batched.py)
    child = subprocess.Popen([sys.executable, "-c", _CHILD, json.dumps(spec), str(tmp_path)], cwd=REPO,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    log = tmp_path / "train" / "episodes.csv"
    deadline = time.monotonic() + 60
    # Kill once episode 2 is logged: the checkpoint holds 2 episodes, the next one is due after episode 4.
    while child.poll() is None and time.monotonic() < deadline and (not log.exists() or len(log.read_text().splitlines()) < 4):
        time.sleep(0.01)
    os.kill(child.pid, signal.SIGKILL)
    child.wait()
    checkpoint = json.loads((tmp_path / "train" / "checkpoint" / "policy.json").read_text())["episodes"]
    logged = len(log.read_text().splitlines()) - 1
    assert not (tmp_path / "meta.json").exists() and checkpoint < logged < 12  # episodes past the checkpoint are lost

    summary = run_unit(spec, tmp_path)
    assert summary["status"] == "done" and summary["resumed"]
    tests, training = check_complete(tmp_path, spec)
    assert list(training["episode_seed"]) == [1_000_000 + episode for episode in range(12)]
    assert list(pd.read_csv(log)["episode"]) == list(range(12))  # the raw log too: re-trained episodes set aside


def test_checkpoint_whose_snapshot_was_never_written_is_evaluated_in_its_place(tmp_path):
    spec = tiny_unit_spec()

    def crash_after_training(event, data):
        if event == "trained":
            raise Crash

    with pytest.raises(Crash):
        run_unit(spec, tmp_path, on_event=crash_after_training)
    shutil.rmtree(tmp_path / "train" / "snapshots" / "episode_00004")  # as if killed between checkpoint and snapshot
    events = []
    run_unit(spec, tmp_path, on_event=lambda event, data: events.append((data["evaluation"], data["training_episodes"])))
    assert events == [(0, 2), (1, 4)]
    check_complete(tmp_path, spec)


def test_a_failing_run_is_reported_and_the_others_finish_in_the_process_pool(tmp_path):
    experiment = experiment_from_mapping(tiny_experiment_document(seeds=1))
    (spec, broken), _ = experiment.units(tmp_path / "tiny")
    broken.mkdir(parents=True)
    (broken / "spec.json").write_text(json.dumps({**spec.to_dict(), "seed": 7}))  # someone else's run in that folder
    report = run_experiment(experiment, tmp_path, workers=2, progress=False, video=False, log=lambda line: None)
    assert [(f["configuration"], f["seed"]) for f in report.failures] == [("lidar", 0)]
    assert "holds a different run" in report.failures[0]["error"] and (broken / "error.log").is_file()
    assert [(s["configuration"], s["status"]) for s in report.summaries] == [("closest", "done")]
    assert (tmp_path / "tiny" / "leaderboard.md").is_file()  # the report covers the runs that finished


@pytest.mark.parametrize("algo", ["ppo", "a2c"])
def test_on_policy_rollouts_longer_than_an_evaluation_interval_still_evaluate_at_every_point(tmp_path, algo):
    """A rollout of 512 steps spans many 40-step episodes: snapshots are taken when the episode ends, not at the rollout's end."""
    spec = tiny_unit_spec(train_episodes=6, eval_every=1)
    spec["train"] = {key: value for key, value in spec["train"].items() if key not in ("batch_size", "buffer_size", "learning_starts", "algo_kwargs")}
    spec["train"].update(algo=algo, algo_kwargs={"n_steps": 512, **({"batch_size": 64, "n_epochs": 1} if algo == "ppo" else {})})
    summary = run_unit(spec, tmp_path)
    evaluations = pd.read_csv(tmp_path / "test_episodes.csv").drop_duplicates("evaluation")
    assert summary["status"] == "done" and list(evaluations["training_episodes"]) == [1, 2, 3, 4, 5, 6]


def test_an_edited_configuration_starts_afresh_and_its_old_run_is_kept_aside(tmp_path):
    spec = tiny_unit_spec()
    run_unit(spec, tmp_path / "run")
    edited = {**spec, "train": {**spec["train"], "net_arch": [8]}}
    summary = run_unit(edited, tmp_path / "run")
    assert summary["status"] == "done"
    assert json.loads((tmp_path / "run" / "spec.json").read_text())["train"]["net_arch"] == [8]
    assert json.loads((tmp_path / "run.replaced-1" / "spec.json").read_text())["train"]["net_arch"] == [16]
    assert (tmp_path / "run.replaced-1" / "meta.json").is_file()
    from crowdnav.evaluation.storage import finished_runs

    assert finished_runs([tmp_path]) == [tmp_path / "run"]  # the old run is kept, not counted


def test_adding_seeds_to_the_protocol_keeps_a_finished_run_instead_of_training_it_again(tmp_path):
    spec = tiny_unit_spec()
    run_unit(spec, tmp_path / "run")
    rows = (tmp_path / "run" / "test_episodes.csv").read_bytes()
    more_seeds = {**spec, "protocol": {**spec["protocol"], "seeds": spec["protocol"]["seeds"] + 3}}
    summary = run_unit(more_seeds, tmp_path / "run")
    assert summary["status"] == "skipped" and not (tmp_path / "run.replaced-1").exists()
    assert (tmp_path / "run" / "test_episodes.csv").read_bytes() == rows
