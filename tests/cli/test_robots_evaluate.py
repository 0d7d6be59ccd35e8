"""`crowdnav evaluate` with a shared robot policy (`crowdnav train --agents robots`): on its scenario every robot is driven by
the network, one row per robot per test episode (the rows an experiment writes), ranked by `crowdnav leaderboard`; on the
robots_crossing_hall track it drives the first robot, the others social-force robots, as the track defines, and is ranked
against the track's reference rows; what would change its robots or what its network reads is refused in one line."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from crowdnav.cli import main
from tests.cli.conftest import HALL

pytest.importorskip("torch")

ROBOTS = ["east_bound", "west_bound", "north_bound"]


def _evaluate(policy: Path, out: Path, *options: str) -> int:
    return main(["evaluate", str(policy), "--scenario", HALL, "--episodes", "2", "--out", str(out), "--no-progress", *options])


def _result(out: Path) -> tuple[dict, list[dict[str, str]]]:
    """(meta.json, rows of test_episodes.csv) of the one result under ``out``."""
    (meta,) = out.glob("evaluate/*/seeds_*/meta.json")
    with open(meta.with_name("test_episodes.csv"), encoding="utf-8", newline="") as file:
        return json.loads(meta.read_text(encoding="utf-8")), list(csv.DictReader(file))


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    return err


def _same(text: str, value) -> bool:
    """A CSV cell is ``value`` exactly (floats are written at full precision: repr round-trips)."""
    if isinstance(value, str):
        return text == value
    number = float(text)
    return (math.isnan(number) and math.isnan(value)) or number == value


def test_evaluate_plays_every_robot_one_row_per_robot_per_episode_as_robot_episodes_gives_them(robots_run, tmp_path, capsys):
    from crowdnav.agents.marl.robots import load_robots_policy
    from crowdnav.evaluation.robot_rollout import RobotEpisodes

    assert _evaluate(robots_run, tmp_path) == 0, capsys.readouterr().err
    assert "on 2 test episodes x 3 robots (east_bound, west_bound, north_bound)" in capsys.readouterr().out
    meta, rows = _result(tmp_path)
    policy = load_robots_policy(robots_run)
    episodes = RobotEpisodes(policy.env_options, [0, 1])
    try:
        expected = episodes.run(policy)
    finally:
        episodes.close()
    assert [(row["test_seed"], row["robot"]) for row in rows] == [(str(seed), robot) for seed in (0, 1) for robot in ROBOTS]
    assert len(rows) == len(expected)
    for row, want in zip(rows, expected, strict=True):  # bit for bit, every column
        assert all(_same(row[key], value) for key, value in want.items()), (row, want)
        assert (row["experiment"], row["seed"], row["evaluation"], row["training_episodes"]) == ("evaluate", "0", "0", "0")
    # the meta an experiment's robots rows carry: rows counted, robot steps, the env that played them (robots-only)
    assert meta["test_episodes"] == 6 and meta["env_steps"]["test"] == sum(int(row["steps"]) for row in rows)
    assert meta["env"]["agents"] == "robots" and meta["env"]["overrides"] == {"max_steps": 20} and meta["robots"] == ROBOTS
    assert meta["observations"] == ["goal", "lidar"]
    assert meta["final"]["success"] == sum(row["outcome"] == "success" for row in rows) / 6


def test_the_leaderboard_ranks_the_robot_rows_as_test_episodes_and_breaks_them_down_per_robot(robots_run, tmp_path, capsys):
    assert _evaluate(robots_run, tmp_path) == 0
    assert main(["leaderboard", str(tmp_path)]) == 0, capsys.readouterr().err
    with open(tmp_path / "leaderboard.csv", encoding="utf-8") as file:
        (ranked,) = list(csv.DictReader(file))
    assert ranked["configuration"] == "run--robots_crossing_hall" and ranked["test_episodes"] == "2"  # episodes, not robot rows
    with open(tmp_path / "leaderboard_robots.csv", encoding="utf-8") as file:
        per_robot = list(csv.DictReader(file))
    assert sorted(row["robot"] for row in per_robot) == sorted(ROBOTS) and {row["episodes"] for row in per_robot} == {"2"}


def test_a_set_that_leaves_what_the_network_reads_alone_is_played_and_recorded(robots_run, tmp_path, capsys):
    assert _evaluate(robots_run, tmp_path, "--set", "max_steps=3", "--set", "humans.count=2") == 0, capsys.readouterr().err
    meta, rows = _result(tmp_path)
    assert meta["env"]["overrides"] == {"max_steps": 3, "humans.count": 2}
    assert len(rows) == 6 and all(int(row["steps"]) <= 3 for row in rows)


@pytest.mark.parametrize(("options", "refusal"), [
    (["--modalities", "goal"], "--modalities goal: {run} reads the observation keys it was trained on (lidar,goal); leave --modalities out"),
    (["--set", "sensors.lidar.beams=32"], "--set sensors.lidar.beams: {run} was trained on 19 observation values per robot, these "
                                          "settings give 35 ({{goal: (3,), lidar: (32,)}}); its network takes only what it was trained on"),
    (["--set", "world.max=[8,6]"], "--set world.max: {run} was trained on goal scaled otherwise than these settings give"),
    (["--scenario", "open_space"], "--scenario open_space: {run} drives the robots of 'robots_crossing_hall' "
                                   "(east_bound, west_bound, north_bound), not those of 'open_space' (robot)"),
], ids=["modalities", "sensor-size", "scales", "another-scenario"])
def test_what_changes_its_robots_or_what_its_network_reads_is_refused_in_one_line(robots_run, tmp_path, capsys, options, refusal):
    assert _evaluate(robots_run, tmp_path, *options) == 1
    assert refusal.format(run=robots_run) in _one_error_line(capsys)
    assert not (tmp_path / "evaluate").exists()


def test_a_track_of_another_scenario_is_refused_in_one_line(robots_run, tmp_path, capsys):
    assert main(["evaluate", str(robots_run), "--track", "figure4", "--out", str(tmp_path), "--no-progress"]) == 1
    assert f"--track figure4: {robots_run} drives the robots of 'robots_crossing_hall'" in _one_error_line(capsys)
    assert not (tmp_path / "evaluate").exists()


def test_on_the_robots_track_it_drives_the_first_robot_and_is_ranked_against_the_reference(robots_run, tmp_path, capsys, monkeypatch):
    """The track's 100 episodes take too long here: a copy cut to 3 episodes (the same name, version and fingerprint: the
    same first episodes), its reference played by `crowdnav track reference`, as the published one was."""
    from crowdnav.evaluation.track import load_track

    short = tmp_path / "short.yaml"
    short.write_text(Path(load_track(HALL).source).read_text(encoding="utf-8").replace("test_episodes: 100", "test_episodes: 3"),
                     encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    assert main(["track", "reference", str(short), "--out", "ref", "--allow-dirty", "--baseline", "straight"]) == 0
    capsys.readouterr()
    assert main(["evaluate", str(robots_run), "--track", str(short), "--out", "res", "--no-progress"]) == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    assert f"on 3 test episodes (it drives east_bound) of track {HALL} v1" in printed
    meta, rows = _result(tmp_path / "res")
    # the track's rows: one per episode (the first robot's), its time limit, with no robot column, as the reference's
    assert [row["test_seed"] for row in rows] == ["0", "1", "2"] and "robot" not in rows[0]
    assert meta["robots"] == ["east_bound"] and meta["track"]["name"] == HALL and "agents" not in meta["env"]
    assert meta["env"]["overrides"] == {"max_steps": 150} and meta["env"]["sensors"] == {"lidar": {"beams": 16}}
    assert main(["leaderboard", "--track", str(short), "--reference", f"ref/{HALL}", "res"]) == 0, capsys.readouterr().err
    board = capsys.readouterr().out
    assert "| run * | policy | goal, lidar |" in board and "straight to goal (scripted)" in board and "Challenger: run" in board


def test_the_first_robot_acts_as_the_shared_policy_acts_for_it(robots_run):
    """What the track plays: the Gymnasium env's Dict observation, flattened, scaled and one-hot, gives robot 0's action."""
    from crowdnav.agents.marl.env import robots_env
    from crowdnav.agents.marl.robots import load_robots_policy
    from crowdnav.evaluation.robot_rollout import FirstRobot

    from crowdnav.envs import CrowdNavEnv

    policy = load_robots_policy(robots_run)
    single, several = CrowdNavEnv(**policy.env_options), robots_env(policy.env_options)
    try:
        first = FirstRobot(policy, single.observation_space)
        for seed in (0, 3):
            observation, _ = single.reset(seed=seed)
            observations, infos = several.reset(seed=seed)
            action = first({key: value[None] for key, value in observation.items()})
            # robot 0's input row of the robots env, through the network alone: the same bits (a batch of 3 rows may round apart)
            alone, _ = policy.network.predict(policy.inputs(observations, infos)[:1], deterministic=True)
            assert action.shape == (1, 2) and np.array_equal(action, alone)
            assert np.allclose(action[0], policy.act(observations, infos)["east_bound"], atol=1e-6)
    finally:
        single.close()
        several.close()


def test_load_policy_from_python_still_refuses_it_in_one_line_naming_load_robots_policy(robots_run):
    from crowdnav.agents import load_policy
    from crowdnav.agents.runs.checkpoint import SharedRobotPolicyError

    with pytest.raises(SharedRobotPolicyError) as refused:
        load_policy(robots_run)
    message = str(refused.value)
    assert "\n" not in message and "crowdnav.agents.load_robots_policy" in message and "crowdnav evaluate" in message
