"""Every scripted baseline crowdnav ships plays a whole episode in every library scenario, or refuses it in one line.

The lattice planners (oracle, predictive, onboard) drive one holonomic robot; the oracle also needs a crowd that
does not react to the robot. Elsewhere they raise :class:`crowdnav.planning.PlannerUnavailable`. The shielded baselines
play with the shield on, which shields one holonomic robot (a one-line ValueError elsewhere).
"""

from __future__ import annotations

import importlib.util

import pytest
from crowdnav.evaluation.baselines import BASELINES, SHIELDED_BASELINES, scripted_policy, shielded
from crowdnav.evaluation.rollout import HeldOutEpisodes

from crowdnav.planning import PlannerUnavailable
from crowdnav.scenario.library import library_names
from crowdnav.worlds.compiled import load_world

OUTCOMES = {"success", "collision", "out_of_bounds", "truncated"}
HAS_PYRVO = importlib.util.find_spec("pyrvo") is not None


@pytest.mark.parametrize("baseline", [
    name if name != "orca" or HAS_PYRVO else pytest.param(name, marks=pytest.mark.skip(reason="needs crowdnav[orca]"))
    for name in BASELINES])
@pytest.mark.parametrize("scenario", library_names())
def test_the_baseline_plays_two_whole_episodes_of_the_library_scenario_with_defined_metrics(baseline, scenario):
    episodes = HeldOutEpisodes(shielded(baseline, {"scenario": scenario, "modalities": ["goal"]}), range(2))
    spec = load_world(scenario).scenario
    if baseline in SHIELDED_BASELINES and (spec.robot.kinematics != "holonomic" or spec.robots is not None):
        with pytest.raises(ValueError) as refusal:
            episodes.run(scripted_policy(baseline), privileged=True)
        assert "\n" not in str(refusal.value) and "shield" in str(refusal.value)
        return
    refuses = baseline in ("oracle", "predictive", "onboard") and (  # the planners drive the first robot (others: their own policy)
        spec.robot.kinematics != "holonomic" or (baseline == "oracle" and (spec.robots is not None or spec.humans.see_robot)))
    if refuses:
        with pytest.raises(PlannerUnavailable) as refusal:
            episodes.run(scripted_policy(baseline), privileged=True)
        assert "\n" not in str(refusal.value)
        return
    rows = episodes.run(scripted_policy(baseline), privileged=True)
    assert [row["outcome"] in OUTCOMES for row in rows] == [True, True]
    for row in rows:  # NaN only where documented: no time to goal without reaching it, no jerk in a 1-2 step episode
        allowed = {"time_to_goal"} if row["outcome"] != "success" else set()
        allowed |= {"mean_jerk", "max_jerk", "mean_acceleration", "max_acceleration"} if row["steps"] < 3 else set()
        assert [key for key, value in row.items() if isinstance(value, float) and value != value and key not in allowed] == []
