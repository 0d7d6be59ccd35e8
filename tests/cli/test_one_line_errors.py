"""Bad input where a traceback used to come: each case is one line naming what is wrong (issue 36, item 5).

Damaged ``policy.json`` files (several robots, a scenario that is not one), demonstration and
training settings beyond the seed bands or numerically meaningless, and seeds of the wrong kind.
Commands run through ``crowdnav.cli.main`` (a traceback would escape it and fail the test), Python
entries through ``pytest.raises``; every message is a single line.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from crowdnav.agents.training.config import ConfigError

from crowdnav.cli import main
from crowdnav.errors import CrowdNavError
from tests.agents.agents_tiny import tiny_config
from tests.agents.test_marl import robots_config


def _error(capsys, *argv: str) -> str:
    """``crowdnav ARGV``'s one error line (exit status 1, nothing else on stderr)."""
    code = main(list(argv))
    err = capsys.readouterr().err.strip()
    assert code == 1 and err.count("\n") == 0 and "Traceback" not in err, err
    return err


def _one_line(error: BaseException) -> str:
    message = str(error)
    assert isinstance(error, CrowdNavError) and "\n" not in message, message
    return message


@pytest.fixture(scope="module")
def robots_run(tmp_path_factory):
    from crowdnav.agents import train

    out = tmp_path_factory.mktemp("robots") / "run"
    train(robots_config(out, timesteps=96, checkpoint_every_steps=96))
    return out / "checkpoint"


@pytest.fixture(scope="module")
def robot_run(tmp_path_factory):
    from crowdnav.agents import train

    out = tmp_path_factory.mktemp("robot") / "run"
    train(tiny_config(out, modalities=["goal"], episodes=1, max_steps=10))
    return out / "checkpoint"


def _damaged(checkpoint, tmp_path, change):
    folder = tmp_path / "damaged"
    shutil.copytree(checkpoint, folder)
    info = json.loads((folder / "policy.json").read_text())
    change(info)
    (folder / "policy.json").write_text(json.dumps(info))
    return folder


def _drop(*path):
    def change(info):
        node = info
        for key in path[:-1]:
            node = node[key]
        del node[path[-1]]
    return change


def _set(value, *path):
    def change(info):
        node = info
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
    return change


@pytest.mark.parametrize(("change", "field"), [
    (_drop("robots"), "robots: expected a mapping"),
    (_drop("robots", "offset"), "robots.offset: expected a list"),
    (_set("nan", "robots", "scale", 0), "robots.scale: expected a list of 1 to 65,536 finite numbers"),
    (_set(float("nan"), "robots", "scale", 0), "robots.scale: expected a list of 1 to 65,536 finite numbers"),
    (_set(0.0, "robots", "scale", 0), "robots.scale: expected positive numbers"),
    (_set([], "robots", "robots"), "robots.robots: expected a list of 1 to 8 distinct robot names"),
    (_set({"optimizer_class": "torch.optim.SGD"}, "config", "policy_kwargs"), "policy_kwargs.optimizer_class: a torch optimizer class"),
], ids=["no-robots", "no-offset", "nan-text-scale", "nan-scale", "zero-scale", "no-robot-names", "string-optimizer"])
def test_a_damaged_robots_policy_json_is_one_line(robots_run, tmp_path, change, field):
    from crowdnav.agents.marl.robots import load_robots_policy

    folder = _damaged(robots_run, tmp_path, change)
    with pytest.raises(CrowdNavError) as caught:
        load_robots_policy(folder)
    assert field in _one_line(caught.value)


def test_the_undamaged_robots_policy_still_loads(robots_run):
    from crowdnav.agents.marl.robots import load_robots_policy

    policy = load_robots_policy(robots_run)
    assert np.all(np.isfinite(policy.observe.scale)) and len(policy.robots) == 3


@pytest.mark.parametrize(("scenario", "expected"), [
    ("no_such_scenario", "no_such_scenario: no such file or library scenario"),
    ("a text file", "expected a mapping of scenario fields"),
    (123, "env.scenario: expected a library scenario name or a scenario file's path, got '123'"),
    (None, "env.scenario: expected a library scenario name"),
], ids=["unknown-name", "not-a-scenario-file", "number", "null"])
def test_export_of_a_policy_json_whose_scenario_is_not_one_is_one_line(robot_run, tmp_path, capsys, scenario, expected):
    if scenario == "a text file":
        scenario = tmp_path / "notes.yaml"
        scenario.write_text("just some notes\n")
    folder = _damaged(robot_run, tmp_path, _set(str(scenario) if scenario is not None and not isinstance(scenario, int) else scenario,
                                                 "env", "scenario"))
    assert expected in _error(capsys, "export", str(folder), "--out", str(tmp_path / "policy.onnx"))


@pytest.mark.parametrize(("env", "expected"), [("nope", "env: expected a mapping of environment options"),
                                               ({"scenario": "open_space", "sensors": [1]}, "env.sensors: expected a mapping")])
def test_a_policy_json_whose_env_is_not_a_mapping_is_one_line(robot_run, tmp_path, capsys, env, expected):
    folder = _damaged(robot_run, tmp_path, _set(env, "env"))
    assert expected in _error(capsys, "evaluate", str(folder), "--scenario", "open_space", "--out", str(tmp_path / "out"))


