"""One configuration system: shared error style, JSON Schemas, validation once per run, one name registry."""

from __future__ import annotations

import json

import pytest
import yaml

from crowdnav.cli import build_parser, main
from crowdnav.registry import ALGORITHM_NAMES, ALGORITHMS, ENCODER_MODES, algorithm_names, modality_names, reward_preset_names
from tests.evaluation.evaluation_tiny import tiny_experiment_document


def _write(tmp_path, name, document):
    path = tmp_path / name
    path.write_text(document if isinstance(document, str) else yaml.safe_dump(document, sort_keys=False), encoding="utf-8")
    return path


# ----------------------------------------------------------------------------- error style


def test_bad_train_config_errors_read_file_line_field_expectation_and_did_you_mean(tmp_path):
    from crowdnav.agents import ConfigError, load_config

    path = _write(tmp_path, "train.yaml", "algo: sca\nepisodes: 10\nextractor:\n  leog_latnt: 8\nseed: many\n")
    with pytest.raises(ConfigError) as caught:
        load_config(path)
    lines = str(caught.value).splitlines()
    assert f"{path}:1: algo: expected one of 'sac', 'td3', 'ddpg', 'a2c', 'ppo', 'recurrent_ppo', 'sarl', got 'sca'; did you mean 'sac'?" in lines
    assert any(line.startswith(f"{path}:4: extractor.leog_latnt: unknown key 'leog_latnt'; did you mean 'leog_latent'?")
               for line in lines)
    assert f"{path}:5: seed: expected an integer, got 'many'" in lines
    assert {issue.path for issue in caught.value.issues} == {"algo", "extractor.leog_latnt", "seed"}


def test_bad_experiment_file_errors_read_file_line_field_expectation_and_did_you_mean(tmp_path):
    from crowdnav.evaluation.experiment import ExperimentError, load_experiment

    document = tiny_experiment_document()
    document["protocol"]["eval_evry"] = 2
    path = _write(tmp_path, "bad.yaml", document)
    line = next(n for n, text in enumerate(path.read_text().splitlines(), 1) if "eval_evry" in text)
    with pytest.raises(ExperimentError) as caught:
        load_experiment(path)
    assert str(caught.value).startswith(f"{path}:{line}: protocol.eval_evry: unknown key 'eval_evry'; did you mean 'eval_every'?")

    document = tiny_experiment_document()
    document["configurations"][0]["train"]["algo"] = "tdd3"
    path = _write(tmp_path, "bad_algo.yaml", document)
    line = next(n for n, text in enumerate(path.read_text().splitlines(), 1) if "tdd3" in text)
    with pytest.raises(ExperimentError) as caught:
        load_experiment(path)
    assert str(caught.value) == (f"{path}:{line}: configurations.0.train.algo: expected one of 'sac', 'td3', 'ddpg', 'a2c', 'ppo', "
                                 "'recurrent_ppo', 'sarl', got 'tdd3'; did you mean 'td3'? (configuration 'lidar')")


def test_an_experiment_train_error_in_the_defaults_points_at_the_defaults(tmp_path):
    from crowdnav.evaluation.experiment import ExperimentError, load_experiment

    document = tiny_experiment_document()
    document["defaults"]["gama"] = 0.9
    path = _write(tmp_path, "bad.yaml", document)
    with pytest.raises(ExperimentError, match=r"defaults.gama: unknown key 'gama'; did you mean 'gamma'\?"):
        load_experiment(path)


# ----------------------------------------------------------------------------- schemas


