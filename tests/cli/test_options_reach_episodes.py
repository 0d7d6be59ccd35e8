"""Every option of `crowdnav evaluate` and `crowdnav render` reaches the episodes played, or is refused in one line naming it,
for every policy form: a baseline, a module:function, an SB3 run, a SARL run and a shared robot policy (`--agents robots`).

"Reaches" is read from what was played: the episodes' rows (seeds, steps) and the env the results' meta.json records,
built again (a run's own sensor settings and reward weights used to win over --set there, recorded but never played).
"""

from __future__ import annotations

import csv
import json
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

from crowdnav.cli import main
from crowdnav.envs import CrowdNavEnv

pytest.importorskip("torch")

HALL = "robots_crossing_hall"
FORMS = ("baseline", "callable", "sb3", "sarl")
CALLABLE = "options_reach_policy"


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> Iterator[dict[str, str]]:
    """POLICY of each form; the tiny runs trained once (~4 s). The SB3 run sets its own lidar range and collision weight."""
    from crowdnav.agents import train

    from tests.agents.agents_tiny import SMALL_LEOG, tiny_config
    from tests.agents.test_sarl import config as sarl_config

    folder = tmp_path_factory.mktemp("runs")
    (folder / f"{CALLABLE}.py").write_text("import numpy as np\n\ndef act(observation):\n    return np.array([0.5, 0.0])\n")
    sys.path.insert(0, str(folder))
    train(tiny_config(folder / "sb3", algo="sac", episodes=2, max_steps=20, reward_weights={"collision": -10.0},
                      sensors={**SMALL_LEOG, "lidar": {"beams": 32, "max_range": 4.0}}))
    train(sarl_config(folder / "sarl", episodes=2))
    config = {"scenario": HALL, "algo": "ppo", "num_envs": 2, "timesteps": 96, "n_steps": 16, "batch_size": 48, "net_arch": [16],
              "seed": 0, "out": str(folder / "robots"), "progress": False, "overrides": {"max_steps": 20}}
    (folder / "robots.yaml").write_text(yaml.safe_dump(config), encoding="utf-8")
    assert main(["train", "--config", str(folder / "robots.yaml"), "--agents", "robots"]) == 0
    yield {"baseline": "baseline:straight", "callable": f"{CALLABLE}:act", "sb3": str(folder / "sb3"), "sarl": str(folder / "sarl"),
           "robots": str(folder / "robots")}
    sys.path.remove(str(folder))
    sys.modules.pop(CALLABLE, None)


def _evaluate(policy: str, out: Path, *options: str) -> int:
    return main(["evaluate", policy, "--scenario", "open_space", "--episodes", "2", "--out", str(out), "--no-progress", *options])


def _result(out: Path) -> tuple[dict, list[dict[str, str]]]:
    """(meta.json, episode rows) of the one result under ``out``."""
    (meta_path,) = out.glob("evaluate/*/seeds_*/meta.json")
    with open(meta_path.with_name("test_episodes.csv"), encoding="utf-8") as file:
        return json.loads(meta_path.read_text()), list(csv.DictReader(file))


def _played(meta: dict) -> CrowdNavEnv:
    """The env the results say was played, built again from meta.json."""
    return CrowdNavEnv(**meta["env"])


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("form", FORMS)
def test_episodes_and_test_seed_base_choose_the_seeds_played(runs, form, tmp_path):
    assert main(["evaluate", runs[form], "--scenario", "open_space", "--episodes", "3", "--test-seed-base", "7",
                 "--out", str(tmp_path), "--no-progress"]) == 0
    meta, rows = _result(tmp_path)
    assert [row["test_seed"] for row in rows] == ["7", "8", "9"] and meta["test_episodes"] == 3
    assert meta["protocol"]["test_seed_base"] == 7


@pytest.mark.parametrize("form", FORMS)
def test_set_of_a_scenario_field_is_played_on_top_of_a_runs_own_settings(runs, form, tmp_path):
    assert _evaluate(runs[form], tmp_path, "--set", "max_steps=3", "--set", "humans.count=2") == 0
    meta, rows = _result(tmp_path)
    env = _played(meta)
    assert env.scenario.max_steps == 3 and env.scenario.humans.count == 2
    assert all(int(row["steps"]) <= 3 for row in rows)  # the episodes themselves stopped at the limit --set gave


