"""No silent wrong rows: a run folder missing a file or holding damaged rows is named, rebuilt where what the run kept
allows it (its evaluations, snapshots and training log), never dropped or half-read; the leaderboard says when seeds are missing."""

from __future__ import annotations

import shutil

import pytest
from crowdnav.agents.runs.episode_log import HEADER
from crowdnav.evaluation.benchmark import run_experiment
from crowdnav.evaluation.experiment import experiment_from_mapping
from crowdnav.evaluation.leaderboard import write_leaderboard
from crowdnav.evaluation.storage import ResultsError, load_results, table_damage

from crowdnav.cli import main
from tests.evaluation.evaluation_tiny import tiny_experiment_document, tiny_results


@pytest.fixture
def results(tmp_path_factory, tmp_path):
    """A copy of the tiny experiment's finished results (2 configurations x 2 seeds), to damage."""
    shutil.copytree(tiny_results(tmp_path_factory), tmp_path / "results" / "tiny")
    return tmp_path / "results" / "tiny"


def _rerun(folder):
    experiment = experiment_from_mapping(tiny_experiment_document())
    report = run_experiment(experiment, folder.parent, workers=1, progress=False, video=False, log=lambda line: None)
    return report, {f"{s['configuration']}/seed_{s['seed']}": s for s in report.summaries}


