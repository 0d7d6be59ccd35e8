"""Recorded pedestrians (crowdnav.crowd.recording): the three formats, resampling, windows and one-line errors.

Every recording here is written by the test itself (no data ships): two people at 2.5 Hz
(annotations every 10 frames, 0.4 s), person 1 walking +x at 1 m/s for 1.2 s, person 2 seen at
frames 10 and 20 only, walking +y.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from crowdnav.crowd import recording
from crowdnav.crowd.recording import RecordingError, read_recording

ROWS = [  # frame, id, x, y
    (0, 1, 0.0, 1.0), (10, 1, 0.4, 1.0), (20, 1, 0.8, 1.0), (30, 1, 1.2, 1.0),
    (10, 2, 2.0, -1.0), (20, 2, 2.0, -0.6),
]


def _obsmat(rows=ROWS) -> str:  # frame id x z y vx vz vy; z = 99 so reading the wrong column shows
    return "\n".join(f"{f:.7e}   {p:.7e}   {x:.7e}   9.9e+01   {y:.7e}   0.0e+00   0.0e+00   0.0e+00" for f, p, x, y in rows) + "\n"


def _frames(rows=ROWS) -> str:
    return "\n".join(f"{f}\t{p}\t{x}\t{y}" for f, p, x, y in rows) + "\n"


def _trajnet(rows=ROWS, fps=2.5) -> str:
    lines = [json.dumps({"scene": {"id": 0, "p": 1, "s": 0, "e": 30, "fps": fps}})]
    lines += [json.dumps({"track": {"f": f, "p": p, "x": x, "y": y}}) for f, p, x, y in sorted(ROWS)]
    return "\n".join(lines) + "\n"


@pytest.fixture
def files(tmp_path):
    paths = {"obsmat": tmp_path / "obsmat.txt", "frames": tmp_path / "biwi_eth.txt", "trajnet": tmp_path / "eth.ndjson"}
    paths["obsmat"].write_text(_obsmat())
    paths["frames"].write_text(_frames())
    paths["trajnet"].write_text(_trajnet())
    return paths


def test_the_three_formats_give_the_same_annotations_at_0_4_s(files):
    read = {kind: read_recording(path) for kind, path in files.items()}  # the format guessed from the file
    for kind, rec in read.items():
        assert np.array_equal(rec.people, [1, 1, 1, 1, 2, 2]), kind
        assert np.allclose(rec.times, [0.0, 0.4, 0.8, 1.2, 0.4, 0.8]), kind
        assert np.allclose(rec.positions, [1j, 0.4 + 1j, 0.8 + 1j, 1.2 + 1j, 2 - 1j, 2 - 0.6j]), kind  # y, never obsmat's z
    assert read_recording(files["frames"], "frames", annotation_step=0.5).duration == pytest.approx(1.5)


def test_resampling_interpolates_linearly_and_people_are_present_only_while_recorded(files):
    grid = read_recording(files["obsmat"]).resample(0.1)
    assert grid.steps == 13  # 0 .. 1.2 s
    first, second = grid.tracks
    assert (first.person, first.start, len(first.positions)) == (1, 0, 13)
    assert np.allclose(first.positions, np.arange(13) * 0.1 + 1j)  # 1 m/s along x
    assert (second.person, second.start, len(second.positions)) == (2, 4, 5)  # 0.4 .. 0.8 s, not before, not after
    assert np.allclose(second.positions, 2 + 1j * np.linspace(-1.0, -0.6, 5))
    ids, positions, present = grid.window(3, 4)  # steps 3..6
    assert ids.tolist() == [1, 2] and present[:, 0].all() and present[:, 1].tolist() == [False, True, True, True]
    assert np.isnan(positions[0, 1]) and positions[1, 1] == second.positions[0]


def test_an_episode_window_is_chosen_by_the_seed(files):
    grid = read_recording(files["obsmat"]).resample(0.1)
    starts = [grid.window_start(np.random.default_rng(seed), 5) for seed in range(40)]
    assert starts == [grid.window_start(np.random.default_rng(seed), 5) for seed in range(40)]
    assert set(starts) == set(range(9))  # every window of 5 of the 13 steps
    assert grid.window_start(np.random.default_rng(0), 50) == 0  # longer than the recording: from its start


def test_a_trajnet_file_written_by_crowdnav_reads_back_at_its_own_fps(tmp_path):
    path = tmp_path / "episode.ndjson"  # crowdnav trajectories writes consecutive frames at fps = 1 / dt
    lines = [json.dumps({"scene": {"id": 0, "p": 0, "s": 0, "e": 2, "fps": 4.0}})]
    lines += [json.dumps({"track": {"f": f, "p": p, "x": 0.1 * f, "y": float(p)}}) for f in range(3) for p in (0, 1)]
    path.write_text("\n".join(lines) + "\n")
    rec = read_recording(path)
    assert np.allclose(rec.times, [0, 0.25, 0.5, 0, 0.25, 0.5]) and np.allclose(rec.positions.real, [0, 0.1, 0.2] * 2)


@pytest.mark.parametrize(("name", "text", "message"), [
    ("a.txt", "0 1 0.0 1.0\n10 1 0.4\n", "a.txt:2: 3 columns; expected 4 numbers (frame id x y)"),
    ("a.txt", "0 1 0.0 1.0\n\n# note\n10 1 x 1.0\n", "a.txt:4: a column is not a number"),
    ("a.txt", "0 1 0.0 1.0\n10 1 nan 1.0\n", "a.txt:2: a column is not finite"),
    ("a.txt", "0.5 1 0.0 1.0\n", "a.txt:1: the frame and the id must be whole numbers"),
    ("a.txt", "0 1 0 1\n0 1 2 2\n", "person 1 has two positions at frame 0"),
    ("a.txt", "1 2 3\n", "a.txt:1: 3 columns; expected 8 (obsmat"),
    ("a.txt", "# only a comment\n", "holds no annotation"),
    ("o.txt", _obsmat()[:-1] + "\n1 2 3 4 5 6 7\n", "o.txt:7: 7 columns; expected 8 numbers (frame id x z y vx vz vy)"),
    ("t.ndjson", '{"track": {"f": 0, "p": 1, "x": 0, "y": 0}}\n[1, 2]\n', 't.ndjson:2: expected {"scene": {...}} or {"track": {...}}'),
    ("t.ndjson", '{"track": {"f": 0, "p": 1, "x": 0, "y": 0}}\n{"track": {"f": 1.5, "p": 1, "x": 0, "y": 0}}\n',
     't.ndjson:2: a track needs whole numbers "f" (frame) and "p" (person)'),
    ("t.ndjson", '{"track": {"f": 0, "p": 1, "x": 0, "y": "north"}}\n', 't.ndjson:1: a track needs finite numbers "x" and "y"'),
    ("t.ndjson", '{"scene": {"fps": 2.5}}\n{"scene": {"fps": 4}}\n', "t.ndjson:2: scene fps 4 differs"),
    ("t.ndjson", "{not json\n", "t.ndjson:1: not a JSON object"),
])
def test_a_malformed_row_is_one_line_naming_the_file_and_line(tmp_path, name, text, message):
    (tmp_path / name).write_text(text)
    with pytest.raises(RecordingError) as error:
        read_recording(name, folder=tmp_path)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_a_relative_path_cannot_leave_the_folder_of_the_file_naming_it(tmp_path):
    inner = tmp_path / "scenarios"
    inner.mkdir()
    (tmp_path / "secret.txt").write_text(_frames())
    with pytest.raises(RecordingError, match="must stay inside"):
        read_recording("../secret.txt", folder=inner)
    os.symlink(tmp_path / "secret.txt", inner / "link.txt")
    with pytest.raises(RecordingError, match="must stay inside"):
        read_recording("link.txt", folder=inner)
    assert len(read_recording(tmp_path / "secret.txt", folder=inner).people) == 6  # an absolute path is the user's own choice


def test_a_directory_a_missing_file_and_an_oversized_file_are_refused_in_one_line(tmp_path, monkeypatch):
    with pytest.raises(RecordingError, match="not a regular file"):
        read_recording(tmp_path)
    with pytest.raises(RecordingError, match="cannot read the recording"):
        read_recording(tmp_path / "missing.txt")
    (tmp_path / "big.txt").write_text(_frames())
    monkeypatch.setattr(recording, "MAX_BYTES", 20)
    with pytest.raises(RecordingError, match="more than 20 bytes"):
        read_recording(tmp_path / "big.txt")
    monkeypatch.setattr(recording, "MAX_ROWS", 3)
    monkeypatch.setattr(recording, "MAX_BYTES", 10_000)
    with pytest.raises(RecordingError, match=r"big.txt:4: more than 3 rows"):
        read_recording(tmp_path / "big.txt")
