"""The results folder on disk: its layout, atomic writes, and loading every finished run below a folder.

Layout (``RESULTS/<experiment>/<configuration>/<run>/``, one folder per run; ``<run>`` is
``seed_<s>`` for a benchmark run, ``baseline`` for a scripted baseline and ``seeds_<a>-<b>``
for ``crowdnav evaluate``)::

    experiment.yaml              the resolved experiment (protocol included), per experiment
    encoder/encoder.pt           the experiment's pre-trained LEOG encoder, if it has one
    <config>/<seed>/spec.json    what the run is (configuration, seed, training config, protocol)
    <config>/<seed>/train/       the training run (crowdnav.agents.train: checkpoint/, snapshots/, episodes.csv)
    <config>/<seed>/evaluations/evaluation_<k>.csv   the test episodes of evaluation k, as they finish
    <config>/<seed>/test_episodes.csv       all test episodes, one row each (written when the run is done)
    <config>/<seed>/training_episodes.csv   the training episodes' outcomes, one row each
    <config>/<seed>/meta.json    versions, git commit, resolved config, wall time, env steps; last
                                 file written, so its presence means the run is complete

This module is the one place that knows the layout: code elsewhere builds and reads folders
through :func:`run_folder`, :func:`experiment_of`, :func:`relative_run_path` and the names below,
never by position (``parents[2]``).

Every file is written to a temporary name and renamed into place, so a file is either absent
or complete, whatever kills the process. A ``crowdnav evaluate`` result is written whole: its
files go to a hidden sibling folder (:func:`crowdnav.files.staging_beside`) that takes the run's place
in one step, under a lock only one writer holds (:func:`result_lock`, :func:`install_result`). Folders whose
name starts with ``.`` below a results folder are never results.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable, Iterable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from crowdnav import files
from crowdnav.errors import CrowdNavError

EXPERIMENT_FILE = "experiment.yaml"
SPEC_FILE = "spec.json"
META_FILE = "meta.json"
TEST_FILE = "test_episodes.csv"
TRAINING_FILE = "training_episodes.csv"
EVALUATIONS_DIR = "evaluations"
TRAIN_DIR = "train"
ENCODER_DIR = "encoder"
ENCODER_FILE = "encoder.pt"
SEED_PREFIX = "seed_"
"""A benchmark run's folder is ``seed_<s>`` in its configuration's folder."""
BASELINE_RUN = "baseline"
"""A scripted baseline's one run folder in its configuration's folder."""


def experiment_folder(results_dir: str | Path, experiment: str) -> Path:
    """``RESULTS/<experiment>``: where an experiment's runs, experiment.yaml and encoder live."""
    return Path(results_dir) / experiment


def run_name(configuration: str, seed: int) -> str:
    """``<configuration>/seed_<s>``: a benchmark run's folder relative to its experiment's, as messages name runs."""
    return f"{configuration}/{SEED_PREFIX}{seed}"


def run_folder(experiment_dir: str | Path, configuration: str, seed: int) -> Path:
    """The folder of run ``seed`` of ``configuration`` in the experiment folder ``experiment_dir``."""
    return Path(experiment_dir) / run_name(configuration, seed)


def baseline_folder(experiment_dir: str | Path, configuration: str) -> Path:
    """The folder of scripted baseline ``configuration``'s one run in the experiment folder ``experiment_dir``."""
    return Path(experiment_dir) / configuration / BASELINE_RUN


def evaluated_run_name(configuration: str, first_seed: int, last_seed: int) -> str:
    """``<configuration>/seeds_<first>-<last>``: a ``crowdnav evaluate`` result relative to its experiment folder."""
    return f"{configuration}/seeds_{first_seed}-{last_seed}"


def experiment_of(run_dir: str | Path) -> Path:
    """The experiment folder a run folder (``<experiment>/<configuration>/<run>``) lies in."""
    return Path(run_dir).parent.parent


def results_root_of(run_dir: str | Path) -> Path:
    """The results folder a run folder lies in (the parent of its experiment folder)."""
    return experiment_of(run_dir).parent


def relative_run_path(run_dir: str | Path) -> Path:
    """``<experiment>/<configuration>/<run>``: a run folder relative to its results folder."""
    return Path(*Path(run_dir).parts[-3:])


def encoder_folder(experiment_dir: str | Path) -> Path:
    """The folder of an experiment's pre-trained LEOG encoder (written whole, through a rename)."""
    return Path(experiment_dir) / ENCODER_DIR


