"""crowdnav evaluate: any policy (baseline, callable, SB3 zip, crowdnav run) on the same fixed test episodes."""

from __future__ import annotations

import sys
import textwrap

import numpy as np
import pytest
from crowdnav.evaluation.evaluate import PolicyError, ResultsExistError, evaluate_policy
from crowdnav.evaluation.leaderboard import write_leaderboard

from crowdnav.cli import main

TOWARD_GOAL = textwrap.dedent('''
    import numpy as np

    def toward_goal(observation):
        distance, sin, cos = observation["goal"]
        return np.array([cos, sin], dtype=np.float32)

    def broken(observation):
        return "forward"

    def raising(observation):
        return observation["lidar"]

    def exiting(observation):
        raise SystemExit(0)
''')


@pytest.fixture
def module_on_path(importable_module):
    return importable_module("my_policies", TOWARD_GOAL)


def test_a_callable_that_drives_at_the_goal_scores_exactly_the_straight_baseline(tmp_path, module_on_path):
    ours = evaluate_policy(f"{module_on_path}:toward_goal", "open_space", tmp_path, modalities=["goal"], episodes=6)
    baseline = evaluate_policy("baseline:straight", "open_space", tmp_path, episodes=6)
    table, _ = write_leaderboard([tmp_path], tmp_path / "board")
    rows = table.set_index("configuration")
    assert rows.loc["my_policies_toward_goal--open_space", "final_success_mean"] == rows.loc["baseline_straight--open_space", "final_success_mean"]
    assert ours.name == baseline.name == "seeds_0-5" and (ours / "test_episodes.csv").is_file()


def test_results_are_keyed_by_policy_scenario_and_test_set_and_never_overwritten_without_force(tmp_path):
    first = evaluate_policy("baseline:straight", "open_space", tmp_path, episodes=3)
    other_scenario = evaluate_policy("baseline:straight", "empty_room", tmp_path, episodes=3)
    other_seeds = evaluate_policy("baseline:straight", "open_space", tmp_path, episodes=3, test_seed_base=100)
    overridden = evaluate_policy("baseline:straight", "open_space", tmp_path, episodes=3, overrides={"humans.count": 2})
    assert len({first, other_scenario, other_seeds, overridden}) == 4
    assert first.relative_to(tmp_path).as_posix() == "evaluate/baseline_straight--open_space/seeds_0-2"
    assert other_seeds.name == "seeds_100-102" and overridden.parent.name.startswith("baseline_straight--open_space-")
    written = (first / "test_episodes.csv").read_bytes()
    with pytest.raises(ResultsExistError, match="already holds .* pass --force"):
        evaluate_policy("baseline:straight", "open_space", tmp_path, episodes=3)
    assert (first / "test_episodes.csv").read_bytes() == written
    assert evaluate_policy("baseline:straight", "open_space", tmp_path, episodes=3, force=True) == first
    (first / "meta.json").unlink()  # an evaluation stopped before its last write: not a result, replaced without --force
    (first / "test_episodes.csv").write_text("cut")
    assert evaluate_policy("baseline:straight", "open_space", tmp_path, episodes=3) == first
    assert (first / "test_episodes.csv").read_bytes() == written


def test_an_sb3_zip_is_evaluated_and_a_space_mismatch_is_one_clear_line(tmp_path):
    from stable_baselines3 import PPO

    from crowdnav import CrowdNavEnv

    model = PPO("MultiInputPolicy", CrowdNavEnv("open_space", modalities=["goal"]), n_steps=32, batch_size=16, seed=0)
    model.save(tmp_path / "my_ppo.zip")
    folder = evaluate_policy(str(tmp_path / "my_ppo.zip"), "open_space", tmp_path / "results", modalities=["goal"], episodes=3)
    assert folder.parent.name == "my_ppo--open_space"
    again = evaluate_policy(str(tmp_path / "my_ppo.zip"), "open_space", tmp_path / "again", episodes=3)  # keys read from the zip
    assert (again / "test_episodes.csv").read_bytes() == (folder / "test_episodes.csv").read_bytes()
    with pytest.raises(PolicyError, match=r"expects observations \{goal: \(3,\)\}, but the scenario with modalities \['lidar'\] gives"):
        evaluate_policy(str(tmp_path / "my_ppo.zip"), "open_space", tmp_path / "results", modalities=["lidar"], episodes=3)


