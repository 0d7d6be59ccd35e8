"""The predictive planner's last-layers memo: plan modality + shield compute one state's lattice once, and a hit is
the same computation a fresh planner makes (so episodes do not change)."""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav.envs.vector.env import CrowdNavVectorEnv
from crowdnav.planning import predictive
from crowdnav.planning.predictive import CrowdEstimate, PlannerSettings, PredictivePlanner
from crowdnav.worlds.compiled import load_world

MAIN_JOB = {"modalities": ["closest_obstacle", "goal", "plan"], "shield": True,
            "overrides": {"humans.count": 5, "humans.preferred_speed": [0.5, 1.2]}}


def crowd(shift: float = 0.0) -> CrowdEstimate:
    return CrowdEstimate(np.array([0.5 + shift + 0.2j]), np.array([3.0 + 1.0j]), np.array([[1.5 + 0.1j, -1.0 + 2.0j]]),
                         np.array([[-0.5 + 0.0j, 0.3 - 0.2j]]), np.array([[0.3, 0.25]]), np.array([[True, True]]))


def test_plan_and_shield_compute_each_steps_layers_once(monkeypatch):
    calls = []
    original = PredictivePlanner._layers
    monkeypatch.setattr(PredictivePlanner, "_layers", lambda self, *args: calls.append(1) or original(self, *args))
    env = CrowdNavVectorEnv("room_furniture", num_envs=4, **MAIN_JOB)
    env.reset(seed=0)
    calls.clear()
    rng = np.random.default_rng(0)
    for _ in range(10):
        env.step(rng.uniform(-1, 1, size=(4, 2)).astype(np.float32))
    assert len(calls) == 10  # the shield's check reuses what the plan observation computed a step before


def test_a_hit_equals_a_fresh_computation_and_cannot_be_written():
    world = load_world("room_furniture")
    first = PredictivePlanner().layers(world, 0.2, crowd())
    again = PredictivePlanner(PlannerSettings()).layers(world, 0.2, crowd())  # another planner, same settings: a hit
    assert again is first
    fresh = PredictivePlanner()._layers(world, 0.2, crowd())
    for name in ("cells", "static_free", "free", "goal", "predicted", "reach"):
        np.testing.assert_array_equal(getattr(first, name), getattr(fresh, name))
    with pytest.raises(ValueError, match="read-only"):
        first.free[0, 0, 0, 0] = True


def test_another_state_world_or_setting_is_computed_anew():
    world, other = load_world("room_furniture"), load_world("open_space")
    planner = PredictivePlanner()
    first = planner.layers(world, 0.2, crowd())
    assert planner.layers(world, 0.2, crowd(shift=1e-12)) is not first  # one bit of the estimate differs
    assert planner.layers(other, 0.2, crowd()) is not first
    assert PredictivePlanner(human_margin=0.2).layers(world, 0.2, crowd()) is not first
    assert planner.layers(world, 0.25, crowd()) is not first
    assert predictive._LAST_LAYERS[0][0] is world
