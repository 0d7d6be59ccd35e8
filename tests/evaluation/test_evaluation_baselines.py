"""Scripted baselines: played on the experiment's own test episodes, ranked and drawn with the learned runs."""

from __future__ import annotations

import pandas as pd
import pytest
from crowdnav.evaluation.baselines import BASELINES, EXPERIMENT_BASELINES, evaluate_baseline, experiment_baselines, is_baseline
from crowdnav.evaluation.curves import curves_figure
from crowdnav.evaluation.experiment import ExperimentError, experiment_from_mapping
from crowdnav.evaluation.leaderboard import leaderboard_table
from crowdnav.evaluation.protocol import Protocol
from crowdnav.evaluation.storage import META_FILE, TEST_FILE, load_results, read_json

from crowdnav.envs import CrowdNavEnv
from crowdnav.planning.onboard import OnboardPlanner
from crowdnav.planning.scripted import SocialForceRobot, StraightToGoal
from tests.evaluation.evaluation_tiny import tiny_experiment_document, tiny_results


def _outcome(policy, env_options, seed):
    env = CrowdNavEnv(**env_options)
    env.reset(seed=seed)
    while True:
        _, _, terminated, truncated, info = env.step(policy(env.simulator))
        if terminated or truncated:
            return info["outcome"]


def test_baselines_play_the_protocols_test_episodes_like_the_scripted_policies_do(tmp_path):
    options = {"scenario": "open_space", "modalities": ["goal"], "overrides": {"max_steps": 60}, "reward_weights": {}}
    protocol = Protocol(train_episodes=4, eval_every=2, test_episodes=4, seeds=1, test_seed_base=7)
    for name, policy in (("straight", StraightToGoal()), ("social_force", SocialForceRobot()), ("onboard", OnboardPlanner())):
        folder = evaluate_baseline("x", f"baseline_{name}", BASELINES[name], options, protocol, tmp_path / name)
        tests = pd.read_csv(folder / TEST_FILE, keep_default_na=False)
        # the same rows at both evaluation points, one per test seed, as the scripted policy plays them
        assert list(tests["training_episodes"].unique()) == [2, 4]
        for _, rows in tests.groupby("evaluation"):
            assert list(rows["test_seed"]) == [7, 8, 9, 10]
            assert list(rows["outcome"]) == [_outcome(policy, options, seed) for seed in range(7, 11)]
        meta = read_json(folder / META_FILE)
        assert meta["kind"] == "baseline" and meta["env_steps"]["train"] == 0 and meta["policy"] == name


def test_a_finished_baseline_is_not_played_again(tmp_path):
    options = {"scenario": "open_space", "modalities": ["goal"], "overrides": {"max_steps": 30}, "reward_weights": {}}
    protocol = Protocol(train_episodes=2, eval_every=2, test_episodes=2, seeds=1)
    folder = evaluate_baseline("x", "baseline_straight", "straight", options, protocol, tmp_path / "b")
    stamp = (folder / META_FILE).stat().st_mtime_ns
    evaluate_baseline("x", "baseline_straight", "straight", options, protocol, tmp_path / "b")
    assert (folder / META_FILE).stat().st_mtime_ns == stamp


def test_an_experiment_gets_one_set_of_baselines_per_distinct_environment():
    experiment = experiment_from_mapping(tiny_experiment_document())
    played = ("straight", "social_force", "onboard", "predictive", "oracle")
    assert EXPERIMENT_BASELINES == played
    assert [name for name, _, _ in experiment_baselines(experiment)] == [f"baseline_{name}" for name in played]
    document = tiny_experiment_document()
    document["configurations"][1]["train"]["scenario"] = "room_furniture"
    names = [name for name, _, _ in experiment_baselines(experiment_from_mapping(document))]
    assert names == [f"baseline_{name}_{first}" for first in ("lidar", "closest") for name in played]


def test_a_baseline_that_refuses_the_scenario_is_one_line_and_the_others_are_played(tmp_path):
    from crowdnav.evaluation.baselines import evaluate_experiment_baselines

    document = tiny_experiment_document(seeds=1, test_episodes=2)
    document["configurations"] = document["configurations"][:1]
    document["defaults"]["overrides"] = {**document["defaults"]["overrides"], "robot.kinematics": "unicycle", "robot.max_angular_speed": 2.0}
    done = evaluate_experiment_baselines(experiment_from_mapping(document), tmp_path / "results")
    refused = {item.split(" skipped: ")[0]: item.split(" skipped: ")[1] for item in done if isinstance(item, str)}
    assert set(refused) == {f"baseline {BASELINES[name]}" for name in ("onboard", "predictive", "oracle")}
    assert refused[f"baseline {BASELINES['onboard']}"] == ("PlannerUnavailable: the onboard planner plans lattice moves for a holonomic "
                                                           "robot; this scenario's robot is unicycle")
    assert [path.parent.name for path in done if not isinstance(path, str)] == ["baseline_straight", "baseline_social_force"]


