"""The command line with a several-robots checkpoint (`crowdnav train --agents robots`): render plays it (evaluate too:
test_robots_evaluate.py), the commands that take one robot's policy refuse it in one line saying what to use instead;
export's zips; render's raising policy."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from crowdnav.cli import main
from tests.cli.conftest import HALL


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    return err


def test_render_plays_a_robots_checkpoint_with_overlay_flags_and_names_the_file_by_robots_arrived(robots_run, tmp_path, capsys):
    argv = ["render", HALL, "--policy", str(robots_run / "checkpoint"), "--episodes", "1", "--format", "gif",
            "--out", str(tmp_path / "videos"), "--human-goals", "--hide", "lidar", "--no-progress"]
    assert main(argv) == 0, capsys.readouterr().err
    (video,) = (tmp_path / "videos").iterdir()
    match = re.fullmatch(rf"{HALL}_checkpoint_seed0_([0-3])of3_arrived\.gif", video.name)
    assert match and video.stat().st_size > 0, video.name
    printed = capsys.readouterr().out
    assert f"wrote {video}" in printed
    # 20 steps are too few to cross the hall: nobody arrives, and the name no longer says "success"
    assert match.group(1) == "0" and "success" not in video.name


def test_render_of_a_robots_run_folder_in_another_scenario_or_with_overrides_is_one_line(robots_run, tmp_path, capsys):
    assert main(["render", "open_space", "--policy", str(robots_run), "--out", str(tmp_path)]) == 1
    assert "drives the robots of 'robots_crossing_hall', not 'open_space'" in _one_error_line(capsys)
    assert main(["render", HALL, "--policy", str(robots_run), "--out", str(tmp_path), "--set", "humans.count=2"]) == 1
    assert "without overrides" in _one_error_line(capsys)


def test_render_takes_the_scenario_file_a_robots_run_was_trained_in_written_relative_or_absolute(tmp_path, capsys, monkeypatch):
    from importlib.resources import files

    monkeypatch.chdir(tmp_path)
    Path("hall.yaml").write_text((files("crowdnav.scenarios") / f"{HALL}.yaml").read_text(encoding="utf-8"), encoding="utf-8")
    Path("other.yaml").write_text(Path("hall.yaml").read_text(encoding="utf-8"), encoding="utf-8")  # same content, another file
    config = {"scenario": "hall.yaml", "algo": "ppo", "num_envs": 2, "timesteps": 96, "n_steps": 16, "batch_size": 48,
              "net_arch": [16], "seed": 0, "out": "run", "progress": False, "overrides": {"max_steps": 20},
              "sensors": {"lidar": {"beams": 16}}}
    Path("robots.yaml").write_text(yaml.safe_dump(config), encoding="utf-8")
    assert main(["train", "--config", "robots.yaml", "--agents", "robots"]) == 0
    for given in ("./hall.yaml", str(tmp_path / "hall.yaml")):  # the run recorded "hall.yaml"
        assert main(["render", given, "--policy", "run", "--episodes", "1", "--format", "gif", "--out", "videos", "--no-progress"]) == 0, \
            capsys.readouterr().err
    assert [video.suffix for video in Path("videos").iterdir()] == [".gif"]
    capsys.readouterr()
    assert main(["render", "other.yaml", "--policy", "run", "--episodes", "1", "--out", "videos", "--no-progress"]) == 1
    assert "drives the robots of 'hall.yaml', not 'other.yaml'" in _one_error_line(capsys)


@pytest.mark.parametrize("command", [
    ["trajectories", "{run}", "--episodes", "1", "--out", "{tmp}/trajectories"],
    ["export", "{run}", "--out", "{tmp}/policy.onnx"],
    ["export", "{run}/checkpoint/model.zip", "--out", "{tmp}/policy.onnx"],  # its own model.zip: the same checkpoint
], ids=["trajectories", "export", "export-model-zip"])  # evaluate plays it: tests/cli/test_robots_evaluate.py
def test_one_robot_commands_refuse_a_robots_checkpoint_saying_what_it_is_and_what_to_use(robots_run, tmp_path, capsys, command):
    argv = [part.format(run=robots_run, tmp=tmp_path) for part in command]
    assert main(argv) == 1
    error = _one_error_line(capsys)
    assert "is a shared robot policy (agents: robots)" in error and "crowdnav render" in error, error
    assert "do not fit" not in error
    assert not (tmp_path / "policy.onnx").exists() and not (tmp_path / "results").exists()


def test_export_refuses_a_plain_sb3_zip_in_one_line_naming_what_it_lacks(tmp_path, capsys):
    from stable_baselines3 import PPO

    PPO("MlpPolicy", "Pendulum-v1", n_steps=8, batch_size=8, device="cpu").save(tmp_path / "sb3.zip")
    assert main(["export", str(tmp_path / "sb3.zip"), "--out", str(tmp_path / "policy.onnx")]) == 1
    error = _one_error_line(capsys)
    assert "is an SB3 model .zip without crowdnav's policy.json" in error and "export the crowdnav run folder" in error


def test_render_with_a_raising_module_policy_is_one_line_and_leaves_no_video(tmp_path, capsys, importable_module):
    name = importable_module("raising_policy", "def act(observation):\n    raise RuntimeError('boom')\n")
    argv = ["render", "open_space", "--policy", f"{name}:act", "--episodes", "1", "--out", str(tmp_path / "videos"), "--no-progress"]
    assert main(argv) == 1
    assert _one_error_line(capsys) == "crowdnav: error: raising_policy:act raised RuntimeError: boom while acting (--traceback shows where)"
    assert not any((tmp_path / "videos").glob("*"))
    assert main([*argv, "--traceback"]) == 1
    assert "raise RuntimeError('boom')" in capsys.readouterr().err
