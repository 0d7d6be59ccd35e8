"""ORCA crowds (``humans.model: orca``) and the ORCA robot baseline, through the optional package pyrvo.

Tests that need ORCA itself skip without pyrvo; the error paths simulate its absence by blocking
the import (``sys.modules["pyrvo"] = None``), so they run either way.
"""

from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest

from crowdnav.cli import main
from crowdnav.crowd.views import WorldView
from crowdnav.scenario import ScenarioError
from crowdnav.scenario.library import library_names
from crowdnav.sim.orca_solver import OrcaUnavailableError
from crowdnav.sim.simulator import Simulator
from crowdnav.worlds.compiled import load_world
from tests.core.test_vector_env import check_batch_equals_singles
from tests.paths import REPO

ROOT = REPO
ORCA = {"humans.model": "orca"}


@pytest.fixture
def no_pyrvo(monkeypatch):
    """The core install: ``import pyrvo`` fails."""
    monkeypatch.setitem(sys.modules, "pyrvo", None)


def _episode(sim: Simulator, seed: int, steps: int = 80) -> bytes:
    sim.reset(seed=seed)
    trace = [sim.positions.tobytes()]
    for k in range(steps):
        sim.step(np.array([np.cos(k / 7), np.sin(k / 5)]))
        trace.append(sim.positions.tobytes() + sim.velocities.tobytes())
    return b"".join(trace)


# ------------------------------------------------------------------ default and errors (no pyrvo needed)


def test_every_library_scenario_keeps_the_social_force_and_builds_no_orca_crowd(no_pyrvo):
    for name in library_names():
        sim = Simulator(name)
        assert list(sim.crowd.models) == ["social_force"]
        assert {group.model for _, group in sim.scenario.humans.crowd if not group.standing} <= {"social_force"}


def test_writing_model_social_force_gives_the_default_episode_bit_for_bit():
    assert _episode(Simulator("station_hall", {"humans.model": "social_force"}), 4) == _episode(Simulator("station_hall"), 4)


def test_an_unknown_model_name_is_one_line_naming_the_field_and_the_choices():
    with pytest.raises(ScenarioError) as error:
        load_world("open_space", {"humans.model": "rvo"})
    assert "humans.model: expected one of 'social_force', 'orca', 'replay', got 'rvo'" in str(error.value)
    assert len(str(error.value).splitlines()) == 1


def test_a_standing_group_refuses_a_model():
    with pytest.raises(ScenarioError, match="humans.groups.2: a standing group does not walk; remove model"):
        load_world("station_hall", {"humans.groups.2.model": "orca"})


def test_orca_without_pyrvo_fails_at_load_in_one_line_with_the_install_command(no_pyrvo):
    with pytest.raises(ScenarioError) as error:
        Simulator("open_space", ORCA)
    message = str(error.value)
    assert len(message.splitlines()) == 1
    assert re.match(r"\S*open_space\.yaml(:\d+)?: humans\.model: orca needs the optional package pyrvo", message), message
    assert 'which the core install leaves out: pip install -e ".[orca]" in crowdnav\'s clone' in message
    with pytest.raises(ScenarioError, match=r'humans.groups.1.model: orca needs .*pip install -e "\.\[orca\]" in crowdnav\'s clone'):
        Simulator("station_hall", {"humans.groups.1.model": "orca"})


def test_the_orca_robot_without_pyrvo_is_one_line_from_python_evaluate_and_render(no_pyrvo, capsys, tmp_path):
    from crowdnav.planning.scripted import OrcaRobot

    with pytest.raises(OrcaUnavailableError, match=r"^the ORCA robot \(baseline:orca\) needs .*pip install -e \"\.\[orca\]\" in crowdnav's clone$"):
        OrcaRobot()
    for argv in (["evaluate", "baseline:orca", "--scenario", "empty_room", "--out", str(tmp_path)],
                 ["render", "empty_room", "--policy", "orca", "--out", str(tmp_path), "--no-progress"],
                 ["render", "empty_room", "--policy", "baseline:orca", "--out", str(tmp_path), "--no-progress"]):
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and 'pip install -e ".[orca]" in crowdnav\'s clone' in err, (argv, err)


