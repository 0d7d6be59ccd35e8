"""Training configs from YAML (strict, with clear errors) and the agent commands."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from crowdnav.agents import ConfigError, TrainConfig, load_config, load_dataset
from crowdnav.agents.training.config import describe_fields

from crowdnav.cli import main
from tests.agents.agents_tiny import tiny_config


def write(tmp_path, text: str):
    path = tmp_path / "train.yaml"
    path.write_text(text)
    return path


def test_a_bad_config_key_names_the_key_the_file_and_the_line(tmp_path):
    path = write(tmp_path, "algo: sac\nepisodes: 10\nlearnig_rate: 0.001\n")
    # the style every crowdnav config file shares: FILE:LINE: dotted.key: expectation, with a did-you-mean
    with pytest.raises(ConfigError, match=rf"{path}:3: learnig_rate: unknown key 'learnig_rate'; did you mean 'learning_rate'\? "
                                          r"\(expected one of: action_noise, .*algo, .*scenario"):
        load_config(path)
    nested = write(tmp_path, "extractor:\n  rbf_centers: 8\n")
    with pytest.raises(ConfigError, match=rf"{nested}:2: extractor.rbf_centers: unknown key 'rbf_centers'; did you mean 'rbf_centres'\?"):
        load_config(nested)


@pytest.mark.parametrize(("text", "message"), [
    ("episodes: many", "episodes: expected an integer, got 'many'"),
    ("algo: dqn", "algo: expected one of 'sac', 'td3', 'ddpg', 'a2c', 'ppo', 'recurrent_ppo', 'sarl'"),
    ("algo: sca", "algo: expected one of 'sac', 'td3', 'ddpg', 'a2c', 'ppo', 'recurrent_ppo', 'sarl', got 'sca'; did you mean 'sac'?"),
    ("modalities: [lidar, gaol]", "modalities.1: unknown modality 'gaol'; did you mean 'goal'?"),
    ("reward_weights: {preset: papr}", "reward_weights: unknown reward preset 'papr'; did you mean 'paper'?"),
    ("modalities: lidar", "modalities: expected a list of strings"),
    ("learning_rate: fast", "learning_rate: expected a number or null"),
    ("episodes: 0", "episodes: expected an integer >= 1"),
    ("encoder: {mode: frozen}", "encoder.weights: encoder mode 'frozen' needs pre-trained weights"),
    ("encoder: {mode: finetune, weights: e.pt}", "'leog' is not among the modalities"),
    ("- a list", "expected a mapping of training options"),
])
def test_wrong_values_are_clear_errors(tmp_path, text, message):
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        load_config(write(tmp_path, text + "\n"))


def test_config_loads_with_overrides_and_every_field_is_documented(tmp_path):
    path = write(tmp_path, "algo: td3\nmodalities: [leog, goal]\nextractor:\n  rbf_centres: 8\nlearning_rate: 1\n")
    config = load_config(path, {"seed": 3, "encoder.mode": "scratch"})
    assert (config.algo, config.modalities, config.extractor.rbf_centres, config.seed) == ("td3", ["leog", "goal"], 8, 3)
    assert config.learning_rate == 1.0 and isinstance(config.learning_rate, float)
    assert load_config(None) == TrainConfig()
    assert all(doc for _, _, doc in describe_fields())


def test_train_command_overrides_the_config_with_flags(tmp_path, capsys):
    path = write(tmp_path, "algo: sac\nepisodes: 10\n")
    code = main(["train", "--config", str(path), "--algo", "ddpg", "--modalities", "leog, lidar,goal", "--episodes", "7",
                 "--seed", "4", "--out", str(tmp_path / "run"), "--print-config"])
    assert code == 0
    printed = yaml.safe_load(capsys.readouterr().out)
    assert (printed["algo"], printed["modalities"], printed["episodes"], printed["seed"]) == ("ddpg", ["leog", "lidar", "goal"], 7, 4)


def test_train_reward_flags_fill_reward_weights_on_top_of_the_config_file(tmp_path, capsys):
    path = write(tmp_path, "reward_weights: {social: 0, goal_progress: 50}\n")
    code = main(["train", "--config", str(path), "--reward", "paper", "--reward-weight", "goal_progress=20",
                 "--reward-weight", "collision=-100", "--print-config"])
    assert code == 0
    printed = yaml.safe_load(capsys.readouterr().out)
    assert printed["reward_weights"] == {"social": 0, "goal_progress": 20.0, "preset": "paper", "collision": -100.0}


@pytest.mark.parametrize(("argv", "message"), [
    (["--reward", "papr"], "invalid choice: 'papr'"),
    (["--reward-weight", "socal=1"], "unknown reward term 'socal'; did you mean 'social'? expected one of: step, goal_progress, social"),
    (["--reward-weight", "social"], "expected TERM=VALUE"),
    (["--reward-weight", "social=lots"], "social: expected a finite number, got 'lots'"),
])
def test_train_reward_flag_errors_are_usage_errors_naming_the_valid_values(capsys, argv, message):
    assert main(["train", *argv, "--print-config"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    if "papr" in argv:
        assert "default" in err.split("choose from")[1] and "paper" in err.split("choose from")[1]


def test_train_config_reward_weights_select_a_preset_for_the_env():
    from crowdnav.agents.sb3.factory import env_options

    from crowdnav.envs import CrowdNavEnv

    config = load_config(None, {"reward_weights": {"preset": "paper", "social": -50}})
    reward = CrowdNavEnv(**env_options(config)).scenario.reward
    assert reward.preset == "paper" and reward.terms == {"step": -5.0, "goal_progress": 10.0, "social": -50.0,
                                                         "goal_reached": 500.0, "collision": -500.0}
    assert CrowdNavEnv(**env_options(TrainConfig())).scenario.reward.preset == "default"


def test_train_command_reports_config_errors_on_one_line(tmp_path, capsys):
    path = write(tmp_path, "episods: 3\n")
    assert main(["train", "--config", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"crowdnav: error: {path}:1: episods: unknown key 'episods'; did you mean 'episodes'?") and "Traceback" not in err
    assert main(["train", "--encoder", "frozen", "--modalities", "leog,goal"]) == 1
    assert "needs pre-trained weights" in capsys.readouterr().err
    assert main(["train", "--algo", "dqn"]) == 2  # argparse usage error


def test_train_command_runs_a_config(tmp_path, capsys):
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(tiny_config(tmp_path / "run", episodes=1, max_steps=10)))
    assert main(["train", "--config", str(path)]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["episodes"] == 1 and (tmp_path / "run" / "checkpoint" / "policy.json").is_file()


def test_collect_dataset_and_pretrain_encoder_commands(tmp_path, capsys):
    data = tmp_path / "grids.npz"
    assert main(["collect-dataset", "--scenario", "room_furniture", "--grids", "40", "--out", str(data)]) == 0
    assert "wrote 40 grids of shape (1, 60, 60)" in capsys.readouterr().out
    assert load_dataset(data).grids.shape == (40, 1, 60, 60)
    assert main(["pretrain-encoder", "--dataset", str(data), "--epochs", "1", "--out", str(tmp_path / "enc")]) == 0
    assert "held-out loss" in capsys.readouterr().out
    assert {p.name for p in (tmp_path / "enc").iterdir()} == {"encoder.pt", "encoder.json", "loss.png"}
    np.savez(tmp_path / "bad.npz", images=np.zeros(3))
    assert main(["pretrain-encoder", "--dataset", str(tmp_path / "bad.npz"), "--out", str(tmp_path / "x")]) == 1
    assert "no 'grids' array" in capsys.readouterr().err
