"""What a simulator step reports: its events, the episode outcomes, and the simulation's own error."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crowdnav.errors import CrowdNavError


@dataclass(frozen=True)
class Collision:
    """A robot collision: what it hit and how deep."""

    kind: str
    """``human``, ``static`` or (several robots) ``robot``."""
    partner: str
    """``human_<i>``, the obstacle's scenario path (e.g. ``furniture.2 (table)``) or the other robot's name."""
    surface_distance: float
    """Distance between surfaces in metres (<= 0: touching or overlapping)."""


OUTCOMES = ("success", "collision", "out_of_bounds", "truncated")
"""Every way an episode ends (:attr:`StepEvents.outcome` of its last step, ``info["outcome"]``
of the envs): the one success, the two failures, the time limit. Evaluation, training logs and
benchmarks count the outcomes in this order."""


OUTCOME_PRECEDENCE = ("collision", "out_of_bounds", "success", "truncated")
"""Which outcome a step has when several of its events happen at once: the first that happened.
A failure wins over a goal reached in the same step, and any event over the time limit."""


def outcome_of(collided: bool, left_world: bool, goal_reached: bool, truncated: bool) -> str | None:
    """The outcome of one step (:data:`OUTCOME_PRECEDENCE` applied to its events), or None while it runs.

    The one world case of :func:`outcomes`, in Python scalars: a step of the single env pays no
    numpy call for it. The events are given in the precedence's order.
    """
    # OUTCOME_PRECEDENCE written out (tests/core/test_reward_outcome_kernel.py checks it against outcomes()):
    # a loop over it cost the single env ~1 us a step
    if collided:
        return "collision"
    if left_world:
        return "out_of_bounds"
    if goal_reached:
        return "success"
    if truncated:
        return "truncated"
    return None


def outcomes(collided: np.ndarray, left_world: np.ndarray, goal_reached: np.ndarray, truncated: np.ndarray) -> np.ndarray:
    """(K,) object array: :func:`outcome_of` of every world (None where it runs), from (K,) bool arrays of its events."""
    names = np.array([*OUTCOME_PRECEDENCE, None], dtype=object)
    chosen: np.ndarray = names[np.select([collided, left_world, goal_reached, truncated], range(len(OUTCOME_PRECEDENCE)), len(OUTCOME_PRECEDENCE))]
    return chosen


@dataclass(frozen=True)
class StepEvents:
    """What happened to the robot during one step."""

    goal_reached: bool
    collision: Collision | None
    truncated: bool
    left_world: bool = False
    """The robot's centre is outside the world rectangle (only without boundary walls: with them it collides first)."""

    @property
    def terminated(self) -> bool:
        """The step ends the episode by an event (goal, collision or leaving the world), not by the time limit."""
        return self.goal_reached or self.collision is not None or self.left_world

    @property
    def outcome(self) -> str | None:
        """How the step ends the episode, one of :data:`OUTCOMES`, or None (running).

        Precedence when several events happen in the same step: :data:`OUTCOME_PRECEDENCE`
        (``collision`` > ``out_of_bounds`` > ``success`` > ``truncated``).
        """
        return outcome_of(self.collision is not None, self.left_world, self.goal_reached, self.truncated)


class SimulationError(CrowdNavError, RuntimeError):
    """The simulated state became non-finite; the message names the agent and the step."""


def check_finite(positions: np.ndarray, velocities: np.ndarray, step_count: int | np.ndarray, worlds: np.ndarray | None = None) -> None:
    """Raise :class:`SimulationError` naming the first agent whose position became non-finite, if any.

    One world: ``positions`` and ``velocities`` (n+1,), ``step_count`` its int. K worlds: (K, n+1)
    arrays, ``step_count`` (K,) and ``worlds`` (K,) their indices in the batch (named in the message).
    One cheap check per step, so a non-finite state stops the episode with its name instead of
    leaking NaN into rewards while the observations stay finite.
    """
    finite = np.isfinite(positions)
    if np.logical_and.reduce(finite, axis=None):  # ndarray.all() without its Python wrapper (a step's cost)
        return
    bad = tuple(np.argwhere(~finite)[0])  # (agent,) or (world, agent)
    who = "the robot" if bad[-1] == 0 else f"human {bad[-1] - 1}"
    at = f"step {step_count}" if worlds is None else f"world {worlds[bad[0]]}, step {step_count[bad[0]]}"  # type: ignore[index]
    raise SimulationError(f"{at}: the position of {who} became non-finite (its velocity: {velocities[bad]}); "
                          "check the scenario's social_force parameters")
