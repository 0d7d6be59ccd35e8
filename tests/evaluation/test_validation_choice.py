"""Early stopping on validation episodes (crowdnav.evaluation.validation_choice, benchmarks/validation_choice.py): each
run keeps the snapshot with the most validation successes (ties: the later), reports that snapshot's stored test
evaluation, stores its validation outcomes and never plays or rewrites them again; seeds that meet the test's are refused."""

from __future__ import annotations

import csv
import shutil
from collections import Counter

import pytest

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")
pytest.importorskip("torch")

from crowdnav.evaluation import validation_choice  # noqa: E402
from crowdnav.evaluation.validation_choice import choose_on_validation, summary  # noqa: E402

from tests.evaluation.evaluation_tiny import tiny_results  # noqa: E402


@pytest.fixture
def results(tmp_path_factory, tmp_path):
    """A copy of the tiny experiment's results (2 configurations x 2 seeds, evaluations after 2 and 4 episodes)."""
    folder = tmp_path / "tiny"
    shutil.copytree(tiny_results(tmp_path_factory), folder)
    return folder


def stored(path):
    with path.open(encoding="utf-8", newline="") as file:
        return list(csv.DictReader(file))


def test_each_run_keeps_its_best_validation_snapshot_and_reports_that_snapshots_test_evaluation(results):
    choices = choose_on_validation(results, episodes=3, log=lambda line: None)
    assert sorted((c.configuration, c.seed) for c in choices) == [("closest", 0), ("closest", 1), ("lidar", 0), ("lidar", 1)]
    for choice in choices:
        run = results / choice.configuration / f"seed_{choice.seed}"
        rows = stored(run / "validation_500000_3.csv")
        assert [int(row["training_episodes"]) for row in rows] == [2, 4] and all(row["episodes"] == "3" for row in rows)
        validation = {int(row["training_episodes"]): int(row["success"]) for row in rows}
        assert choice.validation == validation
        best = max(validation.values())
        assert choice.chosen == max(point for point, successes in validation.items() if successes == best)  # ties: later
        tests = Counter(row["outcome"] for row in stored(run / "test_episodes.csv") if int(row["training_episodes"]) == choice.chosen)
        assert (choice.test_successes, choice.test_episodes) == (tests["success"], sum(tests.values())) == (tests["success"], 3)
    assert "over 2 seeds at the kept snapshots" in summary(choices)


def test_stored_validation_is_reused_and_never_rewritten(results, monkeypatch):
    first = choose_on_validation(results, episodes=3, configurations=["lidar"], log=lambda line: None)
    files = {path: path.read_bytes() for path in results.glob("lidar/seed_*/validation_500000_3.csv")}
    assert len(files) == 2 and not list(results.glob("closest/seed_*/validation_*.csv"))

    def no_playing(*args, **kwargs):
        raise AssertionError("a stored snapshot was played again")

    monkeypatch.setattr(validation_choice, "_validate", no_playing)
    assert choose_on_validation(results, episodes=3, configurations=["lidar"], log=lambda line: None) == first
    assert {path: path.read_bytes() for path in files} == files


def test_the_tie_goes_to_the_later_snapshot(results, monkeypatch):
    monkeypatch.setattr(validation_choice, "_validate", lambda run, point, episodes, seed_base: Counter(success=2, collision=1))
    choices = choose_on_validation(results, episodes=3, log=lambda line: None)
    assert {choice.chosen for choice in choices} == {4}


def test_validation_seeds_that_meet_the_test_seeds_or_the_training_seeds_are_refused_in_one_line(results, tmp_path):
    with pytest.raises(ValueError, match=r"^validation seeds 0-2 meet .*'s test seeds 0-2; choose --seed-base outside them$"):
        choose_on_validation(results, episodes=3, seed_base=0, log=lambda line: None)
    with pytest.raises(ValueError, match="held-out test seeds lie below 1,000,000$"):
        choose_on_validation(results, episodes=3, seed_base=999_999, log=lambda line: None)
    with pytest.raises(ValueError, match="holds no run"):
        choose_on_validation(tmp_path / "nothing", log=lambda line: None)
    assert not list(results.glob("*/seed_*/validation_*.csv"))


def test_the_script_prints_the_table_and_refuses_bad_input_in_one_line(results, capsys):
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "validation_choice.py"
    spec = importlib.util.spec_from_file_location("validation_choice_script", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert script.main([str(results), "--episodes", "3", "--configurations", "closest"]) == 0
    out = capsys.readouterr().out
    assert out.count("| closest |") == 2 and "closest:" in out
    assert script.main([str(results), "--episodes", "3", "--seed-base", "0"]) == 2
    assert capsys.readouterr().err.startswith("error: validation seeds 0-2 meet")
