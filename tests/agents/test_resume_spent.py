"""A resume that finds the run's budget spent changes nothing: no checkpoint file is rewritten, so a later extension of
the run plays what it would have played without that resume (shared robot runs, single-robot SB3 and SARL runs;
issue 49, item 6)."""

from __future__ import annotations

import csv
import hashlib
import time
from pathlib import Path

import pytest
from crowdnav.agents import train
from crowdnav.agents.runs.folder import LOCK_FILE

from tests.agents.agents_tiny import tiny_config
from tests.agents.test_marl import robots_config

BUDGET = {"timesteps": None, "checkpoint_every_steps": None, "checkpoint_every": 6}


def _files(run: Path) -> dict[str, tuple[str, int]]:
    """Every file of the run's checkpoint and log: (content hash, modification time)."""
    kept = [*sorted((run / "checkpoint").rglob("*")), run / "episodes.csv"]
    return {str(path.relative_to(run)): (hashlib.sha256(path.read_bytes()).hexdigest(), path.stat().st_mtime_ns)
            for path in kept if path.is_file()}


def _rows(run: Path) -> list[dict[str, str]]:
    with open(run / "episodes.csv", encoding="utf-8") as file:
        return [{key: value for key, value in row.items() if key != "seconds"} for row in csv.DictReader(file)]


def test_a_no_op_resume_of_a_finished_robots_run_rewrites_nothing_and_its_extension_stays_exact(tmp_path):
    plain, touched = tmp_path / "plain", tmp_path / "touched"
    for run in (plain, touched):
        train(robots_config(run, episodes=6, **BUDGET))
    before = _files(touched)
    again = train(robots_config(touched, episodes=6, **BUDGET), resume=True)  # the budget is spent: nothing to play
    assert _files(touched) == before and again.episodes == 6 and again.records == []
    for run in (plain, touched):
        train(robots_config(run, episodes=12, **BUDGET), resume=True)
    assert _rows(touched) == _rows(plain) and len(_rows(plain)) >= 12


def _every_file(run: Path) -> dict[str, tuple[str, int]]:
    """Every file in the run folder but the writer lock (taken and released by any writer): (content hash, modification time)."""
    return {str(path.relative_to(run)): (hashlib.sha256(path.read_bytes()).hexdigest(), path.stat().st_mtime_ns)
            for path in sorted(run.rglob("*")) if path.is_file() and path.name != LOCK_FILE}


@pytest.mark.parametrize("kind", ["sb3", "sarl"])
def test_a_no_op_resume_of_a_finished_single_robot_run_leaves_every_file_as_it_was(tmp_path, kind):
    run = tmp_path / "run"
    if kind == "sarl":
        pytest.importorskip("torch")
        from tests.agents.test_sarl import config as sarl_config

        config = sarl_config(run, episodes=2)
    else:
        config = tiny_config(run, algo="ppo", episodes=2, max_steps=20)
    train(config)
    before = _every_file(run)
    assert "config.yaml" in before and "episodes.csv" in before
    time.sleep(0.01)  # a rewrite now would show in the modification times even on a coarse clock
    again = train(config, resume=True)  # the checkpoint says 2 of 2 episodes: nothing to play
    assert _every_file(run) == before and again.episodes == 2 and again.records == []