def test_a_misspelled_baseline_gets_a_did_you_mean_from_the_python_api_too(tmp_path):
    with pytest.raises(PolicyError, match=r"unknown baseline 'straigth'; did you mean 'baseline:straight'\?"):
        evaluate_policy("baseline:straigth", "open_space", tmp_path / "results", episodes=1)


def test_bad_policies_are_one_line_errors(tmp_path, module_on_path, capsys):
    assert main(["evaluate", "nowhere:nothing", "--scenario", "open_space", "--out", str(tmp_path)]) == 1
    assert "cannot import 'nothing' from 'nowhere'" in capsys.readouterr().err
    assert main(["evaluate", "baseline:teleport", "--scenario", "open_space", "--out", str(tmp_path)]) == 1
    assert "unknown baseline 'teleport'; expected one of: baseline:straight, baseline:social_force" in capsys.readouterr().err
    assert main(["evaluate", f"{module_on_path}:broken", "--scenario", "open_space", "--modalities", "goal", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "must be 2 numbers" in err
    assert main(["evaluate", f"{module_on_path}:raising", "--scenario", "open_space", "--modalities", "goal", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "my_policies:raising raised KeyError: 'lidar' while acting" in err
    assert main(["evaluate", f"{module_on_path}:exiting", "--scenario", "open_space", "--modalities", "goal", "--out", str(tmp_path)]) == 1
    assert "raised SystemExit" in capsys.readouterr().err
    assert main(["evaluate", f"{module_on_path}:raising", "--scenario", "open_space", "--modalities", "goal", "--out", str(tmp_path),
                 "--traceback", "--no-progress"]) == 1
    assert "Traceback" in capsys.readouterr().err and not (tmp_path / "evaluate" / "my_policies_raising--open_space").exists()


def test_a_module_next_to_where_the_command_runs_imports_without_pythonpath(tmp_path, monkeypatch, capsys):
    (tmp_path / "beside_me.py").write_text(TOWARD_GOAL)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [entry for entry in sys.path if entry not in ("", str(tmp_path))])
    try:
        assert main(["evaluate", "beside_me:toward_goal", "--scenario", "open_space", "--modalities", "goal", "--episodes", "2",
                     "--out", "results", "--no-progress"]) == 0
    finally:
        sys.modules.pop("beside_me", None)
    assert (tmp_path / "results" / "evaluate" / "beside_me_toward_goal--open_space" / "seeds_0-1" / "test_episodes.csv").is_file()


def test_both_spellings_of_a_baseline_name_the_same_policy(tmp_path):
    dashed = evaluate_policy("baseline:social-force", "open_space", tmp_path / "a", episodes=2)
    underscored = evaluate_policy("baseline:social_force", "open_space", tmp_path / "b", episodes=2)
    assert (dashed / "test_episodes.csv").read_bytes() == (underscored / "test_episodes.csv").read_bytes()


def test_a_crowdnav_run_is_evaluated_by_its_parameters_with_its_own_modalities(tmp_path):
    from crowdnav.agents import train

    from tests.agents.agents_tiny import tiny_config

    train(tiny_config(tmp_path / "runs" / "sac", modalities=["goal", "closest_obstacle"], episodes=2))
    folder = evaluate_policy(str(tmp_path / "runs" / "sac"), "open_space", tmp_path / "results", episodes=3)
    assert folder.parent.name == "sac--open_space"
    import json

    meta = json.loads((folder / "meta.json").read_text())
    assert meta["env"]["modalities"] == ["goal", "closest_obstacle"] and meta["test_episodes"] == 3
    assert np.isclose(sum(meta["final"].values()), 1.0)


def test_a_run_evaluated_in_its_own_scenario_with_set_plays_the_changed_setting_on_top_of_its_own(tmp_path):
    import json

    from crowdnav.agents import train

    from tests.agents.agents_tiny import tiny_config

    run = tmp_path / "runs" / "sac"
    train(tiny_config(run, modalities=["goal", "closest_obstacle"], episodes=1, overrides={"humans.count": 2, "max_steps": 7}))
    denser = evaluate_policy(str(run), "open_space", tmp_path / "results", episodes=2, overrides={"humans.count": 4})
    meta = json.loads((denser / "meta.json").read_text())
    assert meta["env"]["overrides"] == {"humans.count": 4, "max_steps": 7}  # --set wins, the run's other settings stay
    rows = (denser / "test_episodes.csv").read_text().splitlines()
    own = evaluate_policy(str(run), "open_space", tmp_path / "own", episodes=2)
    assert json.loads((own / "meta.json").read_text())["env"]["overrides"] == {"humans.count": 2, "max_steps": 7}
    assert rows != (own / "test_episodes.csv").read_text().splitlines()


def test_render_takes_the_same_policy_forms_as_evaluate(tmp_path, module_on_path):
    for policy, extra in ((f"{module_on_path}:toward_goal", ["--modalities", "goal"]), ("baseline:social_force", [])):
        code = main(["render", "open_space", "--policy", policy, *extra, "--episodes", "1", "--format", "gif", "--out", str(tmp_path),
                     "--no-progress"])
        assert code == 0
    names = sorted(path.name for path in tmp_path.glob("*.gif"))
    assert names[0] == "open_space_baseline_social_force_seed0_success.gif"  # the privileged robot reaches the goal
    assert names[1].startswith("open_space_my_policies_toward_goal_seed0_") and len(names) == 2


def test_evaluated_policies_are_reference_lines_in_the_curves_next_to_trained_runs(tmp_path_factory, tmp_path, module_on_path):
    import shutil

    from crowdnav.evaluation.curves import curves_figure
    from crowdnav.evaluation.storage import load_results

    from tests.evaluation.evaluation_tiny import tiny_results

    results = tmp_path / "results"
    shutil.copytree(tiny_results(tmp_path_factory), results)
    evaluate_policy(f"{module_on_path}:toward_goal", "open_space", results, modalities=["goal"], episodes=3)
    evaluate_policy(f"{module_on_path}:toward_goal", "open_space", results, modalities=["goal"], episodes=3, name="second")
    tests, _, _ = load_results([results])
    figure = curves_figure(tests, window=2)
    lines = figure.axes[0].get_lines()
    flat = [line for line in lines if len(set(line.get_ydata())) == 1 and line.get_label() in ("my_policies:toward_goal", "second")]
    assert len(flat) == 2 and len({(line.get_linestyle(), line.get_color()) for line in flat}) == 2  # each its own style
    assert main(["plot", str(results / "evaluate"), "--out", str(tmp_path / "curves")]) == 0


def test_a_plot_of_policies_without_training_draws_one_bar_per_policy_each_its_own_style(tmp_path, module_on_path):
    from crowdnav.evaluation.curves import curves_figure
    from crowdnav.evaluation.storage import load_results

    evaluate_policy(f"{module_on_path}:toward_goal", "open_space", tmp_path, modalities=["goal"], episodes=3)
    evaluate_policy("baseline:social_force", "open_space", tmp_path, episodes=3)
    tests, _, _ = load_results([tmp_path])
    figure = curves_figure(tests, window=2)
    axis = figure.axes[0]
    bars = axis.patches
    assert len(bars) == 2 and len({bar.get_hatch() for bar in bars}) == 2 and len({bar.get_facecolor() for bar in bars}) == 2
    assert "training" not in axis.get_xlabel() and [tick.get_text() for tick in axis.get_xticklabels()] == sorted(set(tests["label"]))
    assert main(["plot", str(tmp_path / "evaluate"), "--out", str(tmp_path / "bars")]) == 0
