"""TrajNet++ written by ``crowdnav trajectories`` reads back as a recording (crowdnav.crowd.recording) with the same tracks."""

from __future__ import annotations

import json

import numpy as np
from crowdnav.evaluation.rollout import HeldOutEpisodes
from crowdnav.evaluation.trajectories import write_trajectories

from crowdnav.crowd.recording import read_recording
from crowdnav.planning.scripted import StraightToGoal


def test_trajnet_written_by_crowdnav_reads_back_with_the_same_tracks_times_and_positions(tmp_path):
    episodes = HeldOutEpisodes({"scenario": "open_space", "modalities": ["goal"]}, [0, 1])
    try:
        recorded = episodes.run(StraightToGoal(), privileged=True, record=True)
    finally:
        episodes.close()
    ndjson = next(path for path in write_trajectories(recorded, tmp_path / "run") if path.suffix == ".ndjson")
    tracks = [json.loads(line)["track"] for line in ndjson.read_text().splitlines() if '"track"' in line]
    recording = read_recording(ndjson)
    dt = recorded[0]["frames"]["dt"]
    assert len(recording.people) == len(tracks)
    for person in {track["p"] for track in tracks}:
        written = sorted((track["f"], track["x"], track["y"]) for track in tracks if track["p"] == person)
        mine = recording.people == person
        frames = np.array([f for f, _, _ in written])
        np.testing.assert_allclose(recording.times[mine], frames * dt, rtol=0, atol=1e-9)  # the file's fps: 1 / dt
        assert np.array_equal(recording.positions[mine], np.array([x + 1j * y for _, x, y in written]))
    grid = recording.resample(dt)
    robot = next(track for track in grid.tracks if track.person == 0)
    assert np.array_equal(robot.positions, np.round(recorded[0]["frames"]["positions"][:, 0].real, 4)
                          + 1j * np.round(recorded[0]["frames"]["positions"][:, 0].imag, 4))
