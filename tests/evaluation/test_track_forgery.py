"""Tracks cannot be forged: a modified copy is refused, results of other episodes are never ranked, and reference
files and track fields cannot make the leaderboard read a device or write markup into its pages."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from crowdnav.evaluation.evaluate import evaluate_policy
from crowdnav.evaluation.storage import META_FILE
from crowdnav.evaluation.track import TrackError, load_track
from crowdnav.evaluation.track_leaderboard import Entry, rank, read_entries, to_markdown
from crowdnav.evaluation.track_reference import reference_csv

from crowdnav.cli import main


def _copy_of_figure4(tmp_path: Path, old: str, new: str) -> Path:
    text = Path(load_track("figure4").source).read_text(encoding="utf-8")
    assert old in text
    path = tmp_path / "figure4.yaml"
    path.write_text(text.replace(old, new), encoding="utf-8")
    return path


def _short(**changes):
    """figure4 with 3 test episodes (a quick test set), with ``changes``, as a Track object (no file, nothing checked)."""
    return dataclasses.replace(load_track("figure4"), **{"test_episodes": 3, **changes})


def test_a_copy_of_figure4_with_no_humans_is_refused_by_evaluate_in_one_line(tmp_path, capsys):
    forged = _copy_of_figure4(tmp_path, "humans.count: 5", "humans.count: 0")
    with pytest.raises(TrackError, match=r"figure4.yaml:\d+: fingerprint: 06ab28dc0bd37b19 is not this file's episodes'"):
        load_track(str(forged))
    assert main(["evaluate", "baseline:straight", "--track", str(forged), "--out", str(tmp_path / "res"), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot pass for track figure4 v1" in err
    assert not (tmp_path / "res").exists()


def test_a_shorter_copy_keeps_the_fingerprint_of_its_episodes(tmp_path):
    short = load_track(str(_copy_of_figure4(tmp_path, "test_episodes: 100", "test_episodes: 4")))
    assert short.fingerprint == load_track("figure4").fingerprint and short.seeds == [0, 1, 2, 3]


def test_results_played_on_a_forged_copy_are_not_ranked_on_the_track(tmp_path):
    """A result written from a copy with no humans that kept figure4's name, version and fingerprint (as today's main allowed)."""
    track = _short()
    forged = _short(overrides={**track.overrides, "humans.count": 0})
    evaluate_policy("baseline:straight", None, tmp_path / "res", track=forged, name="mine")
    with pytest.raises(TrackError, match=r"mine--track-figure4-v1/seeds_0-2: played 'room_furniture' with humans.count=0; track "
                                         r"figure4 v1 fixes room_furniture with humans.count=5: a modified copy") as error:
        read_entries(track, [tmp_path / "res"])
    assert "\n" not in str(error.value)
    longer = _short(time_limit_steps=1000)  # the same first episodes (and fingerprint), more time to reach the goal
    evaluate_policy("baseline:straight", None, tmp_path / "longer", track=longer, name="mine")
    with pytest.raises(TrackError, match="max_steps=1000; track figure4 v1 fixes room_furniture with max_steps=150"):
        read_entries(track, [tmp_path / "longer"])


def test_results_recording_another_fingerprint_are_refused(tmp_path):
    track = _short()
    folder = evaluate_policy("baseline:straight", None, tmp_path / "res", track=track, name="mine")
    assert rank(track, read_entries(track, [tmp_path / "res"])).challenger.name == "mine"
    meta = json.loads((folder / META_FILE).read_text())
    meta["track"]["fingerprint"] = "0123456789abcdef"
    (folder / META_FILE).write_text(json.dumps(meta))
    with pytest.raises(TrackError, match="measured on episodes of fingerprint '0123456789abcdef', and track figure4 v1's are 06ab28dc0bd37b19"):
        read_entries(track, [tmp_path / "res"])


def test_results_of_another_test_set_are_refused(tmp_path):
    evaluate_policy("baseline:straight", None, tmp_path / "res", track=_short(), name="mine")
    with pytest.raises(TrackError, match="played 3 episodes of seeds 0-2; track figure4 v1 is 4 episodes, seeds 0-3, each once"):
        read_entries(_short(test_episodes=4), [tmp_path / "res"])


@contextmanager
def _no_hang() -> Iterator[None]:
    """A read that blocks on a FIFO (as today's main did) fails the test instead of hanging it; not a timing assert."""
    def hung(*_):
        pytest.fail("hung reading a FIFO")

    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(60)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def _reference(folder: Path, track, file: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    entry = {"name": "baseline_straight", "label": "straight", "kind": "scripted, privileged", "observations": "-", "file": file}
    (folder / "reference.json").write_text(json.dumps({"track": track.identity(), "entries": [entry]}))
    return folder


def test_a_reference_index_naming_a_device_a_fifo_a_link_or_a_path_elsewhere_is_refused(tmp_path):
    track = _short()
    rows = [{"test_seed": seed, "outcome": "success", "collision_kind": "", "steps": 5, "return": 1.0, "time_to_goal": 1.0,
             "path_length": 1.0, "spl": 1.0, "min_human_distance": 1.0, "psc": 1.0} for seed in track.seeds]
    good = _reference(tmp_path / "good", track, "baseline_straight.csv")
    (good / "baseline_straight.csv").write_text(reference_csv(rows))
    assert [entry.name for entry in read_entries(track, [good])] == ["baseline_straight"]
    cases = {"../good/baseline_straight.csv": "a reference index names files of its own folder",
             "/dev/zero": "names the file '/dev/zero'; a reference index names files of its own folder",
             "fifo.csv": r"fifo.csv: not a regular file \(a FIFO, device or folder\)",
             "link.csv": "link.csv: cannot read it \\(a symbolic link, which a leaderboard does not follow\\)"}
    for name, message in cases.items():
        folder = _reference(tmp_path / name.replace("/", "_"), track, name)
        if name == "fifo.csv":
            os.mkfifo(folder / name)
        if name == "link.csv":
            (folder / name).symlink_to(good / "baseline_straight.csv")
        with _no_hang(), pytest.raises(TrackError, match=message) as error:
            read_entries(track, [folder])
        assert "\n" not in str(error.value)


def test_a_reference_table_over_the_bound_or_an_index_that_is_a_fifo_is_refused_before_reading(tmp_path, monkeypatch):
    from crowdnav.evaluation import track_leaderboard

    track = _short()
    folder = _reference(tmp_path / "big", track, "baseline_straight.csv")
    (folder / "baseline_straight.csv").write_text("test_seed,outcome\n" + "0,success\n" * 100)
    monkeypatch.setattr(track_leaderboard, "MAX_TABLE_BYTES", 1000)
    with pytest.raises(TrackError, match="baseline_straight.csv: more than 1,000 bytes"):
        read_entries(track, [folder])
    fifo = tmp_path / "fifo"
    fifo.mkdir()
    os.mkfifo(fifo / "reference.json")
    with _no_hang(), pytest.raises(TrackError, match="reference.json: not a regular file"):
        read_entries(track, [fifo])


def test_a_track_fingerprint_that_is_not_16_hex_digits_is_refused(tmp_path):
    forged = _copy_of_figure4(tmp_path, 'fingerprint: "06ab28dc0bd37b19"', 'fingerprint: "<script>alert(1)</script>"')
    with pytest.raises(TrackError, match=r"figure4.yaml.*: fingerprint: string should match pattern '\^\[0-9a-f\]\{16\}\$'"):
        load_track(str(forged))


def test_labels_and_track_fields_are_escaped_in_markdown_and_html(tmp_path):
    from crowdnav.evaluation.track_page import render_page

    track = _short(description="a | b <i>x</i>", fingerprint="<img src=x onerror=alert(1)>")
    evil = "mine | <script>alert(1)</script> `code`\nnext"
    entries = [Entry("agent_x", evil, "policy", "goal|lidar", tmp_path, {seed: "success" for seed in track.seeds}, reference=True),
               Entry("agent_y", "plain", "policy", "goal", tmp_path, {seed: "collision" for seed in track.seeds}, reference=True)]
    board = rank(track, entries)
    text = to_markdown(board)
    row = next(line for line in text.splitlines() if "mine" in line)
    assert "<" not in text and "mine \\| &lt;script&gt;alert(1)&lt;/script&gt; \\`code\\` next" in row
    assert row.replace("\\|", "").count("|") == text.splitlines()[4].count("|")  # the same columns as the header
    page = render_page(board)
    assert "<script>alert(1)" not in page and "<img src=x" not in page and "&lt;img src=x onerror=alert(1)&gt;" in page
    assert "a | b &lt;i&gt;x&lt;/i&gt;" in page
