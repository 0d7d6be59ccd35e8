"""The crowd presets (humans.preset): the paper's humans by default, ``calibrated`` people as measured."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.open_square_speed import WINDOW, crowd_speeds, open_square
from crowdnav import Simulator
from crowdnav.scenario.crowd_presets import CROWD_PRESETS, SPEED_MEAN, SPEED_SD
from crowdnav.scenario.errors import ScenarioError
from crowdnav.scenario.loader import human_substeps, load_scenario

CALIBRATED = CROWD_PRESETS["calibrated"]


def test_calibrated_preset_fills_the_speeds_and_forces_a_file_leaves_out_and_given_fields_win():
    humans = load_scenario(open_square("calibrated"), {"humans.social_force.goal_weight": 2.0,
                                                       "humans.social_force.human_range": 0.5}).humans
    assert humans.preferred_speed == CALIBRATED.preferred_speed == (0.82, 1.86)
    for name, value in CALIBRATED.social_force.items():
        assert getattr(humans.social_force, name) == (0.5 if name == "human_range" else value)
    assert humans.social_force.goal_weight == 2.0
    assert humans.speed_normals == [(SPEED_MEAN, SPEED_SD)]
    # the file's own range wins: drawn uniformly in it, as before
    assert load_scenario("open_space", {"humans.preset": "calibrated"}).humans.speed_normals == [None]


def test_the_default_preset_is_the_schemas_humans_and_dumps_without_the_preset_key():
    scenario = load_scenario("open_space")
    assert scenario.humans.preset == "paper" and scenario.humans.speed_normals == [None]
    assert scenario.humans.social_force == type(scenario.humans.social_force)()
    assert "preset" not in scenario.model_dump()["humans"]


def test_calibrated_preferred_speeds_are_normal_clipped_to_two_standard_deviations():
    sim = Simulator(open_square("calibrated"), {"humans.count": 10})
    speeds = []
    for seed in range(60):
        sim.reset(seed=seed)
        speeds.append(sim.human_preferred_speed.copy())
    drawn = np.concatenate(speeds)
    low, high = CALIBRATED.preferred_speed
    assert drawn.min() >= low and drawn.max() <= high
    assert abs(drawn.mean() - SPEED_MEAN) < 0.03  # 600 draws: the mean's standard error is 0.01
    assert 0.21 < drawn.std() < 0.27  # clipping at 2 sd takes about 0.02 off 0.26
    assert np.isclose(sim.human_max_speed, 1.3 * sim.human_preferred_speed).all()


def test_a_dumped_calibrated_scenario_loads_back_to_the_same_episode():
    scenario = load_scenario(open_square("calibrated"), {"humans.count": 6})
    again = load_scenario(scenario.model_dump(mode="json"))
    assert again == scenario and again.humans.speed_normals == scenario.humans.speed_normals
    first, second = Simulator(scenario), Simulator(again)
    first.reset(seed=4)
    second.reset(seed=4)
    for _ in range(20):
        first.step(np.zeros(2))
        second.step(np.zeros(2))
    assert first.positions.tobytes() == second.positions.tobytes()


def test_only_groups_without_their_own_range_draw_the_presets_normal():
    document = open_square("calibrated")
    crowd = {key: document["humans"].pop(key) for key in ("count", "spawn", "goal", "on_goal")}
    document["humans"]["groups"] = [{"name": "people", **crowd}, {"name": "slow", **crowd, "preferred_speed": [0.4, 0.6]}]
    humans = load_scenario(document).humans
    assert humans.speed_normals == [(SPEED_MEAN, SPEED_SD), None]


def test_an_unknown_crowd_preset_is_refused_in_one_line_with_a_suggestion():
    with pytest.raises(ScenarioError) as error:
        load_scenario("open_space", {"humans.preset": "calibratd"})
    message = str(error.value)
    assert "humans.preset" in message and "did you mean 'calibrated'" in message and len(message.splitlines()) <= 2


def test_the_calibrated_crowd_walks_at_its_speeds_with_two_substeps():
    scenario = load_scenario(open_square("calibrated"))
    assert human_substeps(scenario) == 2  # 1.86 m/s x 1.3 x 0.2 s = 0.48 m per step, more than the 0.3 m radius
    speeds, sim = crowd_speeds({}, seed=0, steps=300, preset="calibrated")
    assert speeds[100:].mean() > 0.9  # well above the paper's humans (0.5 m/s preferred in open_space)


def test_the_calibrated_crowd_keeps_walking_in_the_open_square_over_steps_2500_to_4000():
    # issue 52: the paper's humans (preferred 0.8-1.2 m/s) average 0.70 m/s there (benchmarks/open_square_speed.py)
    means = [crowd_speeds({}, seed, WINDOW[1], preset="calibrated")[0][WINDOW[0] : WINDOW[1]].mean() for seed in range(4)]
    assert min(means) >= 0.8, means
