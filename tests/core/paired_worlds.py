"""Worlds of robots_crossing_hall stepped twice, stacked and one simulator each: the twins the robots' batched code is
compared with (tests/core/test_stacked_robots.py, tests/core/test_every_robot_policies.py)."""

from __future__ import annotations

from crowdnav.batch.simulator import BatchSimulator
from crowdnav.sim.simulator import Simulator
from crowdnav.worlds.compiled import load_world

SCENARIO = "robots_crossing_hall"
WORLDS = 6


def paired_worlds(overrides: dict[str, object] | None, first_seed: int) -> tuple[BatchSimulator, list[Simulator]]:
    """:data:`WORLDS` worlds of :data:`SCENARIO` with ``overrides``, reset with seeds ``first_seed``, +1, ... in a batch and singly."""
    world = load_world(SCENARIO, overrides)
    batch, singles = BatchSimulator(world, WORLDS), [Simulator(world) for _ in range(WORLDS)]
    batch.reset(range(WORLDS), [first_seed + i for i in range(WORLDS)])
    for i, sim in enumerate(singles):
        sim.reset(seed=first_seed + i)
    return batch, singles