def test_importing_crowdnav_loads_no_pyrvo_and_works_without_it():
    code = ("import sys\n"
            "import crowdnav, crowdnav.envs, crowdnav.planning.scripted, crowdnav.cli\n"
            "assert 'pyrvo' not in sys.modules\n"
            "sys.modules['pyrvo'] = None\n"
            "env = crowdnav.envs.CrowdNavEnv(scenario='open_space')\n"
            "env.reset(seed=0); env.step(env.action_space.sample())\n")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT, timeout=120)


# ------------------------------------------------------------------------------------ with pyrvo


def test_orca_humans_choose_velocities_that_never_overlap_in_a_head_on_crossing():
    pytest.importorskip("pyrvo")
    worst = {}
    for model in ("orca", "social_force"):
        sim = Simulator("perpendicular_crossing", {"humans.model": model})
        assert list(sim.crowd.models) == [model]
        worst[model] = 0.0
        for seed in range(5):
            sim.reset(seed=seed)
            for _ in range(150):
                # where the model's commands lead, before the simulator pushes overlapping humans apart
                reached = sim.human_positions + sim.crowd_commands() * sim.dt
                gap = np.abs(reached[:, None] - reached[None]) + np.eye(sim.n_humans) * 1e9 - 2 * sim.scenario.humans.radius
                worst[model] = min(worst[model], gap.min())
                sim.step(np.zeros(2))
    assert worst["orca"] > -0.005  # under 5 mm: RVO2 works in float32
    assert worst["social_force"] < -0.02  # the same crowd by social force does overlap: the check can fail


def test_orca_humans_walk_to_their_goals_around_furniture():
    pytest.importorskip("pyrvo")
    sim = Simulator("room_furniture", ORCA)
    sim.reset(seed=2)
    arrivals, speeds = 0, []
    for _ in range(150):
        sim.step(np.zeros(2))
        arrivals += int(sim.human_arrived.sum())
        speeds.append(np.abs(sim.human_velocities).mean())
    assert arrivals >= sim.n_humans and np.mean(speeds) > 0.3
    assert (np.abs(sim.human_velocities) <= sim.human_max_speed + 1e-6).all()


def test_the_same_seed_gives_the_same_orca_episode_and_another_seed_does_not():
    pytest.importorskip("pyrvo")
    overrides = {**ORCA, "humans.see_robot": True, "humans.count": [3, 8]}
    first = _episode(Simulator("open_space", overrides), 11)
    sim = Simulator("open_space", overrides)
    _episode(sim, 12)  # another episode first: solvers are reused across episodes
    assert _episode(sim, 11) == first
    assert _episode(Simulator("open_space", overrides), 13) != first


def test_a_group_with_model_orca_mixes_with_social_force_and_standing_groups():
    pytest.importorskip("pyrvo")
    sim = Simulator("station_hall", {"humans.groups.0.model": "orca"})
    sim.reset(seed=5)
    commuters = sim.human_group == 0
    standing = np.array([group.standing for group in sim.groups])[sim.human_group]
    mask = sim.crowd.moved_by("orca", sim.human_group)
    assert (mask == commuters | standing).all() and list(sim.crowd.models) == ["social_force", "orca"]
    sim.step(np.zeros(2))
    social = sim.social_force_commands()
    orca = sim.crowd.models["orca"].commands(WorldView(sim))
    commands = sim.crowd_commands()
    assert np.array_equal(commands[~mask], social[~mask]) and np.array_equal(commands[commuters], orca[commuters])
    still = sim.human_positions[standing].copy()
    for _ in range(30):
        sim.step(np.zeros(2))
    assert np.array_equal(sim.human_positions[standing], still)


