"""Published results name only code that can be checked out: no ``+dirty`` commit under docs/results outside the archive."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from benchmarks.publish_results import facts

RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results"
ARCHIVE = RESULTS / "archive"


def test_no_published_result_names_uncommitted_code() -> None:
    dirty = [str(path.relative_to(RESULTS)) for path in sorted(RESULTS.rglob("*"))
             if path.is_file() and ARCHIVE not in path.parents and path.suffix in {".md", ".csv", ".json"}
             and "+dirty" in path.read_text(encoding="utf-8", errors="replace")]
    assert not dirty, f"results from uncommitted code (re-run from a clean commit, or archive with a README): {dirty}"


def test_every_archived_result_says_it_is_archived_in_its_title_or_first_lines() -> None:
    folders = sorted(path for path in ARCHIVE.iterdir() if path.is_dir())
    assert folders
    for folder in folders:
        head = "\n".join((folder / "README.md").read_text(encoding="utf-8").splitlines()[:5]).lower()
        assert "archive" in head, folder.name
        text = "\n".join(path.read_text(encoding="utf-8", errors="replace") for path in folder.glob("*.md"))
        assert "+dirty" not in text or "uncommitted" in text, f"{folder.name} names a +dirty commit without saying what it means"


def _finished_run(tmp_path: Path, commit: str) -> Path:
    folder = tmp_path / "tiny"
    experiment = {"protocol": {"seeds": 1, "train_episodes": 10, "eval_every": 5, "test_episodes": 2, "window": 1, "final_evaluations": 1},
                  "configurations": [{"name": "ppo", "train": {"scenario": "open_space"}}]}
    (folder / "ppo" / "seed_0").mkdir(parents=True)
    (folder / "experiment.yaml").write_text(yaml.safe_dump(experiment), encoding="utf-8")
    meta = {"configuration": "ppo", "git_commit": commit, "wall_time_s": 12.0}
    (folder / "ppo" / "seed_0" / "meta.json").write_text(json.dumps(meta), encoding="utf-8")
    return folder


def test_publish_refuses_runs_from_uncommitted_code_in_one_line(tmp_path: Path) -> None:
    with pytest.raises(SystemExit, match=r"ran from uncommitted code \(0123abc\+dirty\); re-run from a clean commit") as refused:
        facts(_finished_run(tmp_path, "0123abc+dirty"))
    assert "\n" not in str(refused.value)


def test_publish_writes_the_commit_of_runs_from_a_clean_tree(tmp_path: Path) -> None:
    assert "commit(s) 0123abc." in facts(_finished_run(tmp_path, "0123abc"))


def test_every_results_folder_is_listed_in_the_results_index() -> None:
    index = (RESULTS / "README.md").read_text(encoding="utf-8")
    folders = [path for path in RESULTS.iterdir() if path.is_dir() and path != ARCHIVE] + [p for p in ARCHIVE.iterdir() if p.is_dir()]
    unlisted = [str(f.relative_to(RESULTS)) for f in folders if f"({f.relative_to(RESULTS)}/" not in index]
    assert not unlisted, f"docs/results/README.md does not link {unlisted}"
