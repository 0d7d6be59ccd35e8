"""The single env's numpy floor (benchmarks/bench_env_floor.py, ``bench_env.py --floor``) does the env's own work:
replayed on the env's simulator, sensors and reward without the env layer, it returns what the env returns, bit for bit.
(A floor that did less would make the env look slower than it is; one that did more, faster.)"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_env_floor import ALL_MODALITIES, ALL_SENSORS, check_floor, floor_steps
from crowdnav.envs import CrowdNavEnv


@pytest.mark.parametrize(("scenario", "options"), [
    ("room_furniture", {}),
    ("open_space", {"modalities": ALL_MODALITIES, "sensors": ALL_SENSORS}),
], ids=["room_default", "open_all"])
def test_the_floor_returns_what_the_env_returns_bit_for_bit_through_resets(scenario, options):
    env = CrowdNavEnv(scenario, **options)
    actions = np.random.default_rng(0).uniform(-1, 1, (300, 2)).astype(np.float32)
    check_floor(env, actions, seed=0)  # raises on the first step that differs
    ends = sum(terminated or truncated for _, _, terminated, truncated, _ in floor_steps(env, actions, 0))
    assert ends > 0  # the episodes' resets (and their observations) are part of what was compared


def test_the_floor_refuses_several_robots():
    with pytest.raises(ValueError, match="one robot"):
        next(floor_steps(CrowdNavEnv("robots_crossing_hall"), np.zeros((1, 2)), 0))
