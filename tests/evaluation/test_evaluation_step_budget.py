"""Protocols in env steps: validation, the runs' snapshots and columns, curves and leaderboard labels; episodes unchanged."""

from __future__ import annotations

import json

import crowdnav.agents
import pandas as pd
import pytest
import yaml
from crowdnav.agents import train_seed
from crowdnav.evaluation.benchmark import claim_folder, run_experiment
from crowdnav.evaluation.curves import curves_figure, rate_curves
from crowdnav.evaluation.experiment import ExperimentError, experiment_from_mapping, load_experiment
from crowdnav.evaluation.leaderboard import to_markdown, write_leaderboard
from crowdnav.evaluation.progress import episodes_on_disk, logged_steps, run_episodes
from crowdnav.evaluation.protocol import MAX_WORLDS, QUICK_STEPS, UNITS, Protocol, describe_budget, protocol_unit, quick
from crowdnav.evaluation.runner import UnitSpec, run_unit
from crowdnav.evaluation.storage import ResultsError, load_results

from crowdnav.sim.simulator import OUTCOMES
from tests.evaluation.evaluation_tiny import tiny_experiment_document, tiny_unit_spec

STEPS = {"train_steps": 400, "eval_every_steps": 200}
"""Two evaluations of a run of 4 worlds: about 10 tiny episodes, a second or two."""
PAPER_DICT = {"train_episodes": 700, "eval_every": 50, "test_episodes": 20, "seeds": 5, "test_seed_base": 0, "window": 10,
              "final_evaluations": 3}
"""Protocol().to_dict() as crowdnav wrote it before budgets in env steps: spec.json and experiment.yaml of older results."""


def step_document(**protocol):
    """The tiny experiment (2 configurations, 1 seed) in env steps, 4 worlds per run."""
    document = tiny_experiment_document(seeds=1)
    for key in ("train_episodes", "eval_every"):
        del document["protocol"][key]
    document["protocol"].update({**STEPS, **protocol})
    document["defaults"]["num_envs"] = 4
    return document


def step_spec():
    spec = tiny_unit_spec()
    for key in ("train_episodes", "eval_every"):
        del spec["protocol"][key]
    spec["protocol"].update(STEPS)
    spec["train"]["num_envs"] = 4
    return spec


# ------------------------------------------------------------------ the protocol


def test_the_papers_700_episode_protocol_is_unchanged():
    protocol = Protocol()
    assert protocol.unit == "episodes" and protocol.budget == 700 and protocol.interval == 50
    assert protocol.evaluation_points == list(range(50, 701, 50))
    assert protocol.to_dict() == PAPER_DICT  # older spec.json files still match: their runs are skipped, not retrained
    assert Protocol(**PAPER_DICT) == protocol and protocol_unit(PAPER_DICT) == "episodes"
    assert protocol.point_column == "training_episodes" and protocol.describe_budget() == "700 episodes"
    assert load_experiment("modalities").protocol.to_dict() == PAPER_DICT


def test_a_protocol_in_env_steps_evaluates_at_multiples_of_its_interval():
    from crowdnav.agents.runs.folder import UNITS as SNAPSHOT_UNITS

    assert UNITS == SNAPSHOT_UNITS  # a protocol's unit names its runs' snapshots
    protocol = Protocol(train_steps=2_000_000, eval_every_steps=100_000)
    assert protocol.unit == "steps" and protocol.point_column == "training_steps"
    assert protocol.evaluation_points == list(range(100_000, 2_000_001, 100_000)) and protocol.evaluations == 20
    assert Protocol(train_steps=250, eval_every_steps=100).evaluation_points == [100, 200]  # stops at the budget
    assert protocol.describe_budget() == "2,000,000 env steps" == describe_budget(protocol.to_dict())
    assert "train_episodes" not in protocol.to_dict() and "eval_every" not in protocol.to_dict()
    assert Protocol(**protocol.to_dict()) == protocol and protocol_unit(protocol.to_dict()) == "steps"


