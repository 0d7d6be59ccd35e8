"""Reference agents played again (crowdnav track reference NAME --agents RESULTS/CONFIGURATION --played), from a tiny trained experiment."""

from __future__ import annotations

import copy
import dataclasses
import json
from pathlib import Path

import pytest
from crowdnav.evaluation.track import TrackError, load_track
from crowdnav.evaluation.track_agents import read_agents, write_agents
from crowdnav.evaluation.track_reference import COLUMNS

from crowdnav.cli import main
from tests.evaluation.evaluation_tiny import TINY_TRAIN
from tests.evaluation.test_track_agents import COMMIT, EPISODES, _experiment, _track

PENDING = "figure4_lidar_tracker"


def _lidar(track):
    """``track`` seen through the lidar_tracker profile: the setting differs in the sensing only."""
    return dataclasses.replace(track, name=PENDING, overrides={**track.overrides, "sensors.tracker": "lidar_tracker"})


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> Path:
    """A finished 3-seed experiment in figure4's setting (2 training episodes of a tiny SAC reading humans + goal, 3 test
    episodes), its commits made clean as a published one's would be; ~10 s, once for the module. Read only: copy to change."""
    import torch
    from crowdnav.evaluation.benchmark import run_experiment
    from crowdnav.evaluation.experiment import experiment_from_mapping

    track = _track()
    document = {
        "name": "tiny", "description": "a tiny experiment in figure4's setting",
        "protocol": {"train_episodes": 2, "eval_every": 2, "test_episodes": EPISODES, "seeds": 3, "window": 2, "final_evaluations": 1},
        "defaults": {**copy.deepcopy(TINY_TRAIN), "scenario": track.scenario, "overrides": dict(track.overrides), "sensors": {},
                     "extractor": {"table_hidden": [8], "rbf_centres": 4, "lowdim_hidden": [8]}},
        "configurations": [{"name": "humans", "label": "SAC, humans + goal", "train": {"modalities": ["humans", "goal"]}}],
    }
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        report = run_experiment(experiment_from_mapping(document), tmp_path_factory.mktemp("played"), workers=1, progress=False,
                                video=False, log=lambda line: None)
    finally:
        torch.set_num_threads(threads)
    assert not report.failures, report.failures
    folder = report.folder / "humans"
    for meta_file in folder.glob("seed_*/meta.json"):
        meta = json.loads(meta_file.read_text(encoding="utf-8"))
        meta_file.write_text(json.dumps({**meta, "git_commit": COMMIT, "git_commits": [COMMIT]}), encoding="utf-8")
    return folder


def _quiet(line: str) -> None:
    pass


def test_played_on_the_tracks_own_setting_gives_the_recorded_final_evaluation_rows(trained):
    track = _track()
    recorded = read_agents(track, trained, log=_quiet)
    played = read_agents(track, trained, played=True, log=_quiet)
    assert [text for _, text in played] == [text for _, text in recorded]  # the final policy is what the final evaluation played
    for (entry, text), (before, _) in zip(played, recorded, strict=True):
        assert text.splitlines()[0] == ",".join(COLUMNS) and len(text.splitlines()) == 1 + EPISODES
        assert entry == {**before, "played": f"seed_{entry['seed']}/train/snapshots/episode_00002", "trained_setting": {}}


def test_played_through_the_lidar_tracker_every_seed_is_written_and_its_entry_and_label_say_the_trained_sensing(trained, tmp_path):
    track = _lidar(_track())
    folder = write_agents(track, [trained], tmp_path / "ref", allow_dirty=True, played=True, log=_quiet)
    entries = json.loads((folder / "reference.json").read_text(encoding="utf-8"))["entries"]
    assert [entry["name"] for entry in entries] == [f"agent_tiny_humans_seed{seed}" for seed in range(3)]
    for seed, entry in enumerate(entries):
        assert entry["trained_setting"] == {"sensors.tracker.profile": "perfect"}
        assert entry["label"] == f"SAC, humans + goal (2 training episodes, seed {seed}; trained with perfect sensing, played through lidar_tracker)"
        assert (folder / entry["file"]).read_text(encoding="utf-8").splitlines()[0] == ",".join(COLUMNS)
    perfect = [text for _, text in read_agents(_track(), trained, played=True, log=_quiet)]
    lidar = [(folder / entry["file"]).read_text(encoding="utf-8") for entry in entries]
    assert lidar != perfect  # the network read the tracker's tracks, not the simulator's people