def test_configuration_names_starting_with_baseline_are_refused():
    document = tiny_experiment_document()
    document["configurations"][0]["name"] = "baseline_mine"
    with pytest.raises(ExperimentError, match="kept for the scripted baselines"):
        experiment_from_mapping(document)


def test_benchmark_results_rank_the_baselines_and_draw_them_as_horizontal_lines(tmp_path_factory):
    results = tiny_results(tmp_path_factory)
    tests, _, metas = load_results([results])
    table = leaderboard_table(tests, metas)
    baselines = table[table["kind"] == "baseline"]
    assert sorted(baselines["configuration"]) == ["baseline_onboard", "baseline_oracle", "baseline_predictive", "baseline_social_force",
                                                  "baseline_straight"]
    assert (baselines["seeds"] == 1).all() and all(map(is_baseline, baselines["configuration"]))
    figure = curves_figure(tests, window=3)
    # one horizontal line per baseline in every outcome panel, each with dashes of its own
    for axis in figure.axes:
        horizontal = [line for line in axis.get_lines() if line.get_label() in BASELINES.values()]
        assert len(horizontal) == len(EXPERIMENT_BASELINES) and all(len(set(line.get_ydata())) == 1 for line in horizontal)
        assert len({str(line.get_linestyle()) + str(line._dash_pattern) for line in horizontal}) == len(horizontal)


def test_a_baseline_that_cannot_be_played_is_reported_and_the_others_are_played(tmp_path):
    from crowdnav.evaluation.baselines import evaluate_experiment_baselines

    scenario = tmp_path / "gone.yaml"
    document = tiny_experiment_document(seeds=1)
    from crowdnav.scenario.library import library_dir

    scenario.write_text((library_dir() / "open_space.yaml").read_text())
    document["configurations"][1]["train"]["scenario"] = str(scenario)
    experiment = experiment_from_mapping(document)
    scenario.unlink()
    done = evaluate_experiment_baselines(experiment, tmp_path / "results")
    assert [isinstance(item, str) for item in done] == [False] * len(EXPERIMENT_BASELINES) + [True] * len(EXPERIMENT_BASELINES)
    first_skipped = done[len(EXPERIMENT_BASELINES)]
    assert "gone.yaml" in first_skipped and first_skipped.startswith("baseline straight to goal (scripted) [closest] skipped: ")


def test_a_shielded_configuration_brings_straight_and_social_force_with_its_shield_and_an_unshielded_one_none():
    document = tiny_experiment_document()
    document["defaults"] = {**document["defaults"], "scenario": "room_furniture"}
    assert not any("shield" in name for name, _, _ in experiment_baselines(experiment_from_mapping(document)))
    document["configurations"][1]["train"]["shield"] = {"horizon": 1.0}
    baselines = {name: options for name, _, options in experiment_baselines(experiment_from_mapping(document))}
    assert set(baselines) == {f"baseline_{name}" for name in (*EXPERIMENT_BASELINES, "straight_shield", "social_force_shield")}
    for name in ("straight_shield", "social_force_shield"):
        assert baselines[f"baseline_{name}"] == {**baselines["baseline_straight"], "shield": {"horizon": 1.0}}
    assert "shield" not in baselines["baseline_straight"]


def test_shielded_baselines_play_the_scripted_robot_through_the_envs_shield(tmp_path):
    options = {"scenario": "room_furniture", "modalities": ["goal"], "overrides": {"max_steps": 60}, "reward_weights": {}}
    protocol = Protocol(train_episodes=2, eval_every=2, test_episodes=3, seeds=1, test_seed_base=3)
    guarded = {**options, "shield": True}
    for name, policy in (("straight_shield", StraightToGoal()), ("social_force_shield", SocialForceRobot())):
        folder = evaluate_baseline("x", f"baseline_{name}", BASELINES[name], guarded, protocol, tmp_path / name)
        tests = pd.read_csv(folder / TEST_FILE, keep_default_na=False)
        assert list(tests["outcome"]) == [_outcome(policy, guarded, seed) for seed in range(3, 6)]
        assert read_json(folder / META_FILE)["env"]["shield"] is True


def test_evaluate_plays_baseline_straight_shield_with_the_default_shield():
    from crowdnav.evaluation.evaluate import resolve_policy

    name, label, _, privileged, options = resolve_policy("baseline:straight_shield", {"scenario": "room_furniture"})
    assert (name, label, privileged, options["shield"]) == ("baseline_straight_shield", BASELINES["straight_shield"], True, True)
    assert "shield" not in resolve_policy("baseline:straight", {"scenario": "room_furniture"})[4]
