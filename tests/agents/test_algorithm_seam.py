"""The algorithm seam: an algorithm outside SB3 (tests/agents/toy_algorithm.py) registered by name trains through
``crowdnav train``, is checkpointed without pickle, resumes exactly and is evaluated by ``crowdnav evaluate RUN``."""

from __future__ import annotations

import csv

import numpy as np
import pytest
import yaml

from crowdnav.cli import main
from crowdnav.registry import register_algorithm, unregister_algorithm
from tests.agents.toy_algorithm import SPEC, RandomSearchAgent

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


@pytest.fixture
def random_search():
    register_algorithm("random_search", SPEC)
    yield "random_search"
    unregister_algorithm("random_search")


def toy_config(out, **fields):
    """Goal-only observations in an empty room: a linear policy can learn to drive to the goal in a few dozen episodes."""
    config = {"algo": "random_search", "scenario": "open_space", "modalities": ["goal"], "num_envs": 1, "episodes": 60,
              "seed": 0, "out": str(out), "overrides": {"max_steps": 40, "humans.count": 0}, "checkpoint_every": 20,
              "progress": False, "algo_kwargs": {"step_size": 0.005, "noise": 0.3}}
    config.update(fields)
    return config


def write_config(tmp_path, config, name="toy.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(config), encoding="utf-8")
    return path


def rows(run):
    with open(run / "episodes.csv", encoding="utf-8") as file:
        return [{key: value for key, value in row.items() if key != "seconds"} for row in csv.DictReader(file)]


def mean_return(policy, seeds):
    env = policy.make_env(overrides={"max_steps": 40, "humans.count": 0})
    total = 0.0
    for seed in seeds:
        observation, _ = env.reset(seed=seed)
        done = False
        while not done:
            observation, reward, terminated, truncated, _ = env.step(policy(observation))
            total += float(reward)
            done = terminated or truncated
    return total / len(seeds)


def test_registered_algorithm_trains_through_crowdnav_train_without_pickle_and_learns(tmp_path, random_search):
    from crowdnav.agents import load_policy
    from crowdnav.agents.training.seeding import train_seed

    run = tmp_path / "run"
    assert main(["train", "--config", str(write_config(tmp_path, toy_config(run)))]) == 0
    logged = rows(run)
    assert [int(row["episode"]) for row in logged] == list(range(60))
    assert [int(row["seed"]) for row in logged] == [train_seed(0, episode) for episode in range(60)]
    files = sorted(path.relative_to(run / "checkpoint").as_posix() for path in (run / "checkpoint").rglob("*") if path.is_file())
    assert files == ["algorithm/state.json", "algorithm/weights.npz", "policy.json"]  # arrays and JSON only
    assert sorted(path.name for path in (run / "snapshots").iterdir()) == [f"episode_{n:05d}" for n in (20, 40, 60)]
    policy = load_policy(run)
    assert policy.algo == "random_search" and not np.all(policy.model.weights == 0)
    untrained = load_policy(run)
    untrained.model.weights = np.zeros_like(untrained.model.weights)
    seeds = range(100, 110)  # held-out episodes: zero action scores -4 (time penalty); seeds 0-5 of the run reach 5 to 45
    assert mean_return(policy, seeds) > mean_return(untrained, seeds) + 5.0  # it learned to make progress to the goal


def test_registered_algorithm_resumes_to_the_uninterrupted_run(tmp_path, random_search):
    from crowdnav.agents import load_policy, train

    whole, cut = tmp_path / "whole", tmp_path / "cut"
    train(toy_config(whole, episodes=12, checkpoint_every=3))
    first = train(toy_config(cut, episodes=7, checkpoint_every=3))  # checkpointed at 6 and at its end, 7 (mid-pair)
    assert first.episodes == 7
    resumed = train(toy_config(cut, episodes=12, checkpoint_every=3), resume=True)
    assert resumed.episodes == 12 and len(resumed.records) == 5 and isinstance(resumed.model, RandomSearchAgent)
    assert rows(cut) == rows(whole)
    np.testing.assert_array_equal(load_policy(cut).model.weights, load_policy(whole).model.weights)


def test_crowdnav_evaluate_plays_a_registered_algorithms_run_and_export_refuses_it(tmp_path, capsys, random_search):
    run = tmp_path / "run"
    config = toy_config(run, episodes=2, checkpoint_every=1)
    del config["algo"]  # named on the command line: --algo's choices read the registry too
    assert main(["train", "--config", str(write_config(tmp_path, config)), "--algo", "random_search"]) == 0
    results = tmp_path / "results"
    assert main(["evaluate", str(run), "--scenario", "open_space", "--episodes", "2", "--out", str(results), "--no-progress"]) == 0
    assert list(results.glob("evaluate/*/seeds_*/*"))
    capsys.readouterr()
    assert main(["export", str(run), "--out", str(tmp_path / "p.onnx")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "algorithm 'random_search' has no ONNX export: its agent has no export_module()" in err


def test_registered_algorithm_collects_from_several_worlds_and_a_resume_starts_new_episodes_in_every_world(tmp_path, random_search):
    import json

    from crowdnav.agents import train
    from crowdnav.agents.training.seeding import train_seed

    run = tmp_path / "run"
    result = train(toy_config(run, num_envs=4, episodes=10, checkpoint_every=5))
    first = rows(run)
    assert result.episodes == 10 and [int(row["episode"]) for row in first] == list(range(10))
    assert int(first[-1]["timesteps"]) % 4 == 0  # every step is one of each of the 4 worlds
    info = json.loads((run / "checkpoint" / "policy.json").read_text(encoding="utf-8"))
    started = info["next_episode"]  # the first episode no world had begun when the run stopped
    assert 10 < started <= 10 + 4 and {int(row["seed"]) for row in first} < {train_seed(0, e) for e in range(started)}
    train(toy_config(run, num_envs=4, episodes=16, checkpoint_every=5), resume=True)
    resumed = rows(run)
    assert resumed[:10] == first and len(resumed) == 16
    later = {int(row["seed"]) for row in resumed[10:]}  # new episodes in every world: none played again, none before started
    assert len(later) == 6 and later <= {train_seed(0, e) for e in range(started, started + 10)}


def test_registered_algorithm_refuses_settings_of_the_sb3_path_in_one_line(tmp_path, random_search):
    from crowdnav.agents import train
    from crowdnav.agents.training.config import ConfigError

    config = toy_config(tmp_path / "run", timesteps=400, checkpoint_every_steps=100)
    del config["episodes"]
    with pytest.raises(ConfigError, match="^checkpoint_every_steps: algorithm 'random_search' checkpoints every checkpoint_every episodes$"):
        train(config)
    assert not (tmp_path / "run").exists()


def test_a_run_of_an_algorithm_this_process_has_not_registered_is_refused_in_one_line(tmp_path, capsys, random_search):
    from crowdnav.agents import train

    run = tmp_path / "run"
    train(toy_config(run, episodes=1))
    unregister_algorithm("random_search")
    argv = ["evaluate", str(run), "--scenario", "open_space", "--episodes", "1", "--out", str(tmp_path / "r"), "--no-progress"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "trained with unknown algorithm 'random_search'" in err and "register it" in err


def test_an_installed_algorithm_is_registered_from_its_entry_point(monkeypatch):
    import importlib.metadata

    from crowdnav.agents.training.config import config_from_mapping

    import crowdnav.registry as registry

    point = importlib.metadata.EntryPoint("random_search", "tests.agents.toy_algorithm:SPEC", registry.PLUGIN_GROUP)
    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group: [point] if group == registry.PLUGIN_GROUP else [])
    monkeypatch.setattr(registry, "_plugins_loaded", False)
    try:
        assert config_from_mapping(toy_config("unused")).algo == "random_search"  # validation reads the registry, plug-ins too
        assert registry.ALGORITHM_SPECS["random_search"] is SPEC
    finally:
        unregister_algorithm("random_search")


def test_an_experiment_trains_and_ranks_a_registered_algorithm_by_the_evaluation_protocol(tmp_path, random_search):
    from crowdnav.evaluation.benchmark import run_experiment
    from crowdnav.evaluation.experiment import experiment_from_mapping

    protocol = {"train_episodes": 4, "eval_every": 2, "test_episodes": 3, "seeds": 2, "window": 3, "final_evaluations": 1}
    train = {key: value for key, value in toy_config("unused").items() if key not in ("out", "episodes", "checkpoint_every", "seed", "progress")}
    document = {"name": "toy", "description": "a registered algorithm", "protocol": protocol, "defaults": train,
                "configurations": [{"name": "rs", "label": "random search", "train": {}}]}
    report = run_experiment(experiment_from_mapping(document), tmp_path, workers=1, progress=False, video=False, log=lambda line: None)
    assert not report.failures
    for seed in (0, 1):
        run = report.folder / "rs" / f"seed_{seed}"
        assert sorted(path.name for path in (run / "evaluations").iterdir()) == ["evaluation_000.csv", "evaluation_001.csv"]
        with open(run / "test_episodes.csv", encoding="utf-8") as file:
            assert len(list(csv.DictReader(file))) == 2 * 3  # two evaluations of the 3 test episodes
    assert "| random search | 2 |" in (report.folder / "leaderboard.md").read_text(encoding="utf-8")