@pytest.mark.parametrize(("scenario", "overrides"), [
    ("station_hall", {"humans.groups.1.model": "orca", "humans.see_robot": True}),  # mixed models, standing groups
    ("open_space", {**ORCA, "humans.count": [0, 6]}),  # crowd sizes differ across worlds, including none
])
def test_batched_orca_worlds_equal_single_simulators_bit_for_bit(scenario, overrides):
    pytest.importorskip("pyrvo")
    check_batch_equals_singles(load_world(scenario, overrides), worlds=4, first_seed=30, steps=100, rng_seed=2, scale=1.0)


def test_the_native_vector_env_with_orca_humans_equals_the_sync_one():
    pytest.importorskip("pyrvo")
    import gymnasium as gym

    import crowdnav  # noqa: F401  (registers the ids)

    together = [i for i, group in enumerate(load_world("station_hall").scenario.humans.groups) if group.walk_together]
    apart = {f"humans.groups.{i}.walk_together": False for i in together}  # walking together is social force's (refused with ORCA)
    options = {"num_envs": 3, "modalities": ["goal", "lidar"], "overrides": {**ORCA, **apart, "humans.see_robot": True}}
    native = gym.make_vec("crowdnav/StationHall-v0", vectorization_mode="vector_entry_point", **options)
    sync = gym.make_vec("crowdnav/StationHall-v0", vectorization_mode="sync", **options)
    first, second = native.reset(seed=3), sync.reset(seed=3)
    assert all(np.array_equal(first[0][key], second[0][key]) for key in first[0])
    rng, ends = np.random.default_rng(3), 0
    for _ in range(150):
        actions = rng.uniform(-1, 1, (3, 2)).astype(np.float32)
        mine, theirs = native.step(actions), sync.step(actions)
        assert all(mine[0][key].tobytes() == theirs[0][key].tobytes() for key in mine[0])
        assert mine[1].tobytes() == theirs[1].tobytes() and (mine[2] == theirs[2]).all() and (mine[3] == theirs[3]).all()
        ends += int((mine[2] | mine[3]).sum())
    assert ends > 0  # resets happened inside the comparison


def _outcomes(policy, scenario: str, overrides: dict, seeds: range) -> list[str]:
    from crowdnav.envs import CrowdNavEnv

    env = CrowdNavEnv(scenario=scenario, modalities=["goal"], overrides=overrides)
    outcomes = []
    for seed in seeds:
        env.reset(seed=seed)
        while True:
            _, _, terminated, truncated, info = env.step(policy(env.simulator))
            if terminated or truncated:
                outcomes.append(info["outcome"])
                break
    return outcomes


def test_the_orca_robot_reaches_its_goal_in_easy_scenarios():
    pytest.importorskip("pyrvo")
    from crowdnav.planning.scripted import OrcaRobot

    policy = OrcaRobot()  # one policy for several worlds: its solvers are kept per world
    assert _outcomes(policy, "empty_room", {}, range(5)) == ["success"] * 5
    assert _outcomes(policy, "open_space", {"humans.see_robot": True}, range(8)) == ["success"] * 8
    assert _outcomes(policy, "open_space", {**ORCA, "humans.see_robot": True}, range(8)) == ["success"] * 8


def test_baseline_orca_is_evaluated_by_the_cli_and_named_in_the_leaderboard(tmp_path, capsys):
    pytest.importorskip("pyrvo")
    pytest.importorskip("pandas")
    from crowdnav.evaluation.baselines import BASELINES

    assert main(["evaluate", "baseline:orca", "--scenario", "empty_room", "--out", str(tmp_path), "--episodes", "3"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("baseline:orca: ") and "success 100%" in out
    assert main(["leaderboard", str(tmp_path)]) == 0
    assert f"| {BASELINES['orca']} | 1 | 1.000" in (tmp_path / "leaderboard.md").read_text()
