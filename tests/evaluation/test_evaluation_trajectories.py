"""Trajectory export: the tidy per-step table and TrajNet++ ndjson of recorded test episodes."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
from crowdnav.evaluation.rollout import HeldOutEpisodes
from crowdnav.evaluation.trajectories import TIDY_COLUMNS, TRACK_ID_STRIDE, tidy_table, trajnet_lines, write_trajectories

from crowdnav import CrowdNavEnv
from crowdnav.planning.scripted import StraightToGoal


def _recorded(seeds=(0, 1)):
    episodes = HeldOutEpisodes({"scenario": "open_space", "modalities": ["goal"]}, list(seeds))
    try:
        return episodes.run(StraightToGoal(), privileged=True, record=True)
    finally:
        episodes.close()


def test_recording_changes_no_outcome_or_metric():
    episodes = HeldOutEpisodes({"scenario": "open_space", "modalities": ["goal"]}, [0, 1])
    plain = episodes.run(StraightToGoal(), privileged=True)
    recorded = episodes.run(StraightToGoal(), privileged=True, record=True)
    pd.testing.assert_frame_equal(pd.DataFrame(recorded).drop(columns="frames"), pd.DataFrame(plain))


def test_tidy_table_rows_are_the_states_of_a_replayed_episode():
    episodes = _recorded()
    table = tidy_table(episodes)
    assert tuple(table.columns) == TIDY_COLUMNS
    first = table[table["test_episode"] == 0]
    steps, agents = episodes[0]["frames"]["positions"].shape
    assert len(first) == steps * agents and first["step"].max() == steps - 1
    # the same episode stepped by hand: the robot's position after step 3, a human's goal at the start
    env = CrowdNavEnv("open_space", modalities=["goal"])
    env.reset(seed=0)
    policy = StraightToGoal()
    for _ in range(3):
        env.step(policy(env.simulator))
    robot = first[(first["step"] == 3) & (first["agent"] == "robot")].iloc[0]
    assert (robot["x"], robot["y"]) == (env.simulator.robot_position.real, env.simulator.robot_position.imag)
    assert robot["time_s"] == 3 * env.simulator.dt
    assert set(first["outcome"]) == {episodes[0]["outcome"]}


def test_trajnet_lines_hold_one_scene_per_episode_and_unique_ids_and_frames(tmp_path):
    episodes = _recorded()
    lines = [json.loads(line) for line in trajnet_lines(episodes)]
    scenes = [line["scene"] for line in lines if "scene" in line]
    tracks = pd.DataFrame([line["track"] for line in lines if "track" in line])
    assert [scene["id"] for scene in scenes] == [0, 1] and scenes[1]["s"] == scenes[0]["e"] + 1
    assert scenes[1]["p"] == TRACK_ID_STRIDE
    assert not tracks.duplicated(["f", "p"]).any()
    first_robot = tracks[(tracks["p"] == 0)].sort_values("f")
    np.testing.assert_allclose(first_robot["x"], episodes[0]["frames"]["positions"][:, 0].real, atol=1e-4)
    written = write_trajectories(episodes, tmp_path / "evaluation_000")
    assert [path.suffix for path in written] == [".csv", ".ndjson"]
    assert len(pd.read_csv(written[0])) == len(tidy_table(episodes))
    assert written[1].read_text().count("\n") == len(lines)


def test_trajectories_command_replays_every_run_of_an_experiment_and_checks_the_outcomes(tmp_path_factory, tmp_path, capsys):
    import shutil

    from crowdnav.cli import main
    from tests.evaluation.evaluation_tiny import tiny_results

    results = tmp_path / "results"
    shutil.copytree(tiny_results(tmp_path_factory), results)
    assert main(["trajectories", str(results)]) == 0
    written = sorted(results.glob("*/*/trajectories/*.csv"))
    runs = sorted(results.glob("*/*/meta.json"))
    assert len(written) == len(runs) >= 4
    table = pd.read_csv(written[0])
    assert tuple(table.columns) == TIDY_COLUMNS and set(table["agent"]) >= {"robot", "human_0"}
    # a recorded outcome that the replay does not reproduce is reported, not exported
    learned = next(run.parent for run in runs if run.parent.name.startswith("seed_"))
    episodes_csv = learned / "test_episodes.csv"
    frame = pd.read_csv(episodes_csv, keep_default_na=False)
    last = frame["evaluation"] == frame["evaluation"].max()
    frame.loc[last & (frame["test_episode"] == 0), "outcome"] = "impossible"
    frame.to_csv(episodes_csv, index=False)
    assert main(["trajectories", str(learned)]) == 1
    assert "replayed outcomes differ from the recorded ones" in capsys.readouterr().err


def test_the_tidy_table_names_each_humans_group():
    episodes = HeldOutEpisodes({"scenario": "station_hall", "modalities": ["goal"]}, [0])
    try:
        table = tidy_table(episodes.run(StraightToGoal(), privileged=True, record=True))
    finally:
        episodes.close()
    groups = table[table["step"] == 0].set_index("agent")["group"]
    assert groups["robot"] == "robot" and set(groups.drop("robot")) == {"commuters", "shoppers", "friends", "talking", "meeting"}
    plain = tidy_table(_recorded())
    assert set(plain["group"]) == {"robot", "crowd"}