@pytest.mark.parametrize("form", FORMS)
def test_set_of_a_sensor_field_is_played_even_where_the_run_set_it_itself(runs, form, tmp_path):
    # the SB3 run trained with lidar max_range 4.0: its own setting used to win, recorded as 1.5 but played as 4.0
    assert _evaluate(runs[form], tmp_path, "--set", "sensors.lidar.max_range=1.5") == 0
    assert _played(_result(tmp_path)[0]).scenario.sensors.lidar.max_range == 1.5


@pytest.mark.parametrize("form", FORMS)
def test_set_of_a_reward_weight_is_played_even_where_the_run_set_it_itself(runs, form, tmp_path):
    assert _evaluate(runs[form], tmp_path, "--set", "reward.collision=-3") == 0
    assert _played(_result(tmp_path)[0]).scenario.reward.collision == -3


@pytest.mark.parametrize("form", FORMS)
def test_a_sensor_size_reaches_the_policies_that_take_it_and_is_refused_for_a_network_trained_on_another(runs, form, tmp_path, capsys):
    code = _evaluate(runs[form], tmp_path, "--set", "sensors.lidar.beams=64")
    if form == "sb3":  # its network reads 32 beams
        assert code == 1
        err = _one_line(capsys)
        assert "--set sensors.lidar.beams: " in err and "lidar: (32,)" in err and "lidar: (64,)" in err
    else:  # the SARL run does not read the lidar: the scan it is not given changes nothing it sees
        assert code == 0 and _played(_result(tmp_path)[0]).scenario.sensors.lidar.beams == 64


@pytest.mark.parametrize("form", FORMS)
def test_another_tracker_size_reaches_policies_that_take_it_and_is_refused_for_the_sarl_network(runs, form, tmp_path, capsys):
    code = _evaluate(runs[form], tmp_path, "--set", "sensors.humans.count=2")
    if form == "sarl":  # it was trained on 5 human slots: once a raw broadcast error while acting
        assert code == 1
        assert _one_line(capsys).startswith("crowdnav: error: --set sensors.humans.count: ")
    else:
        assert code == 0 and _played(_result(tmp_path)[0]).scenario.sensors.humans.count == 2


@pytest.mark.parametrize("form", FORMS)
def test_modalities_reach_a_callable_and_are_refused_for_what_reads_its_own(runs, form, tmp_path, capsys):
    code = _evaluate(runs[form], tmp_path, "--modalities", "goal")
    if form == "callable":
        meta, _ = _result(tmp_path)
        assert code == 0 and meta["observations"] == ["goal"] and list(_played(meta).observation_space.keys()) == ["goal"]
    else:  # a baseline reads the simulator, a run the keys it was trained on
        assert code == 1 and _one_line(capsys).startswith("crowdnav: error: --modalities")


@pytest.mark.parametrize("form", ["sb3", "sarl"])
def test_set_of_the_modalities_is_refused_for_a_run(runs, form, tmp_path, capsys):
    assert _evaluate(runs[form], tmp_path, "--set", "sensors.modalities=[goal]") == 1
    assert _one_line(capsys).startswith("crowdnav: error: --set sensors.modalities: ")


@pytest.mark.parametrize("form", FORMS)
def test_another_scenario_is_played_with_only_the_users_overrides(runs, form, tmp_path):
    assert main(["evaluate", runs[form], "--scenario", "empty_room", "--episodes", "2", "--set", "max_steps=4",
                 "--out", str(tmp_path), "--no-progress"]) == 0
    meta, rows = _result(tmp_path)
    env = _played(meta)
    assert meta["scenario"] == "empty_room" and env.scenario.name == "empty_room" and env.scenario.max_steps == 4
    assert meta["env"]["overrides"] == {"max_steps": 4}  # not the run's own humans.count
    assert all(int(row["steps"]) <= 4 for row in rows)


@pytest.mark.parametrize("form", FORMS)
def test_more_episodes_than_the_bound_are_refused_in_one_line(runs, form, tmp_path, capsys):
    from crowdnav.evaluation.evaluate import MAX_EPISODES

    assert main(["evaluate", runs[form], "--scenario", "open_space", "--episodes", str(MAX_EPISODES + 1), "--out", str(tmp_path)]) == 1
    assert _one_line(capsys) == f"crowdnav: error: --episodes must be from 1 to {MAX_EPISODES:,}, got {MAX_EPISODES + 1:,}"
    assert not (tmp_path / "evaluate").exists()


