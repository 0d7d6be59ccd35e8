"""A kill at any moment loses nothing: `crowdnav train` and `crowdnav benchmark` killed (SIGKILL, SIGTERM) at their
earliest moments resume to a whole log, one header and one row per episode; a damaged log or checkpoint is repaired
or refused in one line."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from crowdnav.agents.runs.episode_log import DISCARDED_SUFFIX, HEADER, EpisodeLogError, prepare_log, read_log

from crowdnav.cli import main
from tests.agents.agents_tiny import tiny_config
from tests.paths import REPO

ROOT = REPO


def _crowdnav(*args: str, cwd: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "tests")}
    return subprocess.Popen([sys.executable, "-m", "crowdnav", *args], cwd=cwd, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _kill_when(process: subprocess.Popen, exists: list[Path] | Path, signum: int, timeout: float = 120.0) -> str:
    """Send ``signum`` as soon as ``exists`` (a path, or any of several) appears; returns stderr."""
    paths = exists if isinstance(exists, list) else [exists]
    deadline = time.monotonic() + timeout
    while not any(path.exists() for path in paths):
        assert process.poll() is None, f"ended before {paths[0].name} appeared: {process.communicate()}"
        assert time.monotonic() < deadline, f"{paths[0]} never appeared"
        time.sleep(0.001)
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode in (-signum, 128 + signum), (process.returncode, stderr)
    return stderr


def _finish(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    done = _crowdnav(*args, cwd=cwd)
    stdout, stderr = done.communicate(timeout=600)
    assert done.returncode == 0, stderr
    return subprocess.CompletedProcess(done.args, done.returncode, stdout, stderr)


def _assert_whole_log(log: Path, episodes: int) -> None:
    text = log.read_text(encoding="utf-8")
    assert text.startswith(HEADER + "\n") and text.count(HEADER) == 1 and text.endswith("\n")
    assert [row[0] for row in read_log(log, episodes)] == list(range(episodes))  # every row whole, each episode once


# --------------------------------------------------------------------------- the log on its own


def test_an_empty_log_left_by_a_kill_gets_its_header_back(tmp_path):
    log = tmp_path / "episodes.csv"
    log.write_bytes(b"")
    assert prepare_log(log, 0) and log.read_text() == HEADER + "\n"
    log.write_text(HEADER[:9])  # killed inside the header's write
    prepare_log(log, 0)
    assert log.read_text() == HEADER + "\n"


def test_a_headerless_log_gets_its_header_and_keeps_its_rows(tmp_path):
    log = tmp_path / "episodes.csv"
    rows = "0,1000,success,1.5,10,10,0.1\n1,1001,collision,-2.0,5,15,0.2\n"
    log.write_text(rows)  # an older crowdnav: header lost in a buffer, rows appended by the next session
    notes = prepare_log(log, 2)
    assert len(notes) == 1 and "header" in notes[0]
    assert log.read_text() == HEADER + "\n" + rows


def test_a_cut_last_row_and_rows_after_the_checkpoint_move_to_discarded(tmp_path):
    log = tmp_path / "episodes.csv"
    log.write_text(HEADER + "\n0,1000,success,1.5,10,10,0.1\n1,1001,collision,-2.0,5,15,0.2\n2,10")
    notes = prepare_log(log, 1)
    assert len(notes) == 1 and "cut last line" in notes[0]
    assert log.read_text() == HEADER + "\n0,1000,success,1.5,10,10,0.1\n"
    discarded = (tmp_path / f"episodes.csv{DISCARDED_SUFFIX}").read_text()
    assert discarded == HEADER + "\n1,1001,collision,-2.0,5,15,0.2\n2,10\n"
    assert prepare_log(log, 1) == []  # repaired once: nothing more to do


def test_a_foreign_first_line_is_refused_in_one_line(tmp_path):
    log = tmp_path / "episodes.csv"
    log.write_text("name,age\nbob,3\n")
    with pytest.raises(EpisodeLogError) as error:
        prepare_log(log, 0)
    assert "\n" not in str(error.value) and "move that file away" in str(error.value)
    assert log.read_text() == "name,age\nbob,3\n"  # nothing lost


@pytest.mark.parametrize(("body", "says"), [
    ("0,1000,success,1.5,10,10,0.1\n1,1001,collis\n2,1002,success,1.0,9,24,0.3\n", "line 3 is damaged"),
    ("0,1000,success,1.5,10,10,0.1\n1,1001,flying,-2.0,5,15,0.2\n", "line 3 is damaged"),
    ("0,1000,success,1.5,10,10,0.1\n", "no row for episode(s) [1]"),
])
def test_reading_a_damaged_log_names_the_file_and_line(tmp_path, body, says):
    log = tmp_path / "episodes.csv"
    log.write_text(HEADER + "\n" + body)
    with pytest.raises(EpisodeLogError) as error:
        read_log(log, 2 if "no row" in says else None)
    assert says in str(error.value) and str(log) in str(error.value) and "\n" not in str(error.value)


# --------------------------------------------------------------------------- crowdnav train, killed


def _train_config(tmp_path: Path, episodes: int) -> Path:
    path = tmp_path / "train.yaml"
    config = tiny_config("run", episodes=episodes, max_steps=30, checkpoint_every=2)
    path.write_text(yaml.safe_dump(config), encoding="utf-8")
    return path


@pytest.mark.parametrize(("moment", "signum"), [
    ("episodes.csv", signal.SIGKILL),  # the case: killed before the first episode ended (about 5 s)
    pytest.param("episodes.csv", signal.SIGTERM, marks=pytest.mark.slow),
    pytest.param("checkpoint/policy.json", signal.SIGKILL, marks=pytest.mark.slow),
    pytest.param("checkpoint/policy.json", signal.SIGTERM, marks=pytest.mark.slow),
], ids=["first-SIGKILL", "first-SIGTERM", "checkpoint-SIGKILL", "checkpoint-SIGTERM"])
def test_train_killed_at_its_earliest_moments_resumes_to_a_whole_log(tmp_path, signum, moment):
    config = _train_config(tmp_path, episodes=6)
    stderr = _kill_when(_crowdnav("train", "--config", str(config), cwd=tmp_path), tmp_path / "run" / moment, signum)
    if signum == signal.SIGTERM:  # stopped as Ctrl-C stops it: one line saying how to go on, no traceback
        assert stderr.strip().count("\n") == 0 and stderr.startswith("crowdnav: interrupted;"), stderr
    log = tmp_path / "run" / "episodes.csv"
    assert log.read_text().startswith(HEADER + "\n")  # the header was on disk before the first episode began
    resume = ["--resume"] if (tmp_path / "run" / "checkpoint").is_dir() else []
    _finish("train", "--config", str(config), *resume, cwd=tmp_path)
    _assert_whole_log(log, 6)


def test_train_stopped_by_sigterm_keeps_its_checkpoint_and_says_how_to_resume(tmp_path):
    config = _train_config(tmp_path, episodes=400)
    run = tmp_path / "run"
    stderr = _kill_when(_crowdnav("train", "--config", str(config), cwd=tmp_path), run / "checkpoint" / "policy.json", signal.SIGTERM)
    assert stderr.strip() == f"crowdnav: interrupted; the last checkpoint in {Path('run')} is kept: add --resume to the same " \
                             "command to continue from it"
    episodes = yaml.safe_load((run / "checkpoint" / "policy.json").read_text())["episodes"]
    assert episodes >= 2
    text = (run / "episodes.csv").read_text()
    assert text.startswith(HEADER + "\n") and text.endswith("\n")  # a SIGTERM mid-run leaves whole rows only


# --------------------------------------------------------------------------- a damaged checkpoint


@pytest.mark.parametrize("name", ["policy.json", "model.zip", "training_state.json", "replay_buffer.npz"])
def test_a_cut_checkpoint_file_is_recovered_or_refused_in_one_line(tmp_path, capsys, monkeypatch, name):
    config = _train_config(tmp_path, episodes=2)
    monkeypatch.chdir(tmp_path)
    assert main(["train", "--config", str(config)]) == 0
    file = tmp_path / "run" / "checkpoint" / name
    file.write_bytes(file.read_bytes()[: file.stat().st_size // 2])  # a disk that filled up, a copy cut short
    capsys.readouterr()
    bigger = tmp_path / "bigger.yaml"
    bigger.write_text(config.read_text().replace("episodes: 2", "episodes: 3"))
    status = main(["train", "--config", str(bigger), "--resume"])
    err = capsys.readouterr().err
    if status == 0:  # recovered: the run went on to its new budget, its log whole
        _assert_whole_log(tmp_path / "run" / "episodes.csv", 3)
    else:
        lines = err.strip().splitlines()
        assert status == 1 and len(lines) == 1 and lines[0].startswith("crowdnav: error:") and name in lines[0], err
        assert "move run away" in lines[0] or f"remove {Path('run', 'checkpoint', name)}" in lines[0], err  # how to go on


# --------------------------------------------------------------------------- crowdnav benchmark, killed


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_a_benchmark_killed_as_its_first_run_starts_resumes_to_whole_results(tmp_path, signum):
    from tests.evaluation.evaluation_tiny import write_tiny_experiment

    experiment = write_tiny_experiment(tmp_path / "tiny.yaml")
    command = ["benchmark", str(experiment), "--out", "results", "--workers", "1", "--no-video", "--no-progress"]
    first_logs = [tmp_path / "results" / "tiny" / name / "seed_0" / "train" / "episodes.csv" for name in ("lidar", "closest")]
    stderr = _kill_when(_crowdnav(*command, cwd=tmp_path), first_logs, signum)
    if signum == signal.SIGTERM:
        assert "Traceback" not in stderr and "crowdnav: interrupted; run the same command again" in stderr, stderr
    _finish(*command, cwd=tmp_path)
    folder = tmp_path / "results" / "tiny"
    for run in sorted(folder.glob("*/seed_*")):
        _assert_whole_log(run / "train" / "episodes.csv", 4)
    board = (folder / "leaderboard.md").read_text()
    assert "| LIDAR | 2 |" in board and "| closest obstacle | 2 |" in board and "missing" not in board


def test_evaluate_stopped_by_sigterm_writes_nothing_and_says_so_in_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    before = signal.getsignal(signal.SIGTERM)
    (tmp_path / "stopper.py").write_text(
        "import os, signal\n\ndef act(observation):\n    os.kill(os.getpid(), signal.SIGTERM)\n    return [0.0, 0.0]\n")
    status = main(["evaluate", "stopper:act", "--scenario", "open_space", "--episodes", "2", "--out", "out", "--no-progress"])
    err = capsys.readouterr().err
    assert status == 128 + signal.SIGTERM and err == "crowdnav: interrupted before the results were written; run the same command again\n"
    assert not list(tmp_path.glob("out/**/meta.json")) and not list(tmp_path.glob("out/**/test_episodes.csv"))
    assert signal.getsignal(signal.SIGTERM) == before  # the handler is the command's own, not left behind
