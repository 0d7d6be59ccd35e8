"""The results folder on disk: atomic writes, and loading every finished run below a folder.

Layout (``RESULTS/<experiment>/<configuration>/<seed>/``, one folder per run)::

    experiment.yaml              the resolved experiment (protocol included), per experiment
    encoder/encoder.pt           the experiment's pre-trained LEOG encoder, if it has one
    <config>/<seed>/spec.json    what the run is (configuration, seed, training config, protocol)
    <config>/<seed>/train/       the training run (agents.train: checkpoint/, snapshots/, episodes.csv)
    <config>/<seed>/evaluations/evaluation_<k>.csv   the test episodes of evaluation k, as they finish
    <config>/<seed>/test_episodes.csv       all test episodes, one row each (written when the run is done)
    <config>/<seed>/training_episodes.csv   the training episodes' outcomes, one row each
    <config>/<seed>/meta.json    versions, git commit, resolved config, wall time, env steps; last
                                 file written, so its presence means the run is complete

Every file is written to a temporary name and renamed into place, so a file is either absent
or complete, whatever kills the process.
"""

from __future__ import annotations

import json
import os
import uuid
from collections.abc import Iterable
from pathlib import Path
from typing import Any

EXPERIMENT_FILE = "experiment.yaml"
SPEC_FILE = "spec.json"
META_FILE = "meta.json"
TEST_FILE = "test_episodes.csv"
TRAINING_FILE = "training_episodes.csv"
EVALUATIONS_DIR = "evaluations"
TRAIN_DIR = "train"
ENCODER_DIR = "encoder"


class ResultsError(ValueError):
    """A results folder that cannot be read or does not match what is asked of it."""


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` through a temporary file in the same folder and a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # a name no other process uses (mkstemp would also do, but makes the file private to its owner)
    temporary = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        with open(temporary, "x", encoding="utf-8", newline="") as file:
            file.write(text)
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
    return path


def clean_temporaries(folder: str | Path) -> list[Path]:
    """Remove the temporary files that atomic writes leave when killed before their rename; returns them.

    Only a run's own process writes in its folder (the folder is claimed), so any such file there
    is an orphan.
    """
    orphans = [path for path in Path(folder).rglob(".*.tmp") if path.is_file()]
    orphans += [path for path in Path(folder).rglob("*.csv.tmp") if path.is_file()]  # the training log's own temporary
    for path in orphans:
        path.unlink(missing_ok=True)
    return orphans


def atomic_write_json(path: str | Path, document: Any) -> Path:
    return atomic_write_text(path, json.dumps(document, indent=2, sort_keys=True, default=str) + "\n")


def atomic_write_csv(frame: Any, path: str | Path) -> Path:
    """A pandas DataFrame as CSV (no index; missing numbers as ``nan``, so empty strings stay strings), written atomically."""
    return atomic_write_text(path, frame.to_csv(index=False, lineterminator="\n", na_rep="nan"))


def read_json(path: str | Path) -> Any:
    return json.loads(Path(path).read_text(encoding="utf-8"))


def finished_runs(paths: Iterable[str | Path]) -> list[Path]:
    """Folders of the complete runs (those with meta.json) below each path, sorted; ResultsError if a path is missing.

    Runs set aside when their configuration was edited (``<run>.replaced-N``) are not results.
    """
    runs: set[Path] = set()
    for path in map(Path, paths):
        if not path.exists():
            raise ResultsError(f"{path}: no such results folder")
        if not path.is_dir():
            raise ResultsError(f"{path}: not a folder (expected a results folder written by `crowdnav benchmark`)")
        runs.update(meta.parent for meta in path.rglob(META_FILE)
                    if (meta.parent / TEST_FILE).is_file() and not any(".replaced-" in part for part in meta.parent.parts))
    return sorted(runs)


def load_results(paths: Iterable[str | Path]) -> tuple[Any, Any, list[dict[str, Any]]]:
    """(test episodes, training episodes, metas) of every finished run below ``paths``.

    The two tables are pandas DataFrames with one row per episode and the columns
    ``experiment``, ``configuration``, ``label``, ``seed`` first; ``metas`` are the runs'
    meta.json documents. ResultsError when no finished run is found.
    """
    import pandas as pd

    paths = list(paths)
    runs = finished_runs(paths)
    if not runs:
        shown = ", ".join(str(p) for p in paths)
        raise ResultsError(f"{shown}: no finished run here (no */{META_FILE} next to a {TEST_FILE}); run `crowdnav benchmark` first")
    tests, trainings, metas = [], [], []
    for run in runs:
        try:
            metas.append(read_json(run / META_FILE))
            tests.append(pd.read_csv(run / TEST_FILE, keep_default_na=False, na_values=["nan", "NaN"]))
            if (run / TRAINING_FILE).is_file():
                trainings.append(pd.read_csv(run / TRAINING_FILE))
        except (OSError, ValueError) as error:
            raise ResultsError(f"{run}: unreadable results: {error}") from None
    test_frame = pd.concat(tests, ignore_index=True)
    training_frame = pd.concat(trainings, ignore_index=True) if trainings else pd.DataFrame()
    return test_frame, training_frame, metas
