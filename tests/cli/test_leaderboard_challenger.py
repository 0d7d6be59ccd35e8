"""`crowdnav leaderboard --track` as docs/evaluate.md runs it: the challenger, each baseline once, Holm's adjustment, and one
line for a folder with nothing of the track."""

from __future__ import annotations

import dataclasses

import pytest
from crowdnav.evaluation import track_leaderboard as boards
from crowdnav.evaluation.evaluate import evaluate_policy
from crowdnav.evaluation.track import TrackError, load_track
from crowdnav.evaluation.track_leaderboard import Entry, mcnemar_exact, rank, table_rows

from crowdnav.cli import main


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory):
    """A 4-episode copy of figure4, its reference results, and the docs' two evaluations: a policy (here baseline:straight named
    `mine`) and baseline:social_force."""
    root = tmp_path_factory.mktemp("board")
    short = root / "short.yaml"
    short.write_text(open(load_track("figure4").source, encoding="utf-8").read().replace("test_episodes: 100", "test_episodes: 4"),
                     encoding="utf-8")
    assert main(["track", "reference", str(short), "--out", str(root / "ref"), "--allow-dirty"]) == 0
    for policy, name in (("baseline:straight", ["--name", "mine"]), ("baseline:social_force", [])):
        assert main(["evaluate", policy, "--track", str(short), *name, "--out", str(root / "res"), "--no-progress"]) == 0
    return root


def _board(root, *extra):
    return ["leaderboard", "--track", str(root / "short.yaml"), "--reference", str(root / "ref" / "figure4"), str(root / "res"),
            "--out", str(root / "board"), *extra]


def test_the_users_policy_is_the_challenger_and_an_evaluated_baseline_is_listed_once(evaluated, capsys):
    capsys.readouterr()
    assert main(_board(evaluated)) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("| ")]
    # full labels: the shielded baselines' labels start the same ("social force, privileged, + shield")
    assert sum("social force, privileged (scripted)" in row for row in rows) == 1 and sum("straight to goal (scripted)" in row for row in rows) == 1
    assert "Challenger: mine (your best entry that is not a scripted baseline" in out
    assert next(row for row in rows if "mine *" in row).count("| challenger |") == 1


def test_the_challenger_can_be_named_and_an_unknown_name_is_one_line(evaluated, capsys):
    capsys.readouterr()
    assert main(_board(evaluated, "--challenger", "baseline_social_force")) == 0
    out = capsys.readouterr().out
    assert "Challenger: social force, privileged (scripted) (named" in out
    assert "| challenger |" in next(line for line in out.splitlines() if "social force, privileged (scripted)" in line)
    assert main(_board(evaluated, "--challenger", "mien")) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no entry 'mien' on track figure4 v1's leaderboard; did you mean 'mine'?" in err


def test_the_paired_tests_carry_holms_adjustment_and_a_multiplicity_note(evaluated, capsys):
    capsys.readouterr()
    assert main(_board(evaluated)) == 0
    out = capsys.readouterr().out
    assert f"| {boards.HOLM} |" in out and "Multiple comparisons" in out and "Holm's step-down" in out
    assert boards.holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06]) and boards.holm([0.2, 0.9]) == pytest.approx([0.4, 0.9])


def test_holm_p_is_the_adjusted_mcnemar_p_of_each_row():
    track = load_track("figure4")
    mine = Entry("mine", "mine", "policy", "goal", None, {seed: "success" for seed in range(10)})
    worse = [Entry(f"b{k}", f"b{k}", "scripted, privileged", "-", None, {seed: "success" if seed < k else "collision" for seed in range(10)},
                   reference=True) for k in (2, 5, 8)]
    rows = {row["entry"]: row for row in table_rows(rank(track, [mine, *worse]))}
    raw = [mcnemar_exact(10 - k, 0) for k in (2, 5, 8)]
    assert [float(rows[f"b{k}"][boards.HOLM]) for k in (2, 5, 8)] == pytest.approx([float(f"{p:.3g}") for p in boards.holm(raw)], rel=1e-3)
    assert rows["mine *"][boards.HOLM] == "-"


def test_a_users_baseline_with_other_outcomes_than_the_reference_is_kept_and_never_beats_a_policy_as_challenger():
    track = load_track("figure4")
    reference = Entry("baseline_orca", "ORCA", "scripted, privileged", "-", None, {0: "success", 1: "collision"}, reference=True)
    again = Entry("baseline_orca", "ORCA", "scripted, privileged", "-", None, {0: "success", 1: "success"})
    same = Entry("baseline_orca", "ORCA", "scripted, privileged", "-", None, {0: "success", 1: "collision"})
    mine = Entry("mine", "mine", "policy", "goal", None, {0: "collision", 1: "collision"})
    assert len(rank(track, [reference, same]).rows) == 1
    board = rank(track, [reference, again, mine])
    assert len(board.rows) == 3 and board.challenger is mine
    with pytest.raises(TrackError, match="--challenger: no entry 'nobody'"):
        rank(track, [reference, mine], challenger="nobody")


def test_a_folder_with_no_result_of_the_track_is_one_line_and_exit_1(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert main(["leaderboard", "--track", "figure4", str(tmp_path / "empty")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "empty holds no result of track figure4 v1: evaluate a policy on it with" in err
    room = dataclasses.replace(load_track("room"), test_episodes=2)
    evaluate_policy("baseline:straight", None, tmp_path / "room", track=room)
    assert main(["leaderboard", "--track", "figure4", str(tmp_path / "room")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds no result of track figure4 v1 (it holds results of track room (1))" in err


def test_a_misspelled_baseline_gets_a_did_you_mean(tmp_path, capsys):
    assert main(["evaluate", "baseline:straigth", "--scenario", "open_space", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown baseline 'straigth'; did you mean 'baseline:straight'? expected one of: baseline:straight" in err
