"""Reference agents on a track (crowdnav track reference NAME --agents RESULTS/CONFIGURATION), from fake experiment folders."""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import pytest
from crowdnav.evaluation.track import TrackError, load_track
from crowdnav.evaluation.track_agents import read_agents, write_agents
from crowdnav.evaluation.track_leaderboard import rank, read_entries
from crowdnav.evaluation.track_reference import COLUMNS, write_reference

from crowdnav.cli import main

EPISODES = 3
COMMIT = "0123456789abcdef0123456789abcdef01234567"
HEADER = ["experiment", "configuration", "label", "seed", "training_episodes", "training_steps", "evaluation", "test_seed", *COLUMNS[1:]]


def _track():
    return dataclasses.replace(load_track("figure4"), test_episodes=EPISODES)  # figure4's setting, 3 episodes: quick


def _write_table(path: Path, rows: list[dict]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", encoding="utf-8", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=HEADER, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)


def _straight_rows(track):
    from crowdnav.evaluation.baselines import scripted_policy
    from crowdnav.evaluation.rollout import HeldOutEpisodes

    played = HeldOutEpisodes(track.env_options(["goal"]), track.seeds)
    try:
        return played.run(scripted_policy("straight"), privileged=True)
    finally:
        played.close()


def _experiment(root: Path, track, *, seeds: int = 3, overrides=None, protocol=None, commit: str = COMMIT,
                straight: list[dict] | None = None) -> Path:
    """A finished benchmark experiment ``root/exp`` with configuration ``planned`` (two evaluations per seed)."""
    overrides = dict(track.overrides) if overrides is None else overrides
    protocol = {"seeds": seeds, "test_seed_base": track.test_seed_base, "test_episodes": track.test_episodes, "final_evaluations": 2,
                **(protocol or {})}
    config = {"scenario": track.scenario, "overrides": overrides, "modalities": ["closest_obstacle", "goal"], "shield": True, "algo": "ppo"}
    for seed in range(seeds):
        run = root / "exp" / "planned" / f"seed_{seed}"
        rows = []
        for evaluation, steps in enumerate((50_000, 100_000)):
            for test_seed in track.seeds:
                success = (test_seed + seed + evaluation) % 2 == 0  # differs between evaluations: only the last one is copied
                rows.append({"experiment": "exp", "configuration": "planned", "label": "PPO + shield, closest obstacle + goal",
                             "seed": seed, "training_episodes": 100 * (evaluation + 1), "training_steps": steps, "evaluation": evaluation,
                             "test_seed": test_seed, "outcome": "success" if success else "collision",
                             "collision_kind": "" if success else "human", "steps": 30 + test_seed, "return": 1.23456789,
                             "time_to_goal": 6.0 if success else "nan", "path_length": 5.5, "spl": 0.9, "min_human_distance": 0.3,
                             "psc": 0.5})
        _write_table(run / "test_episodes.csv", rows)
        meta = {"experiment": "exp", "configuration": "planned", "label": "PPO + shield, closest obstacle + goal", "seed": seed,
                "status": "complete", "protocol": protocol, "config": config, "git_commit": commit, "git_commits": [commit]}
        (run / "meta.json").write_text(json.dumps(meta), encoding="utf-8")
    straight = _straight_rows(track) if straight is None else straight
    _write_table(root / "exp" / "baseline_straight" / "baseline" / "test_episodes.csv",
                 [{**row, "evaluation": 0, "training_steps": 0, "training_episodes": 0} for row in straight])
    return root / "exp" / "planned"


def test_each_training_seed_is_ranked_beside_the_baselines_with_its_final_evaluation_only(tmp_path):
    track = _track()
    reference = write_reference(track, tmp_path / "ref", allow_dirty=True, log=lambda line: None)
    baselines = json.loads((reference / "reference.json").read_text())["entries"]
    folder = write_agents(track, [_experiment(tmp_path, track)], tmp_path / "ref", allow_dirty=True, log=lambda line: None)
    index = json.loads((folder / "reference.json").read_text())
    agents = index["entries"][len(baselines):]
    assert index["entries"][: len(baselines)] == baselines and [entry["name"] for entry in agents] == [
        f"agent_exp_planned_seed{seed}" for seed in range(3)]
    assert {(entry["kind"], entry["seed"], entry["experiment_commit"], entry["training_steps"]) for entry in agents} == {
        ("policy", seed, COMMIT, 100_000) for seed in range(3)}
    assert agents[0]["label"] == "PPO + shield, closest obstacle + goal (100k env steps, seed 0)"
    with open(folder / "agent_exp_planned_seed1.csv", encoding="utf-8") as file:
        rows = list(csv.DictReader(file))
    assert list(rows[0]) == list(COLUMNS) and [row["test_seed"] for row in rows] == ["0", "1", "2"]
    assert [row["outcome"] for row in rows] == ["success", "collision", "success"]  # evaluation 1's: (seed + 1 + 1) even
    assert rows[0]["return"] == "1.2346" and rows[1]["time_to_goal"] == "nan"
    board = rank(track, read_entries(track, [folder]))
    seeds = [entry for entry in board.rows if entry.kind == "policy"]
    assert len(seeds) == 3 and all(entry.reference and len(entry.outcomes) == EPISODES for entry in seeds)
    assert board.rows[0].kind == "ceiling"
    from crowdnav.evaluation.track_page import entry_frame

    assert "a reference agent ships its episodes, not its policy" in entry_frame(board, seeds[0])[1]


def test_adding_agents_again_keeps_them_and_playing_the_baselines_again_keeps_the_agents(tmp_path):
    track = _track()
    experiment = _experiment(tmp_path, track)
    folder = write_agents(track, [experiment], tmp_path / "ref", allow_dirty=True, log=lambda line: None)
    first = {path.name: path.read_bytes() for path in folder.iterdir()}
    lines: list[str] = []
    write_agents(track, [experiment], tmp_path / "ref", allow_dirty=True, log=lines.append)
    assert sum("kept (the same result)" in line for line in lines) == 3
    assert {path.name: path.read_bytes() for path in folder.iterdir()} == first
    write_reference(track, tmp_path / "ref", allow_dirty=True, log=lambda line: None)
    names = [entry["name"] for entry in json.loads((folder / "reference.json").read_text())["entries"]]
    assert names[0] == "baseline_straight" and names[-3:] == [f"agent_exp_planned_seed{seed}" for seed in range(3)]


def test_a_different_result_under_the_same_name_is_refused_unless_forced(tmp_path):
    track = _track()
    write_agents(track, [_experiment(tmp_path / "a", track)], tmp_path / "ref", allow_dirty=True, log=lambda line: None)
    other = _experiment(tmp_path / "b", track, commit="f" * 40)
    with pytest.raises(TrackError, match=r"agent_exp_planned_seed0.csv already holds a different result of agent_exp_planned_seed0 .*--force"):
        write_agents(track, [other], tmp_path / "ref", allow_dirty=True, log=lambda line: None)
    folder = write_agents(track, [other], tmp_path / "ref", allow_dirty=True, force=True, log=lambda line: None)
    with pytest.raises(TrackError, match=r"the same experiment and configuration \(agent_exp_planned_seed0\): name each once"):
        write_agents(track, [other, tmp_path / "a" / "exp" / "planned"], tmp_path / "ref", allow_dirty=True, log=lambda line: None)
    assert {entry["experiment_commit"] for entry in json.loads((folder / "reference.json").read_text())["entries"]} == {"f" * 40}


@pytest.mark.parametrize(("change", "message"), [
    ({"commit": COMMIT + "+dirty"}, r"seed_0 ran from 0123.*\+dirty: reference agents are published only from experiments run from a clean"),
    ({"seeds": 2}, r"2 training seeds; reference agents are published with at least 3"),
    ({"overrides": {"humans.count": 7, "humans.preferred_speed": [0.5, 1.2]}},
     r"planned/seed_0 ran another setting than track figure4: humans.count: 7 \(track 5\)$"),
    ({"overrides": {"humans.count": 5, "humans.preferred_speed": [0.5, 1.2], "max_steps": 100}},
     r"ran with a time limit of 100 steps; track figure4's is 150$"),
    ({"protocol": {"test_seed_base": 10}}, r"was tested on 3 episodes from seed 10; track figure4 is 3 episodes from seed 0$"),
])
def test_an_experiment_that_is_not_the_tracks_is_refused_in_one_line_naming_the_difference(tmp_path, change, message):
    track = _track()
    folder = _experiment(tmp_path, track, **change)
    with pytest.raises(TrackError, match=message) as caught:
        read_agents(track, folder, log=lambda line: None)
    assert "\n" not in str(caught.value)
    assert not (tmp_path / "ref").exists()


def test_an_unfinished_seed_or_episodes_of_another_simulator_are_refused(tmp_path):
    track = _track()
    folder = _experiment(tmp_path / "a", track)
    meta = json.loads((folder / "seed_2" / "meta.json").read_text())
    (folder / "seed_2" / "meta.json").write_text(json.dumps({**meta, "status": "running"}))
    with pytest.raises(TrackError, match=r"seed_2 is not finished"):
        read_agents(track, folder, log=lambda line: None)
    (folder / "seed_2" / "meta.json").unlink()
    with pytest.raises(TrackError, match=r"seed_2 is not finished"):
        read_agents(track, folder, log=lambda line: None)
    moved = [{**row, "steps": int(row["steps"]) + 1} for row in _straight_rows(track)]
    with pytest.raises(TrackError, match=r"its episodes are not track figure4 v1's: straight-to-goal on test seed 0 ended"):
        read_agents(track, _experiment(tmp_path / "b", track, straight=moved), log=lambda line: None)


def test_the_command_adds_the_agents_and_the_leaderboard_ranks_them(tmp_path, capsys):
    track_file = tmp_path / "short.yaml"
    source = Path(load_track("figure4").source).read_text(encoding="utf-8")
    track_file.write_text(source.replace("test_episodes: 100", f"test_episodes: {EPISODES}"), encoding="utf-8")
    track = load_track(track_file)
    experiment = _experiment(tmp_path, track)
    out = tmp_path / "ref"
    assert main(["track", "reference", str(track_file), "--agents", str(experiment), "--out", str(out), "--allow-dirty"]) == 0
    assert "agent_exp_planned_seed2 success" in capsys.readouterr().out
    assert main(["leaderboard", "--track", str(track_file), "--reference", str(out / "figure4"), "--out", str(tmp_path / "board")]) == 0
    table = (tmp_path / "board.md").read_text(encoding="utf-8")
    assert sum(line.startswith("| ") and "closest obstacle + goal (100k env steps, seed" in line for line in table.splitlines()) == 3
    assert main(["track", "reference", str(track_file), "--agents", str(tmp_path / "nothing"), "--out", str(out), "--allow-dirty"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("crowdnav: error: ") and "no seed_K folders" in err and err.count("\n") == 1


def _validation_table(run: Path, successes: dict[int, int]) -> None:
    """The table benchmarks/validation_choice.py stores beside a run: validation outcomes per evaluation point."""
    with open(run / "validation_500000_300.csv", "w", encoding="utf-8", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=["training_episodes", "episodes", "success", "collision", "out_of_bounds", "truncated"])
        writer.writeheader()
        writer.writerows({"training_episodes": point, "episodes": 300, "success": won, "collision": 300 - won, "out_of_bounds": 0,
                          "truncated": 0} for point, won in successes.items())


def test_the_snapshot_chosen_on_validation_is_published_apart_at_its_own_evaluation(tmp_path):
    track = _track()
    experiment = _experiment(tmp_path, track)
    for seed, table in enumerate(({100: 290, 200: 280}, {100: 290, 200: 290}, {100: 250, 200: 299})):  # ties go to the later
        _validation_table(experiment / f"seed_{seed}", table)
    write_agents(track, [experiment], tmp_path / "ref", allow_dirty=True, log=lambda line: None)
    folder = write_agents(track, [experiment], tmp_path / "ref", allow_dirty=True, chosen=True, log=lambda line: None)
    entries = {entry["name"]: entry for entry in json.loads((folder / "reference.json").read_text())["entries"]}
    assert sorted(entries) == sorted([*(f"agent_exp_planned_seed{seed}" for seed in range(3)),
                                      *(f"agent_exp_planned_validated_seed{seed}" for seed in range(3))])
    assert [entries[f"agent_exp_planned_validated_seed{seed}"]["validation_choice"]["kept"] for seed in range(3)] == [100, 200, 200]
    assert entries["agent_exp_planned_validated_seed0"]["label"] == (
        "PPO + shield, closest obstacle + goal (50k env steps, seed 0; the snapshot after 100 episodes, chosen on validation "
        "episodes 500,000-500,299)")
    with open(folder / "agent_exp_planned_validated_seed0.csv", encoding="utf-8") as file:
        chosen = [row["outcome"] for row in csv.DictReader(file)]
    with open(folder / "agent_exp_planned_seed0.csv", encoding="utf-8") as file:
        final = [row["outcome"] for row in csv.DictReader(file)]
    assert chosen == ["success", "collision", "success"] and final == ["collision", "success", "collision"]  # evaluation 0's, 1's


def test_choosing_on_validation_without_the_stored_table_or_with_played_is_refused_in_one_line(tmp_path, capsys):
    track = _track()
    experiment = _experiment(tmp_path, track)
    _validation_table(experiment / "seed_0", {100: 290})  # the 200-episode snapshot never validated
    with pytest.raises(TrackError, match=r"seed_0: .*validation_500000_300.csv has no validation row for the snapshot after 200 "
                                         r"episodes: run `python benchmarks/validation_choice.py .*exp --episodes 300") as caught:
        read_agents(track, experiment, chosen=True, log=lambda line: None)
    assert "\n" not in str(caught.value)
    with pytest.raises(TrackError, match="one or the other"):
        read_agents(track, experiment, chosen=True, played=True, log=lambda line: None)
    assert main(["track", "reference", "figure4", "--chosen-on-validation"]) == 1
    err = capsys.readouterr().err
    assert "--chosen-on-validation reads the runs of --agents" in err and err.count("\n") == 1
