"""The ORCA solver sets only the velocities RVO2 does not already hold (issue 38 item 3), with the same answers bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav.scenario.schema import Orca
from crowdnav.sim.orca_solver import OrcaSolver, obstacle_rings, toward_goal
from crowdnav.worlds.compiled import load_world

pytest.importorskip("pyrvo")

DT = 0.2


class CountingSim:
    """A pyrvo simulator that counts the velocities set on it."""

    def __init__(self, sim: object):
        self._sim = sim
        self.velocities_set = 0

    def __getattr__(self, name: str) -> object:
        return getattr(self._sim, name)

    def set_agent_velocity(self, agent: int, velocity: object) -> None:
        self.velocities_set += 1
        self._sim.set_agent_velocity(agent, velocity)


def _solver(count: int, rings: list) -> OrcaSolver:
    solver = OrcaSolver(rings, Orca(), DT, count, "test")
    solver.configure(np.full(count, 0.3), np.full(count, 1.2))
    return solver


@pytest.mark.parametrize("scenario", ["circle_crossing", "room_furniture"])
def test_velocities_equal_a_solver_given_every_velocity_at_every_step(scenario):
    rings = obstacle_rings(load_world(scenario).obstacles)
    rng = np.random.default_rng(7)
    count = 12
    positions = rng.uniform(-3, 3, count) + 1j * rng.uniform(-3, 3, count)
    goals = -positions
    lean, full = _solver(count, rings), _solver(count, rings)
    lean._sim = counting = CountingSim(lean._sim)  # type: ignore[assignment]
    velocities = np.zeros(count, dtype=complex)
    for step in range(60):
        preferred = toward_goal(goals - positions, 1.0, DT)
        full._held = None  # forgets what RVO2 holds: sets every velocity, as before the shortcut
        mine, theirs = lean.velocities(positions, velocities, preferred), full.velocities(positions, velocities, preferred)
        assert mine.tobytes() == theirs.tobytes(), f"step {step}"
        velocities = mine.copy()
        # what a simulator does to some agents between steps: stops one, nudges another's y, a third one's x
        velocities[step % count] = 0.0
        velocities[(step + 5) % count] += 0.05j
        velocities[(step + 3) % count] -= 0.05
        positions = positions + velocities * DT
    # three agents at most changed per step (after the first): far fewer calls than 12 a step
    assert counting.velocities_set <= count + 3 * 59 < count * 60


def test_a_solver_whose_step_failed_sets_every_velocity_again():
    solver = _solver(3, [])
    positions, velocities = np.array([0, 2, 4], dtype=complex), np.zeros(3, dtype=complex)
    answer = solver.velocities(positions, velocities, np.ones(3, dtype=complex))
    with pytest.raises(ValueError, match="could not convert"):
        solver.velocities(positions, answer, np.array(["a", "b", "c"], dtype=object))  # the preferred velocities cannot reach RVO2
    assert solver._held is None  # not trusted any more: the next call sets every velocity