@pytest.mark.parametrize("fields, message", [
    ({"train_steps": 1000}, "eval_every_steps: a budget in env steps needs both train_steps and eval_every_steps"),
    ({"eval_every_steps": 100}, "train_steps: a budget in env steps needs both"),
    ({"train_steps": 100, "eval_every_steps": 200}, "eval_every_steps: 200 is more than train_steps \\(100\\): no evaluation would run"),
    ({"train_steps": 0, "eval_every_steps": 1}, "train_steps: expected an integer >= 1, got 0"),
    ({"train_steps": 100.0, "eval_every_steps": 10}, "train_steps: expected an integer >= 1, got 100.0"),
    ({"train_steps": 100, "eval_every_steps": True}, "eval_every_steps: expected an integer >= 1, got True"),
    ({"train_steps": 100, "eval_every_steps": 10, "train_episodes": 700}, "train_episodes: the budget is in env steps"),
    ({"train_steps": 100, "eval_every_steps": 10, "eval_every": 5}, "eval_every: the budget is in env steps"),
])
def test_invalid_step_budgets_are_refused_with_the_field_name(fields, message):
    with pytest.raises(ValueError, match=message):
        Protocol(**fields)


def test_quick_shrinks_a_protocol_in_its_own_unit():
    steps = quick(Protocol(train_steps=2_000_000, eval_every_steps=100_000, test_seed_base=7))
    assert steps.unit == "steps" and steps.evaluation_points == [QUICK_STEPS["eval_every_steps"], QUICK_STEPS["train_steps"]]
    assert steps.test_seed_base == 7 and steps.seeds == 1
    assert quick(Protocol()).evaluation_points == [10, 20]


def test_step_budget_training_seeds_bound_every_episode_the_run_can_start():
    from crowdnav.agents.training.config import TrainConfig

    # the bound counts the first reset's episodes: it must cover the most worlds a config allows
    limit = next(item.le for item in TrainConfig.model_fields["num_envs"].metadata if hasattr(item, "le"))
    assert MAX_WORLDS == limit
    protocol = Protocol(train_steps=1000, eval_every_steps=100, seeds=2)
    seeds = protocol.training_seeds(1)
    # one world: at most one episode per env step, plus the one the last step starts
    assert {train_seed(1, episode) for episode in range(1001)} <= set(seeds)
    protocol.check_disjoint()  # test seeds 0..19, far below every training seed
    near = Protocol(train_steps=1000, eval_every_steps=100, seeds=2, test_seed_base=train_seed(1, 1000 + 2 * MAX_WORLDS - 1))
    with pytest.raises(ValueError, match="also training seeds of run seed 1"):
        near.check_disjoint()
    Protocol(train_steps=1000, eval_every_steps=100, seeds=2, test_seed_base=train_seed(1, 1000 + 2 * MAX_WORLDS)).check_disjoint()


# ------------------------------------------------------------------ experiment files


def test_an_experiment_file_states_its_budget_in_env_steps(tmp_path):
    experiment = experiment_from_mapping(step_document())
    assert experiment.protocol.unit == "steps" and experiment.protocol.evaluation_points == [200, 400]
    spec, out = experiment.units(tmp_path)[0]
    config = spec.config_for(out)
    assert (config.timesteps, config.checkpoint_every_steps) == (400, 200)
    assert config.episodes == 700 and config.checkpoint_every == 50  # the TrainConfig defaults, ignored with timesteps
    episodes = UnitSpec(**{**spec.to_dict(), "protocol": Protocol().to_dict()}).config_for(out)
    assert (episodes.timesteps, episodes.checkpoint_every_steps, episodes.episodes) == (None, None, 700)


@pytest.mark.parametrize("change, message", [
    ({"protocol": {"eval_every_steps": None}}, "protocol.eval_every_steps: a budget in env steps needs both"),
    ({"protocol": {"eval_every_steps": 2}}, "protocol.eval_every_steps: 2 is less than num_envs \\(4\\) of configuration 'lidar'"),
    ({"defaults": {"timesteps": 100}}, "defaults.timesteps: 'timesteps' is set by the protocol"),
    ({"defaults": {"checkpoint_every_steps": 100}}, "defaults.checkpoint_every_steps: 'checkpoint_every_steps' is set by the protocol"),
])
def test_step_budget_problems_in_an_experiment_file_name_the_field(change, message):
    document = step_document()
    for section, fields in change.items():
        document[section].update(fields)
    with pytest.raises(ExperimentError, match=message):
        experiment_from_mapping(document)


