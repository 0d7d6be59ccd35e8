"""Hostile input through the command line on the paths that landed together (issue 36, Reliability 5):
track files (`crowdnav track check`, `evaluate --track`, `leaderboard --track`), the planners as
baselines where they must refuse, and the train config's `shield` / `residual`.

Each bad input is rc 1 with exactly one line on stderr (no traceback) and writes nothing.
"""

from __future__ import annotations

import pytest
from crowdnav.evaluation.track import load_track
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from crowdnav.cli import main

FUZZ = settings(max_examples=25, derandomize=True, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
FIGURE4 = open(load_track("figure4").source, encoding="utf-8").read()


def refused_in_one_line(capsys, argv: list[str]) -> str:
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and err.startswith("crowdnav: error: "), err
    return err


@pytest.mark.parametrize(("old", "new", "named"), [
    ("test_seed_base: 0", "test_seed_base: 999990", "test_seed_base"),  # 100 seeds reaching run seed 0's training seeds
    ("test_seed_base: 0", "test_seed_base: -1", "test_seed_base"),
    ("test_episodes: 100", "test_episodes: 1e9", "test_episodes"),
    ("version: 1", "version: true", "version"),
    ("scenario: room_furniture", "scenario: ../../scenarios/room_furniture", "scenario"),
    ("name: figure4", "name: ../evil", "name"),
    ("observations: any", "observations: [goal, telepathy]", "observations"),
    ("observations: any", "observations: []", "observations"),
    ("time_limit_steps: 150", "time_limit_steps: .nan", "time_limit_steps"),
    ("overrides: {humans.count: 5, humans.preferred_speed: [0.5, 1.2]}", "overrides: {humans.count: 1e9}", "overrides"),
    ("overrides: {humans.count: 5, humans.preferred_speed: [0.5, 1.2]}", "overrides: {humans.model: replay}", "overrides"),
    ("fingerprint: \"06ab28dc0bd37b19\"", "fingerprint: 7", "fingerprint"),
    ("description:", "colour: red\ndescription:", "colour"),
])
def test_a_damaged_track_file_is_refused_in_one_line_by_check_and_evaluate(capsys, tmp_path, old, new, named):
    assert old in FIGURE4
    track = tmp_path / "t.yaml"
    track.write_text(FIGURE4.replace(old, new), encoding="utf-8")
    assert named in refused_in_one_line(capsys, ["track", "check", str(track)])
    assert named in refused_in_one_line(capsys, ["evaluate", "baseline:straight", "--track", str(track), "--out", str(tmp_path / "r")])
    assert not (tmp_path / "r").exists()


@FUZZ
@given(st.binary(max_size=200))
def test_fuzzed_track_file_bytes_never_give_a_traceback(capsys, tmp_path_factory, data):
    track = tmp_path_factory.mktemp("track") / "t.yaml"
    track.write_bytes(data)
    refused_in_one_line(capsys, ["track", "show", str(track)])


@pytest.mark.parametrize("argv", [
    ["track", "show", "figure5"], ["track", "show", "/nonexistent/t.yaml"], ["track", "check", "."],
    ["leaderboard", "--track", "nope", "."], ["evaluate", "baseline:straight", "--track", "../figure4.yaml"],
])
def test_unknown_or_missing_tracks_are_refused_in_one_line(capsys, argv):
    refused_in_one_line(capsys, argv)


@pytest.mark.parametrize(("policy", "sets", "words"), [
    ("baseline:oracle", ["humans.see_robot=true"], "see_robot"),
    ("baseline:oracle", ["robot.kinematics=unicycle", "robot.max_angular_speed=1.0"], "holonomic"),
    ("baseline:predictive", ["robot.kinematics=unicycle", "robot.max_angular_speed=1.0"], "holonomic"),
    ("baseline:predictive", ["world.min=[-5000,-5000]", "world.max=[5000,5000]"], "limit of 1,000,000"),
    ("baseline:onboard", ["robot.kinematics=unicycle", "robot.max_angular_speed=1.0"], "holonomic"),
    ("baseline:onboard", ["world.min=[-5000,-5000]", "world.max=[5000,5000]"], "limit of 1,000,000"),
    ("baseline:oracle", ["humans.see_robot=false", "max_steps=100000"], "limit of 50,000,000"),
])
def test_planner_baselines_refuse_what_they_cannot_plan_in_one_line_and_write_nothing(capsys, tmp_path, policy, sets, words):
    argv = ["evaluate", policy, "--scenario", "open_space", "--episodes", "1", "--out", str(tmp_path / "r"), "--no-progress"]
    for item in sets:
        argv += ["--set", item]
    assert words in refused_in_one_line(capsys, argv)
    assert not list((tmp_path / "r").rglob("test_episodes.csv"))


@pytest.mark.parametrize(("lines", "named"), [
    ('shield: "yes"', "shield"), ("shield: 1", "shield"), ("shield: {horizn: 2.0}", "horizn"),
    ("shield: {horizon: true}", "horizon"), ("shield: {horizon: .nan}", "horizon"), ("shield: {cells_per_step: 9}", "cells_per_step"),
    ("residual: true", "plan"), ("residual: 1", "residual"),
])
def test_train_config_refuses_bad_shield_and_residual_before_writing_a_run(capsys, tmp_path, lines, named):
    config = tmp_path / "train.yaml"
    config.write_text(f"scenario: open_space\nmodalities: [goal]\nepisodes: 1\nout: {tmp_path / 'run'}\n{lines}\n", encoding="utf-8")
    err = refused_in_one_line(capsys, ["train", "--config", str(config)])
    assert named in err and "train.yaml" in err
    assert not (tmp_path / "run").exists()
