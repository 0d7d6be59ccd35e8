"""Trajectory export: a respawned human starts a new track, and every result or POLICY form exports its episodes."""

from __future__ import annotations

import json
import textwrap

import numpy as np
import pandas as pd
import pytest
from crowdnav.evaluation.rollout import HeldOutEpisodes
from crowdnav.evaluation.trajectories import (
    TIDY_COLUMNS,
    finished_results,
    record_policy,
    replay_evaluation,
    tidy_table,
    track_ids,
    track_stride,
    trajnet_lines,
)

from crowdnav import load_scenario
from crowdnav.cli import main

RESPAWNING = ("corridor", "perpendicular_crossing", "hotel_lobby", "station_hall")
"""Library scenarios whose humans (some groups) respawn at their goal."""
TOLERANCE = 1e-3  # m: the 4-decimal rounding of the TrajNet++ file, and float noise


def _standing_robot(sim):
    """Stand still: long episodes (the humans walk around the robot), so many respawns."""
    return np.zeros(2)


def _fastest_step(scenario: str) -> float:
    """The furthest any agent of the scenario can move in one step (m): its top speed x dt."""
    spec = load_scenario(scenario)
    factor = spec.humans.social_force.max_speed_factor
    walkers = [group.preferred_speed or spec.humans.preferred_speed for group in spec.humans.groups] or [spec.humans.preferred_speed]
    return max(spec.robot.max_speed, factor * max(float(speed[1]) for speed in walkers)) * spec.time_step


def _recorded(scenario: str, seeds=(0, 1, 2)):
    episodes = HeldOutEpisodes({"scenario": scenario, "modalities": ["goal"]}, list(seeds))
    try:
        return episodes.run(_standing_robot, privileged=True, record=True)
    finally:
        episodes.close()


@pytest.mark.parametrize("scenario", RESPAWNING)
def test_no_track_moves_further_than_max_speed_times_dt_in_the_table_or_the_trajnet_file(scenario):
    episodes = _recorded(scenario)
    bound = _fastest_step(scenario) + TOLERANCE
    table = tidy_table(episodes).sort_values(["track", "step"])
    assert table["respawned"].sum() > 0, "the scenario should have respawns in these episodes"
    step = np.hypot(table.groupby("track")["x"].diff(), table.groupby("track")["y"].diff())
    assert step.max() <= bound
    # the same agent slot does jump: those are the respawns, each the first row of its track
    by_agent = table.sort_values(["test_episode", "agent", "step"])
    jump = np.hypot(by_agent.groupby(["test_episode", "agent"])["x"].diff(), by_agent.groupby(["test_episode", "agent"])["y"].diff())
    assert (jump > bound).sum() > 0 and by_agent.loc[jump > bound, "respawned"].all()
    lines = [json.loads(line) for line in trajnet_lines(episodes)]
    tracks = pd.DataFrame([line["track"] for line in lines if "track" in line]).sort_values(["p", "f"])
    frames = tracks.groupby("p")["f"].diff().dropna()
    assert (frames == 1).all()  # a track runs on frame after frame, no gap
    assert np.hypot(tracks.groupby("p")["x"].diff(), tracks.groupby("p")["y"].diff()).max() <= bound
    assert set(tracks["p"]) == set(table["track"])


def test_a_respawn_starts_a_new_track_at_rest_and_every_track_id_is_unique():
    episodes = _recorded("corridor")
    table = tidy_table(episodes)
    assert tuple(table.columns) == TIDY_COLUMNS
    respawns = table[table["respawned"]]
    assert (respawns["agent"] != "robot").all() and (respawns[["vx", "vy"]] == 0).all().all()
    for _, row in respawns.head(5).iterrows():  # the same slot's previous row belongs to another track
        before = table[(table["test_episode"] == row["test_episode"]) & (table["agent"] == row["agent"]) & (table["step"] == row["step"] - 1)]
        assert before["track"].item() != row["track"]
    # one agent per track and one episode per track; ids follow the documented scheme
    assert (table.groupby("track")[["agent", "test_episode"]].nunique() == 1).all().all()
    first = table[table["step"] == 0]
    agent_index = first["agent"].map(lambda name: 0 if name == "robot" else int(name.split("_")[1]) + 1)
    assert (first["track"] == 1000 * first["test_episode"] + agent_index).all()