def test_quick_refuses_an_interval_shorter_than_one_step_of_all_worlds():
    document = step_document(train_steps=10_000, eval_every_steps=5_000)
    document["defaults"]["num_envs"] = 4096
    experiment = experiment_from_mapping(document)
    with pytest.raises(ExperimentError, match="protocol.eval_every_steps: 2000 is less than num_envs \\(4096\\)"):
        experiment.with_options(quick_protocol=True)


# ------------------------------------------------------------------ a run, end to end


@pytest.fixture(scope="module")
def step_results(tmp_path_factory):
    experiment = experiment_from_mapping(step_document())
    report = run_experiment(experiment, tmp_path_factory.mktemp("steps"), workers=1, progress=False, video=False, log=lambda line: None)
    assert not report.failures, report.failures
    return experiment, report


def test_a_step_budget_experiment_evaluates_each_snapshot_at_its_env_step_point(step_results):
    experiment, report = step_results
    run = report.folder / "lidar" / "seed_0"
    tests = pd.read_csv(run / "test_episodes.csv")
    columns = list(tests.columns)
    assert columns[:7] == ["experiment", "configuration", "label", "seed", "training_episodes", "training_steps", "evaluation"]
    points = tests.drop_duplicates("evaluation")
    assert list(points["training_steps"]) == [200, 400]
    for _, row in points.iterrows():  # the snapshot named by the point; the episodes it had finished then
        info = json.loads((run / "train" / "snapshots" / f"steps_{row['training_steps']:09d}" / "policy.json").read_text())
        assert row["training_episodes"] == info["episodes"] and row["training_steps"] <= info["timesteps"] < row["training_steps"] + 4
    meta = json.loads((run / "meta.json").read_text())
    assert meta["protocol"] == experiment.protocol.to_dict() and meta["config"]["timesteps"] == 400
    assert 400 <= meta["env_steps"]["train"] < 404
    baseline = pd.read_csv(report.folder / "baseline_straight" / "baseline" / "test_episodes.csv").drop_duplicates("evaluation")
    assert list(baseline["training_steps"]) == [200, 400] and set(baseline["training_episodes"]) == {0}


def test_curves_and_leaderboard_say_the_budget_was_in_env_steps(step_results, tmp_path):
    _, report = step_results
    tests, _, metas = load_results([report.folder])
    figure = curves_figure(tests, window=3)
    assert {axis.get_xlabel() for axis in figure.axes[:4]} == {"training env steps"}
    curves = rate_curves(tests[tests["configuration"] == "lidar"], window=3, unit="steps")
    assert curves["training_steps"].max() == 400
    table, written = write_leaderboard([report.folder], tmp_path / "board")
    budgets = table.groupby("kind")["budget"].unique()
    assert list(budgets["learned"]) == ["400 env steps"] and list(budgets["baseline"]) == ["-"]
    assert written[0].read_text().splitlines()[-1] == "budget: 400 env steps per run"
    assert "budget" in written[1].read_text().splitlines()[0]
    rates = pd.read_csv(written[2])
    assert list(rates.loc[rates["configuration"] == "lidar", "training_steps"]) == [200, 400]


def test_a_finished_step_run_is_skipped_and_a_protocol_in_the_other_unit_refused(step_results):
    experiment, report = step_results
    again = run_experiment(experiment, report.folder.parent, workers=1, progress=False, video=False, log=lambda line: None)
    assert {summary["status"] for summary in again.summaries} == {"skipped"}
    in_episodes = experiment_from_mapping(tiny_experiment_document(seeds=1))
    with pytest.raises(ResultsError, match="protocol differ: its budget is in env steps, this one's in episodes"):
        claim_folder(report.folder, in_episodes)
    record = yaml.safe_load((report.folder / "experiment.yaml").read_text())
    assert record["protocol"]["train_steps"] == 400 and "train_episodes" not in record["protocol"]