def _cut_last_row(path):
    text = path.read_text()
    path.write_text(text[: len(text) - len(text.splitlines()[-1]) // 2 - 1])


def test_a_deleted_test_table_is_named_in_the_leaderboard_and_rebuilt_by_the_benchmark(results, capsys):
    original = (results / "lidar" / "seed_1" / "test_episodes.csv").read_bytes()
    (results / "lidar" / "seed_1" / "test_episodes.csv").unlink()
    with pytest.raises(ResultsError, match=r"lidar/seed_1: test_episodes.csv is missing; run `crowdnav benchmark`"):
        load_results([results])  # never read in part
    assert main(["leaderboard", str(results)]) == 0
    assert f"crowdnav: not in the leaderboard: {results / 'lidar' / 'seed_1'}: test_episodes.csv is missing" in capsys.readouterr().err
    board = (results / "leaderboard.md").read_text()
    assert "| LIDAR | 1 of 2 |" in board and "- tiny/lidar/seed_1: test_episodes.csv is missing" in board and str(results) not in board
    report, runs = _rerun(results)
    assert runs["lidar/seed_1"]["status"] == "repaired" and "test_episodes.csv is missing" in runs["lidar/seed_1"]["repairs"][0]
    assert runs["lidar/seed_0"]["status"] == "skipped" and not report.failures
    assert (results / "lidar" / "seed_1" / "test_episodes.csv").read_bytes() == original  # rebuilt from its evaluations
    assert "| LIDAR | 2 |" in (results / "leaderboard.md").read_text()


@pytest.mark.parametrize("damage", ["garbage", "cut"])
def test_a_garbage_or_cut_row_in_a_test_table_is_found_and_rebuilt(results, damage):
    table = results / "closest" / "seed_0" / "test_episodes.csv"
    original = table.read_bytes()
    if damage == "garbage":
        with open(table, "a") as file:
            file.write("tiny,closest,closest obstacle,0,4,1,2,2,flying," + ",".join(["x"] * 21) + "\n")
    else:
        _cut_last_row(table)
    problem = table_damage(table, 6)
    assert problem is not None and f"test_episodes.csv: line {8 if damage == 'garbage' else 7}" in problem
    _, runs = _rerun(results)
    assert runs["closest/seed_0"]["status"] == "repaired" and table.read_bytes() == original


def test_a_damaged_evaluation_is_evaluated_again_from_its_snapshot(results):
    run = results / "lidar" / "seed_0"
    original = (run / "test_episodes.csv").read_bytes()
    evaluation = run / "evaluations" / "evaluation_001.csv"
    _cut_last_row(evaluation)
    (run / "test_episodes.csv").unlink()
    _, runs = _rerun(results)
    repairs = runs["lidar/seed_0"]["repairs"]
    assert any("evaluation_001.csv" in note and "evaluated again from its snapshot" in note for note in repairs), repairs
    assert (run / "test_episodes.csv").read_bytes() == original  # the test episodes are deterministic
    assert evaluation.with_name("evaluation_001.csv.damaged").is_file()  # the damaged file is kept, not deleted


def test_a_damaged_training_table_is_rebuilt_from_the_training_log(results):
    table = results / "lidar" / "seed_1" / "training_episodes.csv"
    original = table.read_bytes()
    lines = table.read_text().splitlines()
    lines[1] = lines[1].rsplit(",", 1)[0] + ",12abc"  # garbage in a number's place
    table.write_text("\n".join(lines) + "\n")
    _, runs = _rerun(results)
    assert runs["lidar/seed_1"]["status"] == "repaired" and "training_episodes.csv" in runs["lidar/seed_1"]["repairs"][0]
    assert table.read_bytes() == original


@pytest.mark.parametrize("damage", ["garbage", "cut"])
def test_a_damaged_training_log_never_passes_into_the_results(results, damage):
    run = results / "closest" / "seed_1"
    log = run / "train" / "episodes.csv"
    if damage == "garbage":
        lines = log.read_text().splitlines()
        lines[2] = "1,garbage"
        log.write_text("\n".join(lines) + "\n")
    else:
        _cut_last_row(log)
    (run / "training_episodes.csv").unlink()  # the run's table must be rebuilt from the damaged log
    report, runs = _rerun(results)
    failure = next(f for f in report.failures if f["configuration"] == "closest")
    # a cut last row is set aside (a kill's routine repair), which leaves its episode without a row
    said = "line 3 is damaged ('1,garbage')" if damage == "garbage" else "no row for episode(s) [3]"
    assert f"{log}:" in failure["error"] and said in failure["error"] and "\n" not in failure["error"], failure["error"]
    assert damage == "garbage" or "cut last line" in failure["error"]
    assert not (run / "meta.json").exists() and (run / "meta.json.damaged").is_file()  # no longer a finished run
    board = (results / "leaderboard.md").read_text()
    assert "| closest obstacle | 1 of 2 |" in board and "closest/seed_1" in board and "damaged beyond repair" in board


def test_a_training_log_an_older_crowdnav_left_headerless_is_repaired(results):
    """The issue's case: killed before the header left its buffer, the next session appended rows without one."""
    run = results / "lidar" / "seed_0"
    log = run / "train" / "episodes.csv"
    log.write_text(log.read_text().removeprefix(HEADER + "\n"))
    original = (run / "training_episodes.csv").read_bytes()
    (run / "training_episodes.csv").unlink()
    _, runs = _rerun(results)
    assert runs["lidar/seed_0"]["status"] == "repaired"
    assert any("header restored" in note for note in runs["lidar/seed_0"]["repairs"])
    assert (run / "training_episodes.csv").read_bytes() == original and log.read_text().startswith(HEADER + "\n")


def test_the_leaderboard_counts_unfinished_and_missing_seeds(results):
    shutil.rmtree(results / "closest" / "seed_1")
    (results / "lidar" / "seed_1" / "meta.json").unlink()  # a run still training, or killed
    table, _ = write_leaderboard([results], results / "leaderboard")
    seeds = dict(zip(table["configuration"], zip(table["seeds"], table["seeds_expected"], strict=True), strict=True))
    assert seeds["lidar"] == (1, 2) and seeds["closest"] == (1, 2) and seeds["baseline_straight"] == (1, 1)
    board = (results / "leaderboard.md").read_text()
    assert "2 run(s) missing, not ranked" in board
    assert "closest/seed_1" in board and "not started" in board and "lidar/seed_1" in board and "not finished" in board


def test_a_baseline_whose_table_was_deleted_is_played_again(results):
    table = results / "baseline_straight" / "baseline" / "test_episodes.csv"
    original = table.read_bytes()
    table.unlink()
    _rerun(results)
    assert table.read_bytes() == original
