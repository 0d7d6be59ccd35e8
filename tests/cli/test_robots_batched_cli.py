"""`crowdnav train` on a several-robot scenario with the native vector env's worlds (num_envs > 1): it trains, and
every refusal left is one line that leaves no run folder behind."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from crowdnav.cli import main

HALL = "robots_crossing_hall"


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    return err


def _config(tmp_path: Path, **fields) -> str:
    path = tmp_path / "config.yaml"
    path.write_text(yaml.safe_dump({"progress": False, **fields}), encoding="utf-8")
    return str(path)


def test_the_issues_command_trains_robots_crossing_hall_with_the_default_32_worlds(tmp_path, capsys):
    """`crowdnav train --scenario robots_crossing_hall --algo ppo`: the native vector env's 32 worlds, one 2,048-step rollout (~4 s)."""
    out = tmp_path / "run"
    assert main(["train", "--scenario", HALL, "--algo", "ppo", "--timesteps", "2048", "--out", str(out), "--no-progress"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["timesteps"] == 2048 and summary["episodes"] > 0
    assert yaml.safe_load((out / "config.yaml").read_text(encoding="utf-8"))["num_envs"] == 32  # the default: batched worlds
    assert (out / "checkpoint" / "policy.json").is_file()


@pytest.mark.parametrize(("fields", "expected"), [
    ({"scenario": HALL, "shield": True}, "shield: shields one robot; 'robots_crossing_hall' declares several (robots:)"),
    ({"scenario": "open_space", "agents": "robots"}, "agents: robots needs a scenario with several robots (robots:)"),
    ({"scenario": HALL, "overrides": {"humans.count": 3000}}, "humans.count: the spawn regions hold at most"),
])
def test_a_refusal_is_one_line_and_leaves_no_run_folder(tmp_path, capsys, fields, expected):
    out = tmp_path / "new" / "run"  # neither folder exists: both must be gone after the refusal
    assert main(["train", "--config", _config(tmp_path, algo="ppo", timesteps=256, **fields), "--out", str(out)]) != 0
    assert expected in _one_error_line(capsys)
    assert not (tmp_path / "new").exists()