def test_playing_again_writes_the_same_bytes_whatever_torchs_threads_and_keeps_them(trained, tmp_path):
    import torch

    track = _lidar(_track())
    first = write_agents(track, [trained], tmp_path / "a", allow_dirty=True, played=True, log=_quiet)
    threads = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        second = write_agents(track, [trained], tmp_path / "b", allow_dirty=True, played=True, log=_quiet)
    finally:
        torch.set_num_threads(threads)
    assert {path.name: path.read_bytes() for path in first.iterdir()} == {path.name: path.read_bytes() for path in second.iterdir()}
    lines: list[str] = []
    write_agents(track, [trained], tmp_path / "a", allow_dirty=True, played=True, log=lines.append)
    assert sum("kept (the same result)" in line for line in lines) == 3


def test_played_refuses_a_setting_that_differs_outside_the_sensing_in_one_line_naming_the_key(tmp_path):
    track = _lidar(_track())
    folder = _experiment(tmp_path, track, overrides={"humans.count": 7, "humans.preferred_speed": [0.5, 1.2]})
    with pytest.raises(TrackError, match=r"planned/seed_0 ran another setting than track figure4_lidar_tracker: humans.count: 7 "
                                         r"\(track 5\) \(played, only the sensing may differ: keys under sensors.\)$") as caught:
        read_agents(track, folder, played=True, log=_quiet)
    assert "\n" not in str(caught.value) and "sensors.tracker" not in str(caught.value)
    with pytest.raises(TrackError, match=r"ran another setting than track figure4_lidar_tracker: sensors.tracker.profile: \"perfect\" "
                                         r"\(track \"lidar_tracker\"\)$"):
        read_agents(track, _experiment(tmp_path / "b", _track()), log=_quiet)  # without --played the sensing must be the track's too


def test_played_refuses_an_experiment_without_the_final_policy_in_one_line(tmp_path):
    folder = _experiment(tmp_path, _track())  # recorded rows only: no snapshots to play
    with pytest.raises(TrackError, match=r"planned/seed_0: no policy saved after \d+ training episodes in .*seed_0/train \(the one its final "
                                         r"evaluation played\): --played needs the run's snapshots$"):
        read_agents(_lidar(_track()), folder, played=True, log=_quiet)


def test_the_command_plays_the_agents_on_a_track_file_through_the_lidar_tracker(trained, tmp_path, capsys):
    source = Path(load_track("figure4").source).read_text(encoding="utf-8")
    track_file = tmp_path / "short_lidar.yaml"
    track_file.write_text(source.replace("test_episodes: 100", f"test_episodes: {EPISODES}").replace("name: figure4", f"name: {PENDING}")
                          .replace("humans.preferred_speed: [0.5, 1.2]}", "humans.preferred_speed: [0.5, 1.2], sensors.tracker: lidar_tracker}"),
                          encoding="utf-8")
    out = tmp_path / "ref"
    assert main(["track", "reference", str(track_file), "--agents", str(trained), "--played", "--out", str(out), "--allow-dirty"]) == 0
    printed = capsys.readouterr().out
    assert "agent_tiny_humans_seed2 success" in printed and "played through lidar_tracker" in printed
    assert main(["track", "reference", str(track_file), "--played", "--out", str(out), "--allow-dirty"]) == 1
    err = capsys.readouterr().err
    assert "--played plays the trained policies of --agents" in err and err.count("\n") == 1