def test_a_run_whose_unit_changed_starts_afresh_and_keeps_the_old_one_aside(tmp_path):
    spec = tiny_unit_spec(train_episodes=2, eval_every=2, test_episodes=2)
    spec["train"]["num_envs"] = 2
    run_unit(spec, tmp_path / "run")
    steps = {**spec, "protocol": {key: value for key, value in spec["protocol"].items() if key not in ("train_episodes", "eval_every")}}
    steps["protocol"].update(train_steps=80, eval_every_steps=80)
    summary = run_unit(steps, tmp_path / "run")
    assert summary["status"] == "done"
    assert list(pd.read_csv(tmp_path / "run" / "test_episodes.csv")["training_steps"].unique()) == [80]
    old = pd.read_csv(tmp_path / "run.replaced-1" / "test_episodes.csv")
    assert "training_steps" not in old.columns and list(old["training_episodes"].unique()) == [2]


def test_an_interrupted_step_run_resumes_training_and_evaluates_only_the_missing_points(tmp_path, monkeypatch):
    spec = step_spec()
    full = crowdnav.agents.train

    def stopped_half_way(config, **options):  # as if killed after the checkpoint at 200 env steps
        return full(config.model_copy(update={"timesteps": 200}), **options)

    monkeypatch.setattr(crowdnav.agents, "train", stopped_half_way)
    with pytest.raises(ResultsError, match="no policy snapshot for evaluation\\(s\\) \\[1\\] \\(after \\[400\\] training env steps\\)"):
        run_unit(spec, tmp_path)
    first = tmp_path / "evaluations" / "evaluation_000.csv"
    written = first.stat().st_mtime_ns
    assert 0 < logged_steps(tmp_path / "train") <= episodes_on_disk(tmp_path, Protocol(**spec["protocol"])) <= 200
    monkeypatch.setattr(crowdnav.agents, "train", full)
    events = []
    summary = run_unit(spec, tmp_path, on_event=lambda event, data: events.append((event, data.get("training_steps"), data.get("steps"))))
    assert events == [("trained", None, 400), ("evaluated", 400, None)]
    assert summary["status"] == "done" and summary["resumed"] and first.stat().st_mtime_ns == written
    tests = pd.read_csv(tmp_path / "test_episodes.csv")
    assert list(tests.drop_duplicates("evaluation")["training_steps"]) == [200, 400] and not tests.duplicated(["evaluation", "test_episode"]).any()
    assert episodes_on_disk(tmp_path, Protocol(**spec["protocol"])) == run_episodes(Protocol(**spec["protocol"])) == 400
    assert run_unit(spec, tmp_path)["status"] == "skipped"


def test_results_without_a_unit_read_as_episodes():
    rows = [{"experiment": "x", "configuration": "a", "label": "A", "seed": 0, "training_episodes": 10 * (k + 1), "evaluation": k,
             "test_episode": 0, "outcome": "success"} for k in range(2)]
    figure = curves_figure(pd.DataFrame(rows), window=1)
    assert figure.axes[0].get_xlabel() == "training episodes"
    assert describe_budget({"train_episodes": 700, "eval_every": 50}) == "700 episodes" and describe_budget({"window": 3}) == "-"
    rates = [f"final_{o}_{k}" for o in (*OUTCOMES, "collision_human", "collision_static") for k in ("mean", "std", "low", "high")]
    table = pd.DataFrame([{"experiment": "x", "label": "A", "seeds": 1, "budget": "700 episodes", "scenario": "s", "test_set": "t",
                           "interval": "wilson", **{k: 0.0 for k in (
        *rates, "success_iqm", "success_iqm_low", "success_iqm_high", "success_auc_mean", "success_auc_std", "spl", "stl", "psc",
        "min_human_distance", "intimate_share", "social_force", "env_steps", "wall_time_s")}}])
    assert to_markdown(table).splitlines()[-1] == "budget: 700 episodes per run"
    several = pd.concat([table, table.assign(experiment="y", budget="2,000,000 env steps")], ignore_index=True)
    markdown = to_markdown(several)
    assert "| experiment | configuration | seeds | budget |" in markdown and "| y | A | 1 | 2,000,000 env steps |" in markdown