def test_evaluate_plays_a_shared_robot_policy_with_set_and_episodes_and_refuses_other_modalities(runs, tmp_path, capsys):
    """Its rows, one per robot per episode, and the other refusals: tests/cli/test_robots_evaluate.py."""
    assert main(["evaluate", runs["robots"], "--scenario", HALL, "--out", str(tmp_path), "--episodes", "1", "--set", "max_steps=3",
                 "--no-progress"]) == 0
    meta, rows = _result(tmp_path)
    assert meta["env"]["overrides"] == {"max_steps": 3} and len(rows) == 3 and all(int(row["steps"]) <= 3 for row in rows)
    assert main(["evaluate", runs["robots"], "--scenario", HALL, "--out", str(tmp_path / "other"), "--modalities", "goal"]) == 1
    assert "--modalities goal: " in _one_line(capsys) and not (tmp_path / "other").exists()


def _render(policy: str, out: Path, *options: str, scenario: str = "open_space") -> int:
    return main(["render", scenario, "--policy", policy, "--episodes", "1", "--format", "gif", "--out", str(out), "--no-progress", *options])


@pytest.mark.parametrize("form", FORMS)
def test_render_plays_set_seed_and_episodes(runs, form, tmp_path):
    assert _render(runs[form], tmp_path, "--set", "max_steps=1", "--seed", "4") == 0
    (video,) = tmp_path.iterdir()  # one step, no time to arrive: the name says how it ended
    assert "_seed4_" in video.name and video.name.endswith(("_truncated.gif", "_collision.gif"))


@pytest.mark.parametrize("form", ["sb3", "sarl"])
def test_render_refuses_what_a_runs_network_cannot_take_as_evaluate_does(runs, form, tmp_path, capsys):
    option = {"sb3": "sensors.lidar.beams=64", "sarl": "sensors.humans.count=2"}[form]
    assert _render(runs[form], tmp_path, "--set", option) == 1
    assert _one_line(capsys).startswith(f"crowdnav: error: --set {option.partition('=')[0]}: ")
    assert _render(runs[form], tmp_path, "--modalities", "goal") == 1
    assert _one_line(capsys).startswith("crowdnav: error: --modalities goal: ")


@pytest.mark.parametrize("policy", ["straight", "robots"])
def test_render_refuses_modalities_for_a_scripted_name_or_a_shared_robot_policy(runs, policy, tmp_path, capsys):
    assert _render(runs.get(policy, policy), tmp_path, "--modalities", "goal", scenario=HALL) == 1
    assert _one_line(capsys).startswith(f"crowdnav: error: --modalities: {runs.get(policy, policy)} reads ")


@pytest.mark.parametrize("options, refused", [(["--set", "max_steps=3"], "without overrides"), (["--reward", "paper"], "without reward_weights")])
def test_render_refuses_set_and_reward_for_a_shared_robot_policy(runs, options, refused, tmp_path, capsys):
    assert _render(runs["robots"], tmp_path, *options, scenario=HALL) == 1
    assert refused in _one_line(capsys)


def test_render_plays_a_shared_robot_policy_from_the_seed_given(runs, tmp_path):
    assert _render(runs["robots"], tmp_path, "--seed", "6", scenario=HALL) == 0
    (video,) = tmp_path.iterdir()
    assert video.name.startswith(f"{HALL}_robots_seed6_")


def test_another_geodesic_spacing_is_refused_for_a_sarl_network_reading_the_grid(tmp_path, capsys):
    """The grid's spacing changes no observation size but is a constant of the agent's lookahead: once played silently."""
    from crowdnav.agents import train

    from tests.agents.test_sarl import config as sarl_config

    modalities = ["humans", "goal", "velocity", "obstacles", "geodesic"]
    train(sarl_config(tmp_path / "run", episodes=1, scenario="room_furniture", modalities=modalities,
                      overrides={"humans.count": 2, "max_steps": 10}))
    code = main(["evaluate", str(tmp_path / "run"), "--scenario", "room_furniture", "--episodes", "1", "--out", str(tmp_path / "out"),
                 "--no-progress", "--set", "sensors.geodesic.spacing=0.2"])
    assert code == 1
    line = _one_line(capsys)
    assert line.startswith("crowdnav: error: --set: ") and "sensors.geodesic.spacing: this SARL agent was trained with 0.1 m" in line
    assert not (tmp_path / "out").exists() or not list((tmp_path / "out").rglob("meta.json"))
