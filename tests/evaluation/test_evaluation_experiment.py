"""Experiment files: shipped experiments, validation errors naming file, line and field, CLI errors."""

from __future__ import annotations

import copy

import pytest
import yaml
from crowdnav.evaluation.benchmark import claim_folder
from crowdnav.evaluation.experiment import PRETRAINED, ExperimentError, experiment_from_mapping, load_experiment, shipped_experiments
from crowdnav.evaluation.storage import ResultsError

from crowdnav.cli import main
from tests.evaluation.evaluation_tiny import tiny_experiment_document, tiny_frozen_encoder_document


def write(tmp_path, document, name="experiment.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(document, sort_keys=False) if not isinstance(document, str) else document, encoding="utf-8")
    return path


def test_shipped_experiments_cover_figure_4_the_default_and_the_reference_agents():
    assert set(shipped_experiments()) == {"default", "encoders", "modalities", "modalities_paper", "fusion", "paradigms", "learning_check",
                                          "reference_figure4", "reference_room", "modalities_steps", "paradigms_steps", "robots",
                                          "anticipate", "anticipate_room", "anticipate_circle", "anticipate_circle_sarl", "anticipate_circle_sarl_rl",
                                          "anticipate_circle_sarl_deep", "anticipate_circle_sarl_rl_short", "anticipate_circle_sarl_rl_memory",
                                          "anticipate_circle_sarl_rl_bound", "robots_goal_frame", "room_sarl_figure4",
                                          "track_crowded_open_space", "track_station_hall", "track_robots_crossing_hall",
                                          "recurrent_crowded_open_space", "room_sarl_ensemble_figure4",
                                          "room_sarl_figure4_lidar_tracker", "room_sarl_room", "room_sarl_station_hall",
                                          "room_sarl_crowded_open_space", "room_sarl_edge_crowded_open_space",
                                          "room_sarl_room_lidar_tracker", "room_sarl_ensemble_edge_crowded_open_space"}
    labels = {name: [c.name for c in load_experiment(name).configurations] for name in shipped_experiments()}
    assert labels["encoders"] == ["frozen", "finetune", "scratch"]
    assert labels["modalities"] == labels["modalities_paper"] == ["leog", "lidar", "closest_obstacle"]
    assert labels["fusion"] == ["leog", "lidar", "leog_lidar"]
    assert labels["paradigms"] == ["sac", "td3", "ddpg", "a2c"]
    assert labels["robots"] == ["shared_ppo", "shared_ppo_anonymous"]
    assert labels["robots_goal_frame"] == ["goal_frame", "goal_frame_per_kind"]
    assert labels["modalities_steps"] == labels["modalities"] and labels["paradigms_steps"] == [*labels["paradigms"], "ppo"]
    assert load_experiment(None).name == "default"


def test_track_experiments_run_their_tracks_setting():
    """Each track_<name> experiment trains the reference agent of track <name>: same scenario, overrides, test episodes."""
    from crowdnav.evaluation.track import load_track

    for name in [n for n in shipped_experiments() if n.startswith("track_")]:
        experiment, track = load_experiment(name), load_track(name.removeprefix("track_"))
        assert experiment.protocol.test_episodes == track.test_episodes
        assert experiment.protocol.seeds >= 3
        for configuration in experiment.configurations:
            assert configuration.train["scenario"] == track.scenario
            assert dict(configuration.train.get("overrides") or {}) == dict(track.overrides)


def test_figure_4_under_env_step_budgets_trains_batched_with_5_seeds_and_the_frozen_pretrained_encoder():
    for name, budget in (("modalities_steps", 2_000_000), ("paradigms_steps", 1_000_000)):
        experiment = load_experiment(name)
        assert experiment.protocol.evaluation_points[-1] == budget and experiment.protocol.seeds == 5
        assert all("num_envs" not in c.train for c in experiment.configurations)  # batched default, unlike the 700-episode files
        assert experiment.pretrain_encoder is not None


def test_paper_experiments_use_the_papers_protocol_and_a_pretrained_encoder_where_frozen_or_finetuned():
    for name in ("encoders", "modalities", "modalities_paper", "fusion", "paradigms"):
        experiment = load_experiment(name)
        assert experiment.protocol.evaluation_points[-1] == 700 and experiment.protocol.seeds == 5
        assert experiment.protocol.eval_every == 50 and experiment.protocol.window == 10
        for configuration in experiment.configurations:
            encoder = configuration.train.get("encoder", {})
            if encoder.get("mode") in ("frozen", "finetune"):
                assert encoder["weights"] == PRETRAINED


def test_figure_4_experiments_share_one_setting_walking_crowd_of_five_default_preset_but_the_paper_rerun():
    from crowdnav.envs import CrowdNavEnv

    for name in ("encoders", "modalities", "modalities_paper", "fusion", "paradigms"):
        for configuration in load_experiment(name).configurations:
            train = configuration.train
            assert train["scenario"] == "room_furniture" and not {"gamma", "n_step_returns", "algo_kwargs"} & set(train)
            env = CrowdNavEnv("room_furniture", modalities=["goal"], overrides=train["overrides"],
                              reward_weights=train.get("reward_weights", {}))
            humans = env.scenario.humans
            assert humans.min_count >= 5 and humans.preferred_speed[0] >= 0.5 and humans.preferred_speed[1] >= 1.2
            assert not humans.see_robot  # humans do not react to the robot, as in the paper
            assert env.scenario.reward.preset == ("paper" if name == "modalities_paper" else "default")
            env.close()


def test_the_main_job_learns_from_the_batched_defaults_in_the_furnished_room_with_five_humans_two_seeds_100_test_episodes():
    from crowdnav.envs import CrowdNavEnv

    experiment = load_experiment(None)
    protocol = experiment.protocol
    assert protocol.seeds >= 2 and protocol.unit == "steps" and protocol.test_episodes >= 100 and protocol.evaluations >= 10
    for configuration in experiment.configurations:
        # nothing beyond the setting, the algorithm, the input and the shield: the curve is the defaults' own (batched RL;
        # the shield and the plan input read only the robot's own sensing and the map, docs/planning.md)
        assert set(configuration.train) <= {"scenario", "overrides", "algo", "modalities", "shield"}
        env = CrowdNavEnv(configuration.train["scenario"], modalities=configuration.train["modalities"],
                          overrides=configuration.train["overrides"])
        assert env.scenario.name == "room_furniture" and env.scenario.humans.min_count >= 5
        assert env.scenario.reward.preset == "default" and not env.scenario.humans.see_robot
        env.close()


def test_the_learning_check_runs_crowdnavs_defaults_in_two_library_scenarios():
    experiment = load_experiment("learning_check")
    assert experiment.protocol.seeds == 5 and experiment.protocol.evaluation_points == [50, 100, 150, 200, 250, 300]
    assert [c.train["scenario"] for c in experiment.configurations] == ["open_space", "room_furniture"]
    # besides num_envs: 1, the single env its published results were trained with (docs/agents.md#batched-training)
    assert all(set(c.train) <= {"scenario", "algo", "modalities", "num_envs"} for c in experiment.configurations)
    assert all(c.train["num_envs"] == 1 for c in experiment.configurations)


def test_configuration_train_fields_are_merged_over_the_defaults():
    document = tiny_experiment_document()
    document["configurations"][0]["train"]["overrides"] = {"humans.count": 1}
    experiment = experiment_from_mapping(document)
    assert experiment.configurations[0].train["overrides"] == {"max_steps": 40, "humans.count": 1}
    assert experiment.configurations[1].train["overrides"] == {"max_steps": 40, "humans.count": 3}


def test_runs_are_ordered_seed_by_seed_so_a_partial_experiment_covers_every_configuration(tmp_path):
    experiment = experiment_from_mapping(tiny_experiment_document(seeds=2))
    order = [(spec.seed, spec.configuration) for spec, _ in experiment.units(tmp_path)]
    assert order == [(0, "lidar"), (0, "closest"), (1, "lidar"), (1, "closest")]
    assert [folder.relative_to(tmp_path).as_posix() for _, folder in experiment.units(tmp_path)][:2] == ["lidar/seed_0", "closest/seed_0"]


def _error(tmp_path, document) -> str:
    path = write(tmp_path, document)
    with pytest.raises(ExperimentError) as caught:
        load_experiment(path)
    message = str(caught.value)
    assert message.startswith(str(path)) and "\n" not in message
    return message


def test_unknown_top_level_key_is_named_with_its_line(tmp_path):
    document = tiny_experiment_document()
    document["seeds"] = 3
    message = _error(tmp_path, document)
    line = write(tmp_path, document).read_text().splitlines().index("seeds: 3") + 1
    assert f":{line}: seeds: unknown key 'seeds'" in message and "protocol" in message


def test_unknown_protocol_field_is_named(tmp_path):
    document = tiny_experiment_document()
    document["protocol"]["evaluate_every"] = 10
    assert "protocol.evaluate_every: unknown key 'evaluate_every'" in _error(tmp_path, document)


def test_bad_protocol_value_is_named(tmp_path):
    document = tiny_experiment_document()
    document["protocol"]["test_episodes"] = 0
    assert "protocol.test_episodes: expected an integer >= 1" in _error(tmp_path, document)


def test_unknown_training_field_in_a_configuration_is_named_with_the_configuration(tmp_path):
    document = tiny_experiment_document()
    document["configurations"][1]["train"]["learning_rat"] = 0.1
    message = _error(tmp_path, document)
    line = next(n for n, text in enumerate(write(tmp_path, document).read_text().splitlines(), 1) if "learning_rat: 0.1" in text)
    assert f":{line}: configurations.1.train.learning_rat: unknown key 'learning_rat'; did you mean 'learning_rate'?" in message
    assert "(configuration 'closest')" in message


def test_protocol_owned_training_fields_are_refused(tmp_path):
    document = tiny_experiment_document()
    document["defaults"]["episodes"] = 100
    assert "defaults.episodes: 'episodes' is set by the protocol" in _error(tmp_path, document)


def test_unknown_scenario_or_modality_is_reported_at_load_time(tmp_path):
    document = tiny_experiment_document()
    document["configurations"][0]["train"]["modalities"] = ["sonar"]
    assert "configurations.0.train.modalities.0: unknown modality 'sonar'" in _error(tmp_path, document)
    document = tiny_experiment_document()
    document["configurations"][0]["train"]["scenario"] = "no_such_scenario"
    message = _error(tmp_path, document)
    assert "configurations.0.train: environment:" in message and "(configuration 'lidar')" in message


def test_duplicate_configuration_names_are_refused(tmp_path):
    document = tiny_experiment_document()
    document["configurations"][1]["name"] = "lidar"
    assert "configurations.1.name: duplicate configuration name 'lidar'" in _error(tmp_path, document)


def test_malformed_yaml_and_missing_file_are_one_line_errors(tmp_path):
    assert "malformed YAML" in _error(tmp_path, "name: [unclosed\n")
    with pytest.raises(ExperimentError, match="no such experiment file"):
        load_experiment(tmp_path / "missing.yaml")


def test_editing_an_experiment_keeps_its_folder_but_a_different_protocol_is_refused(tmp_path):
    document = tiny_experiment_document()
    claim_folder(tmp_path / "tiny", experiment_from_mapping(document))
    claim_folder(tmp_path / "tiny", experiment_from_mapping(tiny_experiment_document(seeds=3)))  # more seeds: fine
    edited = copy.deepcopy(document)
    edited["description"] = "reworded"
    edited["defaults"]["algo"] = "td3"  # every configuration edited: their runs start afresh, one by one
    edited["configurations"].append({"name": "extra", "train": {"modalities": ["goal"]}})
    claim_folder(tmp_path / "tiny", experiment_from_mapping(edited))
    changed = copy.deepcopy(document)
    changed["protocol"]["test_episodes"] = 5
    with pytest.raises(ResultsError, match="different version of experiment 'tiny' \\(protocol differ\\)"):
        claim_folder(tmp_path / "tiny", experiment_from_mapping(changed))


def run_cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("content, expected", [
    (None, "no such experiment file"),
    ("protocol: {seeds: two}\nconfigurations: []\n", "protocol.seeds: expected an integer"),
    ("name: x\nconfigurations:\n  - name: a\n    trian: {}\n", "configurations.0.trian: unknown key"),
])
def test_benchmark_command_reports_bad_experiment_files_in_one_line(tmp_path, capsys, content, expected):
    path = tmp_path / "bad.yaml"
    if content is not None:
        path.write_text(content, encoding="utf-8")
    code, _, err = run_cli(capsys, "benchmark", str(path), "--out", str(tmp_path / "results"))
    assert code == 1 and expected in err
    assert err.startswith("crowdnav: error: ") and err.count("\n") == 1


def test_benchmark_command_refuses_a_results_folder_from_another_config_in_one_line(tmp_path, capsys):
    document = tiny_experiment_document()
    changed = copy.deepcopy(document)
    changed["protocol"]["test_episodes"] = 5
    claim_folder(tmp_path / "results" / "tiny", experiment_from_mapping(changed))
    code, _, err = run_cli(capsys, "benchmark", str(write(tmp_path, document)), "--out", str(tmp_path / "results"), "--no-progress")
    assert code == 1 and "holds results of a different version of experiment 'tiny' (protocol differ)" in err
    assert err.count("\n") == 1


@pytest.mark.parametrize("argv", [["plot", "{missing}"], ["leaderboard", "{missing}"], ["leaderboard", "{empty}"], ["plot", "{empty}"]])
def test_plot_and_leaderboard_of_a_missing_or_empty_folder_are_one_line_errors(tmp_path, capsys, argv):
    (tmp_path / "empty").mkdir()
    argv = [arg.format(missing=tmp_path / "missing", empty=tmp_path / "empty") for arg in argv]
    code, _, err = run_cli(capsys, *argv)
    assert code == 1 and err.startswith("crowdnav: error: ") and err.count("\n") == 1
    assert ("no such results folder" in err) or ("no finished run here" in err)


def test_pretrained_encoder_is_trained_once_per_experiment_and_given_to_frozen_runs(tmp_path):
    from crowdnav.evaluation.benchmark import run_experiment

    document = tiny_frozen_encoder_document()
    experiment = experiment_from_mapping(document)
    report = run_experiment(experiment, tmp_path, workers=1, progress=False, video=False, log=lambda line: None)
    assert not report.failures
    encoder = tmp_path / "tiny" / "encoder" / "encoder.pt"
    meta = yaml.safe_load((tmp_path / "tiny" / "frozen" / "seed_0" / "meta.json").read_text())
    assert meta["config"]["encoder"] == {"mode": "frozen", "weights": str(encoder), "precompute": True}
    written = encoder.stat().st_mtime_ns
    run_experiment(experiment, tmp_path, workers=1, progress=False, video=False, log=lambda line: None)
    assert encoder.stat().st_mtime_ns == written


@pytest.mark.parametrize(("perfect_name", "lidar_name", "track_name"), [
    ("room_sarl_figure4", "room_sarl_figure4_lidar_tracker", "figure4_lidar_tracker"),
    ("room_sarl_room", "room_sarl_room_lidar_tracker", "room_lidar_tracker"),
])
def test_room_sarl_lidar_tracker_experiments_are_their_perfect_sensing_recipe_in_the_lidar_tracker_tracks_setting(
        perfect_name, lidar_name, track_name):
    """The same recipe as the perfect-sensing experiment, only seen through the track's tracker (what training through it buys)."""
    from crowdnav.evaluation.track import load_track

    perfect, lidar = load_experiment(perfect_name), load_experiment(lidar_name)
    track = load_track(track_name)
    (trained,), (perfect_trained,) = [c.train for c in lidar.configurations], [c.train for c in perfect.configurations]
    assert trained["overrides"] == track.overrides and trained["scenario"] == track.scenario
    assert {**trained, "overrides": None} == {**perfect_trained, "overrides": None}
    assert lidar.protocol == perfect.protocol


@pytest.mark.parametrize("experiment_name, track_name", [("room_sarl_room", "room"), ("room_sarl_station_hall", "station_hall"),
                                                              ("room_sarl_crowded_open_space", "crowded_open_space")])
def test_room_sarl_track_experiments_are_room_sarl_figure4s_recipe_in_their_tracks_setting(experiment_name, track_name):
    """The Figure-4 recipe unchanged (not tuned per track), trained in the setting of the track it is published on."""
    from crowdnav.evaluation.track import load_track

    figure4, other = load_experiment("room_sarl_figure4"), load_experiment(experiment_name)
    track = load_track(track_name)
    (trained,), (figure4_trained,) = [c.train for c in other.configurations], [c.train for c in figure4.configurations]
    assert trained.get("overrides", {}) == track.overrides and trained["scenario"] == track.scenario
    assert {**trained, "overrides": None, "scenario": None} == {**figure4_trained, "overrides": None, "scenario": None}
    assert other.protocol == figure4.protocol


def test_room_sarl_edge_experiment_is_the_open_space_recipe_plus_the_world_edge_only():
    """One sensing change (the world's sides as obstacles), which is a no-op in walled scenarios; nothing else tuned."""
    plain, edge = load_experiment("room_sarl_crowded_open_space"), load_experiment("room_sarl_edge_crowded_open_space")
    (plain_trained,), (edge_trained,) = [c.train for c in plain.configurations], [c.train for c in edge.configurations]
    assert edge_trained == {**plain_trained, "sensors": {"obstacles": {"world_edge": True}}}
    assert edge.protocol == plain.protocol


def test_room_sarl_ensemble_edge_experiment_is_the_edge_recipe_plus_figure4s_ensemble_only():
    """The one change validated on Figure-4 (a value ensemble of 3) added to the edge recipe; nothing else tuned."""
    edge, ensemble = load_experiment("room_sarl_edge_crowded_open_space"), load_experiment("room_sarl_ensemble_edge_crowded_open_space")
    (edge_trained,), (ensemble_trained,) = [c.train for c in edge.configurations], [c.train for c in ensemble.configurations]
    figure4_kwargs = load_experiment("room_sarl_ensemble_figure4").configurations[0].train["algo_kwargs"]
    assert ensemble_trained == {**edge_trained, "algo_kwargs": {**edge_trained["algo_kwargs"], "ensemble": 3}}
    assert ensemble_trained["algo_kwargs"] == figure4_kwargs
    assert ensemble.protocol == edge.protocol
