"""What a simulator step reports: its events, the episode outcomes, and the simulation's own error."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Collision:
    """A robot collision: what it hit and how deep."""

    kind: str
    """``human`` or ``static``."""
    partner: str
    """``human_<i>`` or the obstacle's scenario path (e.g. ``furniture.2 (table)``)."""
    surface_distance: float
    """Distance between surfaces in metres (<= 0: touching or overlapping)."""


OUTCOMES = ("success", "collision", "out_of_bounds", "truncated")
"""Every way an episode ends (:attr:`StepEvents.outcome` of its last step, ``info["outcome"]``
of the envs): the one success, the two failures, the time limit. Evaluation, training logs and
benchmarks count the outcomes in this order."""


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

        Precedence when several events happen in the same step: ``collision`` > ``out_of_bounds``
        > ``success`` > ``truncated`` (a failure wins over a goal reached in the same step, and
        any event over the time limit).
        """
        if self.collision is not None:
            return "collision"
        if self.left_world:
            return "out_of_bounds"
        if self.goal_reached:
            return "success"
        return "truncated" if self.truncated else None


class SimulationError(RuntimeError):
    """The simulated state became non-finite; the message names the agent and the step."""