def pretrained_encoder_path(experiment_dir: str | Path) -> Path:
    """Where an experiment's pre-trained LEOG encoder is kept."""
    return encoder_folder(experiment_dir) / ENCODER_FILE


STRING_COLUMNS = frozenset({"experiment", "configuration", "label", "outcome", "collision_kind", "robot"})
"""The text columns of the result tables; every other column holds numbers (``nan`` and ``inf`` included)."""
INTEGER_COLUMNS = frozenset({"seed", "training_episodes", "training_steps", "evaluation", "test_episode", "test_seed", "steps",
                             "episode", "episode_seed", "length", "timesteps"})
REBUILD = "run `crowdnav benchmark` on its experiment again: it rebuilds the run's tables from what the run kept"


class ResultsError(CrowdNavError, ValueError):
    """A results folder that cannot be read or does not match what is asked of it."""


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` through a temporary file in the same folder and a rename (a link at ``path`` is replaced)."""
    return files.atomic_write_text(path, text)


def clean_temporaries(folder: str | Path) -> list[Path]:
    """Remove the temporary files that atomic writes leave when killed before their rename; returns them.

    Only a run's own process writes in its folder (the folder is claimed), so any such file there
    is an orphan.
    """
    # the helpers' ``.<name>.<pid>.<hex>.tmp<suffix>`` (a video's ends in ``.tmp.mp4``), and older crowdnavs' ``.<name>.tmp``
    orphans = [path for path in Path(folder).rglob(".*") if path.is_file() and (files.is_temporary(path.name) or path.name.endswith(".tmp"))]
    orphans += [path for path in Path(folder).rglob("*.csv.tmp") if path.is_file()]  # the training log's own temporary
    for path in orphans:
        path.unlink(missing_ok=True)
    return orphans


def atomic_write_json(path: str | Path, document: Any) -> Path:
    return atomic_write_text(path, json.dumps(document, indent=2, sort_keys=True, default=str) + "\n")


def atomic_write_csv(frame: Any, path: str | Path) -> Path:
    """A pandas DataFrame as CSV (no index; missing numbers as ``nan``, so empty strings stay strings), written atomically."""
    return atomic_write_text(path, frame.to_csv(index=False, lineterminator="\n", na_rep="nan"))


@contextmanager
def result_lock(folder: str | Path) -> Iterator[None]:
    """Hold the writer lock of the result folder ``folder`` (one writer at a time) and tidy what a killed writer left.

    The lock is a sibling file, ``.<name>.lock`` (the folder itself is replaced whole), held with the
    OS's ``flock`` and removed on release: a second writer gets
    :class:`crowdnav.files.RunBusyError` at once, one line naming the folder and the
    holder's PID. Once held, a replaced result a killed writer left aside is put back and unfinished
    new ones are removed (:func:`install_result`, :func:`crowdnav.files.recover_folder`). Folders made
    for the lock and left empty are removed.
    """
    folder = Path(folder)
    made = [parent for parent in (folder.parent, *folder.parent.parents) if not parent.exists()]

    def busy(holder: str) -> str:
        return f"{folder} is being written by another process (PID {holder}); one writer at a time: wait for it to finish, " \
               "or write to another --out"

    with ExitStack() as stack:
        for attempt in range(10):
            folder.parent.mkdir(parents=True, exist_ok=True)
            try:  # another writer's empty folder may vanish between the mkdir and the lock: make it again
                stack.enter_context(files.hold_lock(folder.parent / f".{folder.name}.lock", busy, remove=True))
                break
            except FileNotFoundError:
                if attempt == 9:
                    raise
        try:
            files.recover_folder(folder)  # killed between the two renames of a replacement: the old result, whole, goes back
            yield
        finally:
            stack.close()  # the lock file goes first, then the folders made for it, if nothing else is in them
            for parent in made:
                try:
                    parent.rmdir()
                except OSError:
                    break


def install_result(folder: str | Path, write: Callable[[Path], object]) -> Path:
    """Write a result whole: ``write(staging)`` fills a hidden sibling folder, which then replaces ``folder`` in one step.

    Call it under :func:`result_lock`. Readers see the old folder or the new one, never a mix
    (:func:`crowdnav.files.swap_folder`: one exchange of the two folders where the system has it,
    else the old one is renamed aside first and put back by the next :func:`result_lock` if the
    process dies between the two renames).
    """
    folder = Path(folder)
    staging = files.staging_beside(folder)
    try:
        write(staging)
        files.swap_folder(staging, folder)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return folder


def write_result(folder: Path, tests: Any, meta: dict[str, Any]) -> None:
    """A finished result's two files in ``folder``: the test episodes (a DataFrame), then meta.json."""
    atomic_write_csv(tests, folder / TEST_FILE)
    atomic_write_json(folder / META_FILE, meta)


def read_json(path: str | Path) -> Any:
    return json.loads(Path(path).read_text(encoding="utf-8"))


def table_damage(path: str | Path, rows: int, fixed: dict[str, Any] | None = None) -> str | None:
    """What is wrong with the result table ``path`` (None: nothing): missing, unreadable, a cut or garbage row, a wrong count.

    Every row must have the header's number of cells, a known ``outcome``, whole numbers in
    :data:`INTEGER_COLUMNS`, numbers in every column not in :data:`STRING_COLUMNS`, and the values
    of ``fixed`` (``{"seed": 1}``: the run's own); the table must hold exactly ``rows`` rows.
    """
    import csv
    import math

    from crowdnav.sim.simulator import OUTCOMES

    path = Path(path)
    if not path.is_file():
        return f"{path.name} is missing"
    try:
        with open(path, encoding="utf-8", newline="") as file:
            table = list(csv.reader(file))
    except (OSError, UnicodeDecodeError, csv.Error) as error:
        return f"{path.name} is unreadable ({type(error).__name__})"
    if not table:
        return f"{path.name} is empty"
    header, body = table[0], table[1:]
    fixed = {column: str(value) for column, value in (fixed or {}).items()}
    absent = [column for column in ("outcome", *fixed) if column not in header]
    if absent:
        return f"{path.name} has no column {absent[0]!r}"
    for number, cells in enumerate(body, start=2):
        if len(cells) != len(header):
            return f"{path.name}: line {number} has {len(cells)} of {len(header)} cells (cut short or garbage)"
        for column, cell in zip(header, cells, strict=True):
            if column == "outcome" and cell not in OUTCOMES:
                return f"{path.name}: line {number} has outcome {cell[:30]!r}"
            if column in fixed and cell != fixed[column]:
                return f"{path.name}: line {number} has {column} {cell[:30]!r}, not this run's {fixed[column]}"
            if column in STRING_COLUMNS:
                continue
            try:
                value = float(cell)
            except ValueError:
                return f"{path.name}: line {number} has {column} {cell[:30]!r}, not a number"
            if column in INTEGER_COLUMNS and math.isfinite(value) and value != int(value):
                return f"{path.name}: line {number} has {column} {cell[:30]!r}, not a whole number"
    if len(body) != rows:
        return f"{path.name} holds {len(body)} rows, {rows} expected"
    return None


def run_damage(run: str | Path, meta: dict[str, Any]) -> list[str]:
    """What is wrong with the tables of the finished run ``run`` whose meta.json is ``meta`` (empty: nothing)."""
    run = Path(run)
    fixed = {"experiment": meta["experiment"], "configuration": meta["configuration"], "seed": meta["seed"]}
    rows = int(meta["test_episodes"])
    if meta.get("kind") == "baseline":  # one deterministic play, its rows repeated at every evaluation point
        from crowdnav.evaluation.protocol import Protocol

        rows *= Protocol(**meta["protocol"]).evaluations
    damage = [table_damage(run / TEST_FILE, rows, fixed)]
    if int(meta.get("training_episodes", 0)) > 0:  # learned runs; baselines and evaluated policies do not train
        damage.append(table_damage(run / TRAINING_FILE, int(meta["training_episodes"]), fixed))
    return [problem for problem in damage if problem is not None]


@dataclass(frozen=True)
class MissingRun:
    """A run the results should hold and do not, or hold damaged: named in the leaderboard's notes."""

    experiment: str
    configuration: str
    seed: int
    folder: Path
    reason: str

    def describe(self, folder: bool = False) -> str:
        """``experiment/configuration/seed_N: reason`` (the same for the same results: no paths), or with the run's ``folder``."""
        return f"{self.folder if folder else f'{self.experiment}/{run_name(self.configuration, self.seed)}'}: {self.reason}"


def finished_runs(paths: Iterable[str | Path]) -> list[Path]:
    """Folders of the complete runs (those with meta.json) below each path, sorted; ResultsError if a path is missing.

    Runs set aside when their configuration was edited (``<run>.replaced-N``) are not results.
    A complete run whose tables are missing or damaged is listed too: :func:`load_results`
    refuses it by name (or reports it, with ``missing``).
    """
    runs: set[Path] = set()
    for path in map(Path, paths):
        if not path.exists():
            raise ResultsError(f"{path}: no such results folder")
        if not path.is_dir():
            raise ResultsError(f"{path}: not a folder (expected a results folder written by `crowdnav benchmark`)")
        runs.update(meta.parent for meta in path.rglob(META_FILE) if not is_set_aside(meta.parent, path))
    return sorted(runs)


def is_set_aside(run: Path, root: Path) -> bool:
    """True for a folder below ``root`` that is not a result: a run set aside (``.replaced-N``), or a hidden
    one (a name starting with ``.``: a result being written, or one being replaced)."""
    parts = run.relative_to(root).parts
    return any(".replaced-" in part or part.startswith(".") for part in parts)


def expected_runs(paths: Iterable[str | Path]) -> dict[tuple[str, str, int], Path]:
    """(experiment, configuration, seed) -> folder of every run the experiments below ``paths`` plan (their experiment.yaml)."""
    import yaml

    planned: dict[tuple[str, str, int], Path] = {}
    for path in map(Path, paths):
        records = [path / EXPERIMENT_FILE] if (path / EXPERIMENT_FILE).is_file() else []
        for record in records + sorted(path.rglob(f"*/{EXPERIMENT_FILE}")):
            try:
                experiment = yaml.safe_load(record.read_text(encoding="utf-8"))
                name, seeds = experiment["name"], int(experiment["protocol"]["seeds"])
                names = [configuration["name"] for configuration in experiment["configurations"]]
            except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError, ValueError):
                raise ResultsError(f"{record}: unreadable experiment record; restore it or run the benchmark again") from None
            for configuration in names:
                for seed in range(seeds):
                    planned[(name, configuration, seed)] = run_folder(record.parent, configuration, seed)
    return planned


def load_results(paths: Iterable[str | Path], missing: list[MissingRun] | None = None) -> tuple[Any, Any, list[dict[str, Any]]]:
    """(test episodes, training episodes, metas) of every finished run below ``paths``.

    The two tables are pandas DataFrames with one row per episode and the columns
    ``experiment``, ``configuration``, ``label``, ``seed`` first; ``metas`` are the runs'
    meta.json documents. ResultsError when no finished run is found.

    A finished run whose tables are missing or damaged (:func:`run_damage`) is never read in
    part: ResultsError names it, or, with a ``missing`` list, it is left out and added to the
    list together with every run an experiment below ``paths`` plans and has not finished.
    """
    import pandas as pd

    paths = list(paths)
    runs = finished_runs(paths)
    if not runs:
        shown = ", ".join(str(p) for p in paths)
        raise ResultsError(f"{shown}: no finished run here (no */{META_FILE} next to a {TEST_FILE}); run `crowdnav benchmark` first")
    tests, trainings, metas, found = [], [], [], set()
    for run in runs:
        try:
            meta = read_json(run / META_FILE)
            key = (meta["experiment"], meta["configuration"], int(meta["seed"]))
            damage = run_damage(run, meta)
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise ResultsError(f"{run}: unreadable {META_FILE} ({type(error).__name__}); {REBUILD}") from None
        found.add(key)
        if damage:
            if missing is None:
                raise ResultsError(f"{run}: {damage[0]}; {REBUILD}")
            missing.append(MissingRun(*key, run, "; ".join(damage)))
            continue
        metas.append(meta)
        tests.append(pd.read_csv(run / TEST_FILE, keep_default_na=False, na_values=["nan", "NaN"]))
        if (run / TRAINING_FILE).is_file():
            trainings.append(pd.read_csv(run / TRAINING_FILE))
    if missing is not None:
        for (experiment, configuration, seed), folder in sorted(expected_runs(paths).items()):
            if (experiment, configuration, seed) not in found:
                reason = "not finished (no meta.json)" if folder.is_dir() else "not started"
                if (folder / f"{META_FILE}.damaged").is_file():  # set aside by a benchmark that could not rebuild it
                    reason = f"damaged beyond repair ({META_FILE}.damaged; the benchmark's log says why): remove the folder to run it again"
                missing.append(MissingRun(experiment, configuration, seed, folder, reason))
    if not tests:
        raise ResultsError(f"{', '.join(str(p) for p in paths)}: no intact finished run here: "
                           + "; ".join(gap.describe(folder=True) for gap in (missing or [])[:3]))
    test_frame = pd.concat(tests, ignore_index=True)
    training_frame = pd.concat(trainings, ignore_index=True) if trainings else pd.DataFrame()
    return test_frame, training_frame, metas
