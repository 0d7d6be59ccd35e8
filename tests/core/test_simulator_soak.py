"""Long runs of the crowd: humans stay out of walls and furniture, values stay finite, memory flat."""

from __future__ import annotations

import resource

import numpy as np
import pytest

from crowdnav import Simulator
from crowdnav.scenario.library import library_names
from crowdnav.scenario.schema import Scenario

PENETRATION_LIMIT = 0.01  # metres


def _soak(sim: Simulator, steps: int) -> float:
    """Worst penetration of a human into a static obstacle over ``steps`` steps (robot still)."""
    worst = 0.0
    sim.reset(seed=0)
    for step in range(steps):
        events = sim.step(np.zeros(2))
        assert np.isfinite(sim.positions).all() and np.isfinite(sim.velocities).all()
        if sim.geometry.static_count and sim.n_humans:
            worst = max(worst, -float(sim.geometry.gap[1:, sim.n_humans + 1 :].min()))
        if events.collision or events.truncated or events.left_world or events.goal_reached:
            sim.reset(seed=step + 1)
    return worst


def test_sixty_humans_in_the_furnished_room_never_sink_a_centimetre_into_furniture():
    assert _soak(Simulator("room_furniture", overrides={"humans.count": 60}), 3000) < PENETRATION_LIMIT


def _max_crowd(name: str) -> dict:
    """Overrides that fix the crowd at its largest size (each group's, for a file with groups)."""
    humans = Scenario.model_validate(Simulator(name).scenario.model_dump()).humans
    if humans.groups:
        return {f"humans.groups.{i}.count": group.max_count for i, group in enumerate(humans.groups)}
    return {"humans.count": humans.max_count}


@pytest.mark.slow
@pytest.mark.parametrize("name", library_names())
def test_library_scenario_at_its_maximum_crowd_soaks_100000_steps_finite_flat_and_out_of_obstacles(name):
    sim = Simulator(name, overrides=_max_crowd(name))
    _soak(sim, 10_000)  # warm-up: caches and arrays reach their working size
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    worst = _soak(sim, 100_000)
    grown_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before
    assert worst < PENETRATION_LIMIT, f"{name}: a human sank {worst:.4f} m into an obstacle"
    assert grown_kib < 20_000, f"{name}: peak memory grew by {grown_kib} KiB over 100,000 steps"


@pytest.mark.slow
@pytest.mark.parametrize("name", ["room_furniture", "cafe", "doorway"])
def test_sixty_humans_soak_100000_steps_without_sinking_into_obstacles(name):
    assert _soak(Simulator(name, overrides={"humans.count": 60}), 100_000) < PENETRATION_LIMIT
