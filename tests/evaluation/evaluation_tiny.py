"""Tiny evaluation settings shared by the evaluation tests: a few short episodes, small networks."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

TINY_TRAIN = {
    "scenario": "open_space", "algo": "sac", "overrides": {"max_steps": 40, "humans.count": 3},
    "sensors": {"lidar": {"beams": 16}}, "net_arch": [16], "batch_size": 16, "buffer_size": 2000, "learning_starts": 30,
    "algo_kwargs": {"train_freq": 4}, "extractor": {"lidar_hidden": [16], "rbf_centres": 4, "lowdim_hidden": [8]},
    "num_envs": 1,
}
"""TrainConfig fields of a run that trains in well under a second per episode, from one env (the kill/resume tests
time their kills by single episodes; batched runs through the pipeline: tests/evaluation/test_evaluation_step_budget.py)."""

TINY_PROTOCOL = {"train_episodes": 4, "eval_every": 2, "test_episodes": 3, "seeds": 2, "window": 3, "final_evaluations": 1}


def tiny_experiment_document(name: str = "tiny", **protocol: Any) -> dict[str, Any]:
    """A 2-configuration experiment (LIDAR, closest obstacle) with the tiny protocol."""
    return copy.deepcopy({
        "name": name,
        "description": "tiny experiment for the tests",
        "protocol": {**TINY_PROTOCOL, **protocol},
        "defaults": TINY_TRAIN,
        "configurations": [
            {"name": "lidar", "label": "LIDAR", "train": {"modalities": ["lidar", "goal"]}},
            {"name": "closest", "label": "closest obstacle", "train": {"modalities": ["closest_obstacle", "goal"]}},
        ],
    })


def tiny_unit_spec(seed: int = 0, **protocol: Any) -> dict[str, Any]:
    """The UnitSpec dict of one tiny run."""
    return copy.deepcopy({"experiment": "tiny", "configuration": "lidar", "seed": seed, "label": "LIDAR",
                          "train": {**TINY_TRAIN, "modalities": ["lidar", "goal"]},
                          "protocol": {**TINY_PROTOCOL, "seeds": 1, **protocol}})


_RESULTS: dict[str, Path] = {}


def tiny_results(tmp_path_factory) -> Path:
    """A results folder of the tiny experiment (2 configurations x 2 seeds), made once per test session."""
    if "folder" not in _RESULTS:
        from crowdnav.evaluation.benchmark import run_experiment
        from crowdnav.evaluation.experiment import experiment_from_mapping

        experiment = experiment_from_mapping(tiny_experiment_document())
        report = run_experiment(experiment, tmp_path_factory.mktemp("results"), workers=1, progress=False, video=False,
                                log=lambda line: None)
        assert not report.failures, report.failures
        _RESULTS["folder"] = report.folder
    return _RESULTS["folder"]


def write_tiny_experiment(path: Path, name: str = "tiny", **protocol: Any) -> Path:
    """The tiny experiment as a YAML file at ``path`` (for the command line)."""
    import yaml

    path.write_text(yaml.safe_dump(tiny_experiment_document(name, **protocol), sort_keys=False), encoding="utf-8")
    return path


def tiny_frozen_encoder_document() -> dict[str, Any]:
    """A one-run experiment whose agent uses a tiny pre-trained frozen LEOG encoder (trained by the experiment)."""
    document = tiny_experiment_document(train_episodes=2, eval_every=2, test_episodes=2, seeds=1)
    document["defaults"].update(
        scenario="room_furniture", sensors={"leog": {"size": 3.0, "resolution": 0.1}},
        extractor={"leog_channels": [4, 8], "leog_kernels": [4, 3], "leog_strides": [4, 2], "leog_latent": 8, "rbf_centres": 4,
                   "lowdim_hidden": [8]},
    )
    document["pretrain_encoder"] = {"scenario": "room_furniture", "grids": 32, "epochs": 1}
    document["configurations"] = [{"name": "frozen", "train": {"modalities": ["leog", "goal"], "encoder": {"mode": "frozen"}}}]
    return document