@pytest.mark.parametrize(("kind", "title", "fields"), [
    ("scenario", "crowdnav scenario", {"robot", "humans", "reward", "sensors"}),
    ("train", "crowdnav training config", {"scenario", "algo", "modalities", "extractor", "encoder", "reward_weights"}),
    ("experiment", "crowdnav experiment", {"name", "protocol", "defaults", "pretrain_encoder", "configurations"}),
])
def test_schema_command_prints_valid_json_schema_listing_the_top_level_fields(capsys, kind, title, fields):
    assert main(["schema", kind]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema" and schema["title"] == title
    assert fields <= set(schema["properties"]) and schema["additionalProperties"] is False
    if kind != "scenario":  # the scenario schema puts some descriptions on the referenced definitions
        assert all(prop.get("description") for prop in schema["properties"].values())


def test_train_schema_lists_the_registry_names_and_the_defaults(capsys):
    from crowdnav.agents import TrainConfig

    assert main(["schema", "train"]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert schema["properties"]["algo"]["enum"] == list(algorithm_names())  # the built-in ones and the installed plug-ins (sarl)
    assert schema["properties"]["modalities"]["items"]["enum"] == list(modality_names())
    assert set(schema["properties"]) == set(TrainConfig.model_fields)
    assert schema["properties"]["episodes"]["default"] == TrainConfig().episodes


def test_shipped_experiments_and_the_default_train_config_fit_their_schemas_top_level_fields(capsys):
    from crowdnav.agents.training.config import config_to_dict, load_config
    from crowdnav.evaluation.experiment import experiment_path, shipped_experiments

    main(["schema", "experiment"])
    experiment_fields = set(json.loads(capsys.readouterr().out)["properties"])
    for name in shipped_experiments():
        assert set(yaml.safe_load(experiment_path(name).read_text())) <= experiment_fields
    main(["schema", "train"])
    assert set(config_to_dict(load_config(None))) == set(json.loads(capsys.readouterr().out)["properties"])


def test_schema_command_writes_to_a_file_and_refuses_an_unknown_kind(tmp_path, capsys):
    target = tmp_path / "train.schema.json"
    assert main(["schema", "train", "--output", str(target)]) == 0
    assert json.loads(target.read_text())["title"] == "crowdnav training config"
    capsys.readouterr()
    assert main(["schema", "trian"]) == 2
    assert "invalid choice: 'trian'" in capsys.readouterr().err


# ----------------------------------------------------------------------------- validation once


def test_one_experiment_unit_validates_its_train_config_exactly_once(tmp_path, monkeypatch):
    """Experiment file -> benchmark -> runner -> train: the TrainConfig is validated when the file is loaded, not after."""
    from crowdnav.agents.training import config as config_module
    from crowdnav.evaluation.benchmark import run_experiment
    from crowdnav.evaluation.experiment import load_experiment

    validations = []
    checks = config_module.cross_field_problems  # runs on every TrainConfig validation

    def counting(config):
        validations.append(config.algo)
        return checks(config)

    monkeypatch.setattr(config_module, "cross_field_problems", counting)
    document = tiny_experiment_document(seeds=1)
    document["configurations"] = document["configurations"][:1]
    experiment = load_experiment(_write(tmp_path, "one.yaml", document))
    assert len(validations) == 1
    report = run_experiment(experiment, tmp_path / "results", workers=1, progress=False, video=False, log=lambda line: None)
    assert not report.failures and len(report.summaries) == 1
    assert len(validations) == 1


# ----------------------------------------------------------------------------- one registry


def test_factory_algorithm_classes_cover_exactly_the_registry_names():
    from crowdnav.agents.sb3.factory import ALGORITHM_DEFAULTS, OFF_POLICY, SB3_ALGORITHMS
    from crowdnav.agents.sb3.factory import ALGORITHMS as CLASSES

    assert tuple(CLASSES) == tuple(SB3_ALGORITHMS) == tuple(ALGORITHM_DEFAULTS) == ALGORITHM_NAMES == tuple(ALGORITHMS)
    assert set(OFF_POLICY) <= set(ALGORITHM_NAMES)
    from crowdnav.agents.networks.size import kind_of, policy_kind

    # the head layout the network-size count reads from a registry entry is the one of SB3's policy class
    from crowdnav.registry import ALGORITHM_SPECS

    assert all(kind_of(name) == policy_kind(CLASSES[name].policy_aliases[ALGORITHM_SPECS[name].policy]) for name in ALGORITHM_NAMES)
    assert all(description.endswith(".") for description in ALGORITHMS.values())


def test_config_and_cli_choices_read_the_registry():
    import typing

    from crowdnav.agents.training.config import EncoderConfig, TrainConfig

    assert TrainConfig.model_json_schema()["properties"]["algo"]["enum"] == list(algorithm_names())
    assert all(TrainConfig(algo=name).algo == name for name in algorithm_names())
    assert typing.get_args(EncoderConfig.model_fields["mode"].annotation) == tuple(ENCODER_MODES)
    train = build_parser()._subparsers._group_actions[0].choices["train"]
    choices = {action.dest: action.choices for action in train._actions if action.choices}
    assert tuple(choices["algo"]) == algorithm_names() and tuple(choices["encoder"]) == tuple(ENCODER_MODES)
    assert tuple(choices["reward"]) == reward_preset_names()


def test_algorithm_properties_come_from_the_registry_entries_and_registered_names_validate():
    from crowdnav.agents.training.config import ConfigError, config_from_mapping

    from crowdnav.registry import (
        ALGORITHM_SPECS,
        OFF_POLICY_ALGORITHMS,
        AlgorithmSpec,
        algorithm_names,
        is_off_policy,
        register_algorithm,
        unregister_algorithm,
    )

    assert OFF_POLICY_ALGORITHMS == tuple(name for name, spec in ALGORITHM_SPECS.items() if spec.off_policy) == ("sac", "td3", "ddpg")
    assert [name for name, spec in ALGORITHM_SPECS.items() if spec.exploration_noise] == ["td3", "ddpg"]
    with pytest.raises(ConfigError, match="algo: expected one of 'sac', 'td3', 'ddpg', 'a2c', 'ppo', 'recurrent_ppo', 'sarl', got 'walker'"):
        config_from_mapping({"algo": "walker"})
    spec = AlgorithmSpec("A test walker.", off_policy=True, builder=object)
    register_algorithm("walker", spec)
    try:
        assert algorithm_names()[-1] == "walker" and is_off_policy("walker") and not spec.sb3
        assert config_from_mapping({"algo": "walker"}).algo == "walker"
        with pytest.raises(ValueError, match="registered already"):
            register_algorithm("walker", AlgorithmSpec("Another."))
    finally:
        unregister_algorithm("walker")
    assert "walker" not in algorithm_names()
    with pytest.raises(ValueError, match="built in"):
        unregister_algorithm("sac")


def test_modality_names_follow_the_sensor_registry_including_user_modalities(monkeypatch):
    from crowdnav.agents.training.config import ConfigError, load_config

    from crowdnav.sensors import MODALITIES, GoalModality

    assert set(modality_names()) == set(MODALITIES) >= {"goal", "lidar", "leog", "closest_obstacle", "velocity"}
    with pytest.raises(ConfigError, match="modalities.0: unknown modality 'sonar'; expected one of: closest_obstacle, geodesic, goal"):
        load_config(None, {"modalities": ["sonar"]})
    monkeypatch.setitem(MODALITIES, "sonar", GoalModality)  # a modality a user registered
    assert load_config(None, {"modalities": ["sonar"]}).modalities == ["sonar"]
