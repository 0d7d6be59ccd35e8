"""ORCA keeps the solvers of its last few agent counts only (issue 36): a crowd whose size changes at
every reset stays bounded, and an episode played on a solver built again equals the first one bit for bit."""

from __future__ import annotations

import gc

import pytest

from crowdnav.planning.scripted import WORLDS_KEPT, OrcaRobot
from crowdnav.sim.orca_solver import SOLVERS_KEPT, SolverCache
from crowdnav.sim.simulator import Simulator
from crowdnav.worlds.compiled import load_world
from tests.core.test_orca import _episode

pytest.importorskip("pyrvo")

VARYING = {"humans.model": "orca", "humans.count": [1, 40]}


def test_the_cache_keeps_the_most_recently_used_counts_and_frees_the_oldest():
    built: list[int] = []
    cache = SolverCache(size=2)
    for count in (3, 5, 3, 7, 5):
        cache.get(count, lambda n: built.append(n) or object())  # type: ignore[func-returns-value]
    assert built == [3, 5, 7, 5] and len(cache) == 2  # 3 was used again before 7 came, so 5 was freed; then 3


def test_an_orca_crowd_of_varying_size_keeps_a_bounded_number_of_solvers_over_many_resets():
    sim = Simulator("open_space", VARYING)
    sizes = set()
    for seed in range(120):
        sim.reset(seed=seed)
        sizes.add(sim.n_humans)
        assert len(sim.crowd.models["orca"]._solvers) <= SOLVERS_KEPT  # type: ignore[attr-defined]
    assert len(sizes) > 3 * SOLVERS_KEPT  # the counts did vary: a cache per count would have grown past the bound


def test_an_orca_episode_after_its_solver_was_freed_and_rebuilt_equals_the_first_bit_for_bit():
    fresh = [_episode(Simulator("open_space", VARYING), seed, 30) for seed in (3, 4)]
    sim = Simulator("open_space", VARYING)
    first = _episode(sim, 3, 30)
    for seed in range(100, 130):  # other crowd sizes push the first one's solver out
        sim.reset(seed=seed)
    gc.collect()
    assert first == fresh[0] and _episode(sim, 3, 30) == fresh[0] and _episode(sim, 4, 30) == fresh[1]


def test_the_orca_robot_keeps_a_bounded_number_of_solvers_and_worlds():
    policy = OrcaRobot()
    world = load_world("open_space", {"humans.count": [1, 40]})
    sim = Simulator(world)
    for seed in range(60):
        sim.reset(seed=seed)
        policy(sim)
        assert len(policy._worlds[id(world)][2]) <= SOLVERS_KEPT
    for _ in range(WORLDS_KEPT + 3):
        other = Simulator(load_world("open_space"))
        other.reset(seed=0)
        policy(other)
    assert len(policy._worlds) == WORLDS_KEPT


def test_the_orca_robot_drives_the_same_episode_after_its_solvers_were_freed():
    def drive(policy: OrcaRobot, sim: Simulator, seed: int) -> bytes:
        sim.reset(seed=seed)
        trace = []
        for _ in range(25):
            sim.step(policy(sim))
            trace.append(sim.positions.tobytes())
        return b"".join(trace)

    overrides = {"humans.count": [1, 40]}
    expected = drive(OrcaRobot(), Simulator("open_space", overrides), 7)
    policy, sim = OrcaRobot(), Simulator("open_space", overrides)
    for seed in range(50):
        sim.reset(seed=seed)
        policy(sim)
    assert drive(policy, sim, 7) == expected
