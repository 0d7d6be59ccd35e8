"""The results-folder layout is known in one place (crowdnav.evaluation.storage) and read back by name."""

from __future__ import annotations

import re
from pathlib import Path

from crowdnav.evaluation.benchmark import claim_folder
from crowdnav.evaluation.experiment import load_experiment
from crowdnav.evaluation.storage import (
    baseline_folder,
    encoder_folder,
    evaluated_run_name,
    expected_runs,
    experiment_folder,
    experiment_of,
    pretrained_encoder_path,
    relative_run_path,
    results_root_of,
    run_folder,
    run_name,
)

from tests.paths import REPO

REPO = REPO


def test_a_run_folder_names_its_experiment_results_root_and_relative_path(tmp_path):
    experiment = experiment_folder(tmp_path / "results", "figure4")
    run = run_folder(experiment, "lidar", 3)
    assert run == tmp_path / "results" / "figure4" / "lidar" / "seed_3"
    assert run_name("lidar", 3) == "lidar/seed_3"
    assert experiment_of(run) == experiment and results_root_of(run) == tmp_path / "results"
    assert relative_run_path(run) == Path("figure4/lidar/seed_3")
    assert experiment_of(baseline_folder(experiment, "baseline:social_force")) == experiment
    evaluated = experiment_folder(tmp_path, "evaluate") / evaluated_run_name("sac--open_space", 0, 99)
    assert evaluated.name == "seeds_0-99" and experiment_of(evaluated) == tmp_path / "evaluate"
    assert pretrained_encoder_path(experiment).parent == encoder_folder(experiment) == experiment / "encoder"


def test_an_experiment_plans_its_runs_where_the_results_reader_expects_them(tmp_path):
    experiment = load_experiment("default")
    folder = experiment_folder(tmp_path, experiment.name)
    planned = {folder for _, folder in experiment.units(folder)}
    folder.mkdir()
    claim_folder(folder, experiment)  # what crowdnav benchmark writes first: experiment.yaml
    assert planned == set(expected_runs([tmp_path]).values())
    assert all(experiment_of(run) == folder for run in planned)


POSITIONAL = re.compile(r"\.parent\.parent\b|\.parents\[\d\]|\.parts\[-\d:\]")


def test_no_module_but_storage_derives_the_results_layout_by_position():
    offenders = []
    for folder in ("evaluation", "crowdnav/cli"):
        for path in sorted((REPO / folder).rglob("*.py")):
            if path.name == "storage.py":
                continue
            for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                if POSITIONAL.search(line) and "__file__" not in line:  # a module finding its own files is not the results layout
                    offenders.append(f"{path.relative_to(REPO)}:{number}: {line.strip()}")
    assert not offenders, "use crowdnav.evaluation.storage's layout functions:\n" + "\n".join(offenders)