def test_the_batched_recording_counts_the_same_respawns_as_single_envs():
    def still(batch):  # a learned-policy stand-in: stacked observations -> actions
        return np.zeros((len(batch["goal"]), 2), dtype=np.float32)

    episodes = HeldOutEpisodes({"scenario": "perpendicular_crossing", "modalities": ["goal"]}, [0, 1])
    try:
        batched, single = episodes.run(still, record=True), episodes.run(still, record=True, batched=False)
    finally:
        episodes.close()
    for a, b in zip(batched, single, strict=True):
        assert a["frames"]["respawns"].max() > 0
        np.testing.assert_array_equal(a["frames"]["respawns"], b["frames"]["respawns"])
        np.testing.assert_array_equal(a["frames"]["positions"], b["frames"]["positions"])


def test_the_id_stride_grows_past_1000_tracks_without_clashes():
    steps, agents = 3, 600
    respawns = np.zeros((steps, agents - 1), dtype=np.int64)
    respawns[1:] += 1
    respawns[2:] += 1  # every human respawns at steps 1 and 2: 600 + 2 x 599 tracks
    frames = {"positions": np.zeros((steps, agents), dtype=complex), "respawns": respawns}
    episodes = [{"frames": frames, "test_episode": k} for k in (0, 1)]
    stride = track_stride(episodes)
    assert stride == 10_000
    ids = [track_ids(frames, k, stride)[0] for k in (0, 1)]
    assert len(np.unique(ids[0])) == agents + 2 * (agents - 1) and not set(ids[0].ravel()) & set(ids[1].ravel())


TOWARD_GOAL = textwrap.dedent('''
    import numpy as np

    def toward_goal(observation):
        distance, sin, cos = observation["goal"]
        return np.array([cos, sin], dtype=np.float32)
''')


@pytest.fixture
def module_on_path(importable_module):
    return importable_module("traj_policies", TOWARD_GOAL)


def test_trajectories_of_evaluate_results_replay_what_was_scored(tmp_path, module_on_path, capsys, monkeypatch):
    from stable_baselines3 import PPO

    from crowdnav import CrowdNavEnv

    monkeypatch.chdir(tmp_path)  # evaluate records where a POLICY file came from: a replay finds it from any folder
    PPO("MultiInputPolicy", CrowdNavEnv("corridor", modalities=["goal"]), n_steps=32, batch_size=16, seed=0).save("my_ppo.zip")
    for policy in ("baseline:straight", f"{module_on_path}:toward_goal", "my_ppo.zip"):
        reads = [] if policy.startswith("baseline:") else ["--modalities", "goal"]  # a baseline reads the simulator: refused
        assert main(["evaluate", policy, "--scenario", "corridor", *reads, "--episodes", "2", "--out", "results"]) == 0
    runs = finished_results(tmp_path / "results")
    assert len(runs) == 3
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")  # the relative zip path resolves where evaluate ran, not here
    # the module:function is imported again only because the command line names it (it is on sys.path here)
    assert main(["trajectories", str(tmp_path / "results"), "--import", f"{module_on_path}:toward_goal"]) == 0
    monkeypatch.chdir(tmp_path)
    for run in runs:
        table = pd.read_csv(run / "trajectories" / "evaluate.csv")
        scored = pd.read_csv(run / "test_episodes.csv")
        assert dict(zip(table["test_episode"], table["outcome"], strict=False)) == dict(zip(scored["test_episode"], scored["outcome"], strict=True))
        assert (run / "trajectories" / "evaluate.ndjson").is_file()
    # an evaluate result whose recorded outcome the replay does not reproduce is reported, not exported
    scored_csv = runs[0] / "test_episodes.csv"
    frame = pd.read_csv(scored_csv, keep_default_na=False)
    frame.loc[frame["test_episode"] == 0, "outcome"] = "impossible"
    frame.to_csv(scored_csv, index=False)
    capsys.readouterr()
    assert main(["trajectories", str(runs[0])]) == 1
    assert "replayed outcomes differ from the recorded ones" in capsys.readouterr().err