@pytest.mark.parametrize(("section", "expected"), [
    ("learning_rate: 1.0e300", "demonstrations.learning_rate: expected a number <= 1"),
    ("action_std: 1.0e-300", "demonstrations.action_std: expected a number >= 0.0001"),
    ("action_std: 1.0e300", "demonstrations.action_std: expected a number <= 10"),
    ("episodes: 300000", "demonstrations.episodes: expected an integer <= 250000"),
    ("{episodes: 1000, dagger_rounds: 300}", "1,000 episodes x (1 + 300 rounds) exceed the 250,000 demonstration seeds"),
], ids=["learning-rate", "tiny-std", "huge-std", "episodes", "dagger-rounds"])
def test_demonstration_settings_out_of_bounds_are_one_line_before_any_work(tmp_path, capsys, section, expected):
    config = tmp_path / "demo.yaml"
    config.write_text(f"demonstrations: {section}\n" if section.startswith("{") else f"demonstrations:\n  {section}\n")
    assert expected in _error(capsys, "train", "--config", str(config), "--out", str(tmp_path / "run"))
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(("settings", "expected"), [({"learning_rate": 1e300}, "learning_rate: expected a number <= 1"),
                                                    ({"action_std": 1e-300}, "action_std: expected a number >= 0.0001")])
def test_behaviour_cloning_called_directly_checks_its_settings_first(settings, expected):
    from crowdnav.agents.imitation.cloning import behaviour_cloning

    with pytest.raises(ConfigError) as caught:
        behaviour_cloning(None, None, **settings)  # refused before the model or the demonstrations are looked at
    assert expected in _one_line(caught.value)


@pytest.mark.parametrize(("argv", "expected"), [
    (["--seed", "-1"], "seed: expected an integer >= 0, got -1"),
    (["--seed", str(2**32)], "seed: expected an integer <= 2147483647, got 4294967296"),
    (["--episodes", "600000"], "episodes: expected an integer <= 500000, got 600000"),
], ids=["negative-seed", "seed-2-32", "episodes-beyond-the-band"])
def test_train_seeds_and_budgets_beyond_the_bands_are_one_line(tmp_path, capsys, argv, expected):
    assert expected in _error(capsys, "train", *argv, "--out", str(tmp_path / "run"))
    assert not (tmp_path / "run").exists()


def test_a_string_optimizer_class_in_a_train_config_is_one_line(tmp_path, capsys):
    config = tmp_path / "sgd.yaml"
    config.write_text("policy_kwargs: {optimizer_class: torch.optim.SGD}\n")
    assert "policy_kwargs.optimizer_class: a torch optimizer class" in _error(capsys, "train", "--config", str(config))


@pytest.mark.parametrize(("argv", "expected"), [
    (["--test-seed-base", "999990", "--episodes", "20"], "test seeds 999,990-1,000,009 include 1,000,000, a seed of run seed 0's"),
    (["--test-seed-base", "3000000"], "include 3,000,000, a seed of run seed 2's"),
    (["--test-seed-base", "-5"], "test seeds must be non-negative"),
], ids=["reaches-run-seed-0", "inside-run-seed-2", "negative"])
def test_evaluate_refuses_test_seeds_that_are_training_seeds(tmp_path, capsys, argv, expected):
    error = _error(capsys, "evaluate", "baseline:straight", "--scenario", "open_space", "--out", str(tmp_path), *argv)
    assert expected in error and not any(tmp_path.iterdir())


def test_evaluate_takes_the_last_test_seeds_below_the_training_band(tmp_path, capsys):
    from crowdnav.agents.training.seeding import TRAIN_SEED_BASE, check_test_seeds

    check_test_seeds(TRAIN_SEED_BASE - 20, 20)  # 999,980-999,999: allowed
    with pytest.raises(ValueError, match="include 1,000,000"):
        check_test_seeds(TRAIN_SEED_BASE - 20, 21)


@pytest.mark.parametrize("seed", [1.5, -1, [1.5, 2], "ab", [True, 1], np.float64(2.0)], ids=str)
def test_the_vector_env_refuses_seeds_the_single_env_refuses(seed):
    from crowdnav.envs.vector.env import CrowdNavVectorEnv

    env = CrowdNavVectorEnv(num_envs=2, scenario="open_space")
    with pytest.raises(ValueError, match=r"seed must be None, an int or a list of one per world, .*non-negative integers") as caught:
        env.reset(seed=seed)
    assert "\n" not in str(caught.value)
    env.reset(seed=np.int64(3))  # numpy integers and lists of them are seeds
    env.reset(seed=[4, None])


def test_trajectories_of_a_policy_refuses_training_seeds_in_one_line(capsys):
    from crowdnav.cli import main

    code = main(["trajectories", "baseline:straight", "--scenario", "open_space", "--test-seed-base", "999990", "--episodes", "20",
                 "--out", "unused"])
    error = capsys.readouterr().err.strip()
    assert code != 0 and "Traceback" not in error and len(error.splitlines()) == 1
    assert "999,990-1,000,009" in error and "training" in error
