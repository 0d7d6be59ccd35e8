"""Fuzzing of what issue 31 found fragile: damaged run folders and training configs on geometry-heavy scenarios.

Every damaged results folder is repaired, reported by name, or refused in one line by both the
leaderboard and a benchmark re-run, never a traceback or a silently wrong table; every training
config on a costly scenario either loads into an env that resets and steps, or fails in one line
naming the file. A few cases per kind run in the default suite; ``-m slow`` runs many more.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from crowdnav.agents.training.config import ConfigError, load_config
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from crowdnav import CrowdNavEnv, ScenarioError
from crowdnav.cli import main
from tests.evaluation.evaluation_tiny import tiny_results, write_tiny_experiment

TARGETS = ("*/seed_0/test_episodes.csv", "*/seed_1/training_episodes.csv", "*/seed_0/meta.json", "*/seed_1/evaluations/evaluation_000.csv",
           "*/seed_0/train/episodes.csv", "baseline_straight/baseline/test_episodes.csv", "*/seed_1/train/checkpoint/policy.json")
DAMAGES = ("delete", "truncate", "garbage_line", "empty_cell", "empty_file")
FAST = settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
LONG = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def damage(path: Path, how: str, where: int) -> None:
    """Break one file the way a kill, a full disk or a careless edit would."""
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines()
    if how == "delete":
        path.unlink()
    elif how == "truncate":
        path.write_text(text[: where % max(len(text), 1)], encoding="utf-8")
    elif how == "empty_file":
        path.write_text("", encoding="utf-8")
    elif how == "garbage_line":
        lines.insert(1 + where % max(len(lines), 1), "#@!not,a,row")
        path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    elif len(lines) > 1:  # empty_cell: one cell of a data row left empty
        row = 1 + where % (len(lines) - 1)
        cells = lines[row].split(",")
        cells[where % len(cells)] = ""
        lines[row] = ",".join(cells)
        path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def check_damaged_results(tmp_path_factory, capsys, target: str, how: str, where: int) -> None:
    root = Path(tempfile.mkdtemp(dir=tmp_path_factory.getbasetemp()))
    folder = root / "tiny"
    shutil.copytree(tiny_results(tmp_path_factory), folder)
    matches = sorted(folder.glob(target))
    assert matches, target
    damage(matches[0], how, where)
    capsys.readouterr()
    code = main(["leaderboard", str(folder), "--out", str(root / "board")])
    out, err = capsys.readouterr()
    assert code in (0, 1) and "Traceback" not in err + out
    if code == 1:
        assert err.startswith("crowdnav: error: ") and err.count("\n") == 1, err
    experiment = write_tiny_experiment(root / "tiny.yaml")
    code = main(["benchmark", str(experiment), "--out", str(root), "--executor", "serial", "--no-video", "--no-progress"])
    out, err = capsys.readouterr()
    assert "Traceback" not in err + out
    if code == 0:  # repaired or re-run: the leaderboard ranks every seed again, nothing missing
        board = (folder / "leaderboard.md").read_text(encoding="utf-8")
        assert "missing" not in board and "| LIDAR | 2 |" in board and "| closest obstacle | 2 |" in board, board
    else:
        assert err.strip().splitlines()[-1].startswith("crowdnav: error: ") or "failed" in out, (out, err)


@FAST
@given(target=st.sampled_from(TARGETS), how=st.sampled_from(DAMAGES), where=st.integers(0, 10**6))
def test_damaged_run_folders_are_repaired_reported_or_refused_in_one_line(tmp_path_factory, capsys, target, how, where):
    check_damaged_results(tmp_path_factory, capsys, target, how, where)


@pytest.mark.slow
@LONG
@given(target=st.sampled_from(TARGETS), how=st.sampled_from(DAMAGES), where=st.integers(0, 10**6))
def test_many_damaged_run_folders_are_repaired_reported_or_refused_in_one_line(tmp_path_factory, capsys, target, how, where):
    check_damaged_results(tmp_path_factory, capsys, target, how, where)


def heavy_scenario(floor_points: int, walls: int, seed: int) -> dict:
    """A 100 m x 10 m hall with a zigzag floor edge of ``floor_points`` points and ``walls`` scattered six-point walls."""
    rng = np.random.default_rng(seed)
    teeth = max(floor_points - 2, 2)
    xs = np.linspace(1, 99, teeth)
    edge = [[float(x), 1.0 + float(i % 2)] for i, x in enumerate(xs)]
    shapes = [{"points": np.clip(rng.uniform(-3, 3, (6, 2)) + rng.uniform([5, 3], [95, 8]), [1, 2.5], [99, 9]).tolist(),
               "thickness": 0.1} for _ in range(walls)]
    return {"description": "fuzzed heavy geometry", "world": {"min": [0, 0], "max": [100, 10], "points": edge + [[99.0, 9.0], [1.0, 9.0]]},
            "walls": shapes, "humans": {"count": 2, "spawn": [{"type": "rectangle", "min": [3, 8], "max": [10, 9]}],
                                        "goal": [{"type": "rectangle", "min": [80, 8], "max": [95, 9]}]},
            "robot": {"start": {"type": "points", "points": [[2.0, 8.5]]}, "goal": {"type": "points", "points": [[98.0, 8.5]]}}}


def check_heavy_config(tmp_path: Path, floor_points: int, walls: int, seed: int) -> None:
    scenario = tmp_path / "heavy.yaml"
    scenario.write_text(yaml.safe_dump(heavy_scenario(floor_points, walls, seed)), encoding="utf-8")
    config_path = tmp_path / "train.yaml"
    config_path.write_text(yaml.safe_dump({"scenario": str(scenario), "modalities": ["lidar", "goal"], "algo": "ppo"}), encoding="utf-8")
    try:
        config = load_config(config_path)
        env = CrowdNavEnv(config.scenario, modalities=config.modalities, overrides=config.overrides)
    except (ConfigError, ScenarioError) as error:
        first = str(error).splitlines()[0]  # one problem per line, each naming the file, line and field
        assert ("heavy.yaml" in first or "train.yaml" in first) and ": " in first, str(error)
        return
    observation, _ = env.reset(seed=seed)
    for _ in range(3):
        observation, reward, terminated, truncated, _ = env.step(env.action_space.sample())
        assert np.isfinite(reward) and all(np.isfinite(value).all() for value in observation.values())
        if terminated or truncated:
            break
    env.close()


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(floor_points=st.sampled_from([4, 50, 1000, 4000, 12000]), walls=st.sampled_from([0, 10, 150, 2500]), seed=st.integers(0, 99))
def test_training_configs_on_geometry_heavy_scenarios_load_and_step_or_fail_in_one_line(tmp_path, floor_points, walls, seed):
    check_heavy_config(tmp_path, floor_points, walls, seed)


@pytest.mark.slow
@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(floor_points=st.integers(4, 12000), walls=st.integers(0, 3000), seed=st.integers(0, 99))
def test_many_training_configs_on_geometry_heavy_scenarios_load_and_step_or_fail_in_one_line(tmp_path, floor_points, walls, seed):
    check_heavy_config(tmp_path, floor_points, walls, seed)
