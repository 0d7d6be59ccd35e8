"""A track's leaderboard: evaluate --track results and reference results ranked, paired by McNemar's exact test; versions kept apart."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from crowdnav.evaluation.evaluate import evaluate_policy
from crowdnav.evaluation.storage import META_FILE, read_json
from crowdnav.evaluation.track import TrackError, load_track
from crowdnav.evaluation.track_leaderboard import Entry, mcnemar_exact, paired, rank, read_entries, to_markdown
from crowdnav.evaluation.track_reference import write_reference


def test_mcnemar_exact_matches_the_binomial_by_hand():
    assert mcnemar_exact(0, 0) == 1.0 and mcnemar_exact(3, 3) == 1.0
    assert mcnemar_exact(0, 5) == pytest.approx(2 / 32) and mcnemar_exact(5, 0) == mcnemar_exact(0, 5)
    assert mcnemar_exact(1, 9) == pytest.approx(2 * (1 + 10) / 2 ** 10)
    assert 0 < mcnemar_exact(0, 3000) < 1e-300 or mcnemar_exact(0, 3000) == 0.0  # thousands of episodes: no overflow


def _entry(name, outcomes, reference=True, kind="scripted, privileged"):
    return Entry(name, name, kind, "-", None, dict(enumerate(outcomes)), reference=reference)


def test_paired_statistics_use_the_shared_episodes_and_the_user_policy_is_the_challenger():
    track = load_track("figure4")
    mine = _entry("mine", ["success"] * 8 + ["collision"] * 2, reference=False)
    straight = _entry("straight", ["success"] * 2 + ["collision"] * 8)
    oracle = _entry("oracle", ["success"] * 10, kind="ceiling")
    board = rank(track, [straight, oracle, mine])
    assert [entry.name for entry in board.rows] == ["oracle", "mine", "straight"] and board.challenger is mine
    shared, delta, p = paired(mine, straight)
    assert (shared, delta, p) == (10, pytest.approx(0.6), pytest.approx(mcnemar_exact(6, 0)))
    text = to_markdown(board)
    assert f"Track figure4 v{track.version}" in text and "| ceiling | oracle" in text and "| 1 | mine *" in text and "McNemar" in text
    with pytest.raises(TrackError, match="nothing to rank on track figure4"):
        rank(track, [])


def test_an_evaluated_policy_ranks_among_the_reference_results_and_another_version_is_refused(tmp_path):
    track = load_track("figure4")
    short = track.__class__(**{**track.__dict__, "test_episodes": 6})  # the same track, fewer episodes: a quick test
    reference = write_reference(short, tmp_path / "ref", allow_dirty=True, log=lambda line: None)
    index = read_json(reference / "reference.json")
    assert {entry["name"] for entry in index["entries"]} >= {"baseline_straight", "baseline_social_force", "baseline_predictive", "baseline_oracle"}
    from crowdnav.evaluation.provenance import git_commit

    assert index["track"] == short.identity() and index["git_commit"] == git_commit()  # "+dirty" only from a dirty tree
    folder = evaluate_policy("baseline:straight", None, tmp_path / "res", track=short, name="mine")
    meta = read_json(folder / META_FILE)
    assert meta["track"] == short.identity() and meta["test_episodes"] == 6 and folder.parent.name == f"mine--track-figure4-v{short.version}"
    board = rank(short, read_entries(short, [reference, tmp_path / "res"]))
    mine = next(entry for entry in board.rows if not entry.reference)
    straight = next(entry for entry in board.rows if entry.name == "baseline_straight" and entry.reference)
    assert board.challenger is mine and mine.outcomes == straight.outcomes  # the same episodes, bit for bit
    meta["track"]["version"] = short.version + 1
    (folder / META_FILE).write_text(json.dumps(meta))
    with pytest.raises(TrackError, match=f"measured on track figure4 v{short.version + 1}, and the track is v{short.version} now"):
        read_entries(short, [reference, tmp_path / "res"])


def test_reference_results_are_resumable_and_idempotent(tmp_path):
    track = load_track("figure4")
    short = track.__class__(**{**track.__dict__, "test_episodes": 3})
    lines: list[str] = []
    folder = write_reference(short, tmp_path, allow_dirty=True, log=lines.append)
    first = {path.name: path.read_bytes() for path in folder.iterdir()}
    (folder / "baseline_social_force.csv").unlink()  # killed before this one was written
    lines.clear()
    write_reference(short, tmp_path, allow_dirty=True, log=lines.append)
    assert sum("kept" in line for line in lines) == len(first) - 2 and any("baseline_social_force success" in line for line in lines)
    assert {path.name: path.read_bytes() for path in folder.iterdir()} == first
    assert all(not math.isnan(float(line.split(",")[0])) for line in (folder / "baseline_straight.csv").read_text().splitlines()[1:])


def test_reference_results_refuse_a_checkout_with_changes(tmp_path, monkeypatch):
    import subprocess

    from crowdnav.evaluation import track_reference

    changes = [" M crowdnav/sim/simulator.py", "?? docs/results/tracks/figure4/x.csv"]

    def fake_run(command, **kwargs):
        out = "abc123\n" if command[1] == "rev-parse" else "".join(line + "\n" for line in changes)
        return subprocess.CompletedProcess(command, 0, out, "")

    monkeypatch.setattr(track_reference.subprocess, "run", fake_run)
    out = Path(track_reference.__file__).resolve().parents[1] / "docs" / "results" / "tracks"
    with pytest.raises(TrackError, match=r"uncommitted changes \(1 paths, e.g. crowdnav/sim/simulator.py\): reference results are published "
                                         "from a clean commit"):
        track_reference.source_state(out)
    changes.pop(0)  # what it writes itself is no change of the source
    assert track_reference.source_state(out) == "abc123"


def test_a_baseline_added_later_is_played_alone_and_the_published_ones_are_kept_with_their_commit(tmp_path):
    from crowdnav.evaluation.baselines import BASELINE_READS
    from crowdnav.evaluation.track_reference import REFERENCE_BASELINES

    track = load_track("figure4")
    short = track.__class__(**{**track.__dict__, "test_episodes": 3})
    older = [name for name in REFERENCE_BASELINES if name != "onboard"]
    folder = write_reference(short, tmp_path, allow_dirty=True, only=older, log=lambda line: None)
    index = folder / "reference.json"
    published = json.loads(index.read_text())
    published["git_commit"] = "0123abc"  # as if played at an older commit
    index.write_text(json.dumps(published))
    files = {path.name: path.read_bytes() for path in folder.glob("*.csv")}
    lines: list[str] = []
    write_reference(short, tmp_path, allow_dirty=True, only=["onboard"], log=lines.append)
    document = read_json(index)
    entries = {entry["name"]: entry for entry in document["entries"]}
    assert document["git_commit"] == "0123abc" and {path.name: path.read_bytes() for path in folder.glob("*.csv") if path.name in files} == files
    assert [entries[entry["name"]] for entry in published["entries"]] == published["entries"]  # the published ones, as they were
    onboard = entries["baseline_onboard"]
    assert onboard["kind"] == "scripted, onboard" and onboard["observations"] == BASELINE_READS["onboard"] and onboard["policy"] == "baseline:onboard"
    assert onboard["git_commit"] not in (None, "0123abc") and list(entries).index("baseline_onboard") == REFERENCE_BASELINES.index("onboard")
    assert sum("kept (as published at 0123abc" in line for line in lines) == len(older) and any("baseline_onboard success" in line for line in lines)
    board = rank(short, read_entries(short, [folder]))
    assert next(entry for entry in board.rows if entry.name == "baseline_onboard").kind == "scripted, onboard"
    write_reference(short, tmp_path, allow_dirty=True, log=lambda line: None)  # every baseline at this commit: no entry names its own
    document = read_json(index)
    assert document["git_commit"] == onboard["git_commit"] and not any("git_commit" in entry for entry in document["entries"])
    with pytest.raises(TrackError, match="unknown reference baseline 'onbord'"):
        write_reference(short, tmp_path, allow_dirty=True, only=["onbord"], log=lambda line: None)


def test_each_reference_baseline_is_labelled_by_what_it_reads_and_a_shield_adds_the_tracker_not_privilege(tmp_path):
    """Straight reads its pose and goal (onboard), the shield the tracker and the map: only the robot inside decides privilege."""
    track = load_track("figure4")
    short = track.__class__(**{**track.__dict__, "test_episodes": 1})
    folder = write_reference(short, tmp_path, allow_dirty=True, only=["straight", "straight_shield", "social_force", "social_force_shield"],
                             log=lambda line: None)
    entries = {entry["name"].removeprefix("baseline_"): entry for entry in read_json(folder / "reference.json")["entries"]}
    assert {name: entry["kind"] for name, entry in entries.items()} == {
        "straight": "scripted, onboard", "straight_shield": "scripted, onboard",
        "social_force": "scripted, privileged", "social_force_shield": "scripted, privileged"}
    assert entries["straight"]["observations"] == "onboard: its pose and goal"
    for shielded in ("straight_shield", "social_force_shield"):
        assert entries[shielded]["observations"].endswith("the shield: the humans its tracker reports and the map")
    assert entries["social_force"]["observations"] == "privileged: the simulator's state"


def test_the_onboard_baseline_is_refused_in_one_line_on_a_track_that_does_not_allow_its_tracker(tmp_path):
    track = load_track("robots_crossing_hall")
    lines: list[str] = []
    folder = write_reference(track, tmp_path, allow_dirty=True, only=["onboard"], log=lines.append)
    skipped = read_json(folder / "reference.json")["skipped"]
    assert [skip["name"] for skip in skipped] == ["baseline_onboard"] and "\n" not in skipped[0]["reason"]
    assert "plan is not allowed" in skipped[0]["reason"] and not (folder / "baseline_onboard.csv").exists()
    with pytest.raises(TrackError, match="plan is not allowed"):
        evaluate_policy("baseline:onboard", None, tmp_path / "res", track=track)


def test_an_evaluated_onboard_baseline_declares_what_it_reads_and_ranks_as_onboard(tmp_path):
    track = load_track("figure4")
    short = track.__class__(**{**track.__dict__, "test_episodes": 3})
    folder = evaluate_policy("baseline:onboard", None, tmp_path / "res", track=short)
    assert read_json(folder / META_FILE)["observations"] == ["plan"]
    (entry,) = read_entries(short, [tmp_path / "res"])
    assert entry.kind == "scripted, onboard" and entry.observations == "plan"


def test_shielded_baselines_are_played_with_the_shield_and_skipped_in_one_line_where_the_track_allows_no_tracker(tmp_path):
    from crowdnav.evaluation.rollout import HeldOutEpisodes

    from crowdnav.planning.scripted import StraightToGoal

    track = load_track("figure4")
    short = track.__class__(**{**track.__dict__, "test_episodes": 3})
    folder = write_reference(short, tmp_path, allow_dirty=True, only=["straight", "straight_shield"], log=lambda line: None)
    entries = {entry["name"]: entry for entry in read_json(folder / "reference.json")["entries"]}
    played = HeldOutEpisodes({**short.env_options(["goal"]), "shield": True}, short.seeds)
    try:
        outcomes = [row["outcome"] for row in played.run(StraightToGoal(), privileged=True)]
    finally:
        played.close()
    rows = (folder / entries["baseline_straight_shield"]["file"]).read_text().splitlines()[1:]
    assert [row.split(",")[1] for row in rows] == outcomes and entries["baseline_straight_shield"]["policy"] == "baseline:straight_shield"
    hall = write_reference(load_track("robots_crossing_hall"), tmp_path / "hall", allow_dirty=True, only=["social_force_shield"],
                           log=lambda line: None)
    skipped = read_json(hall / "reference.json")["skipped"]
    assert [skip["name"] for skip in skipped] == ["baseline_social_force_shield"] and "plan is not allowed" in skipped[0]["reason"]