def test_trajectories_of_a_policy_are_the_episodes_evaluate_scores(tmp_path, module_on_path):
    from crowdnav.evaluation.evaluate import evaluate_policy

    policy = f"{module_on_path}:toward_goal"
    episodes = record_policy(policy, "hotel_lobby", modalities=["goal"], episodes=2, test_seed_base=5)
    folder = evaluate_policy(policy, "hotel_lobby", tmp_path / "results", modalities=["goal"], episodes=2, test_seed_base=5)
    scored = pd.read_csv(folder / "test_episodes.csv")
    assert [e["outcome"] for e in episodes] == list(scored["outcome"]) and [e["test_seed"] for e in episodes] == [5, 6]
    assert replay_evaluation(folder, imports=[policy])[0]["frames"]["positions"].tobytes() == episodes[0]["frames"]["positions"].tobytes()
    out = tmp_path / "exported"
    assert main(["trajectories", "baseline:social_force", "--scenario", "station_hall", "--episodes", "1", "--out", str(out)]) == 0
    table = pd.read_csv(out / "baseline_social_force__station_hall__seeds0-0.csv")
    assert tuple(table.columns) == TIDY_COLUMNS and table["respawned"].dtype == bool


@pytest.mark.parametrize(("argv", "message"), [
    (["baseline:straight"], "no scenario to play it on"),
    (["nowhere:at_all", "--scenario", "corridor"], "cannot import"),
    (["baseline:straight", "--scenario", "corridor", "--evaluation", "2"], "--evaluation is for results folders"),
    (["baseline:straight", "--scenario", "corridor", "--episodes", "0"], "--episodes must be at least 1"),
])
def test_bad_trajectories_arguments_are_one_line_errors(argv, message, capsys, tmp_path):
    assert main(["trajectories", *argv, "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_a_planted_trajectories_symlink_is_refused_and_nothing_is_written_through_it(tmp_path, capsys):
    from crowdnav.evaluation.evaluate import evaluate_policy

    run = evaluate_policy("baseline:straight", "open_space", tmp_path / "results", episodes=1)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (run / "trajectories").symlink_to(elsewhere, target_is_directory=True)
    assert main(["trajectories", str(run)]) == 1
    assert "outside the output folder" in capsys.readouterr().err and not any(elsewhere.iterdir())


def test_trajectories_of_other_episodes_under_the_same_name_are_refused_and_the_same_ones_kept(tmp_path, capsys):
    argv = ["trajectories", "baseline:straight", "--scenario", "open_space", "--episodes", "1", "--out", str(tmp_path)]
    assert main(argv) == 0
    files = {path: path.read_bytes() for path in tmp_path.iterdir()}
    capsys.readouterr()
    assert main(argv) == 0 and capsys.readouterr().out.count("kept") == 2  # the same episodes: kept, nothing rewritten
    assert main([*argv, "--set", "humans.count=2"]) == 1  # other episodes under this name: refused, the files as they were
    assert "exists with other episodes" in capsys.readouterr().err and {path: path.read_bytes() for path in tmp_path.iterdir()} == files
    assert main([*argv, "--set", "humans.count=2", "--force"]) == 0
    assert {path: path.read_bytes() for path in tmp_path.iterdir()} != files and len(list(tmp_path.iterdir())) == 2
