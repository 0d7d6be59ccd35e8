"""The robot's reward: named, weighted terms computed from the simulator after each step.

With weights ``w`` (a named preset, ``default`` or ``paper``, with single terms overridden: the
scenario's ``reward`` section, the env option ``reward_weights``, see
:mod:`crowdnav.scenario.reward_presets`) and ``d_t`` the robot-goal centre distance in metres
after step ``t`` (in parentheses: the ``paper`` preset's weight):

* ``step``          = ``w_step`` every step (paper: -5, a penalty);
* ``goal_progress`` = ``w_goal_progress * (d_{t-1} - d_t)``, potential-based shaping (paper: 10);
* ``social``        = ``w_social * |F_social|`` (paper: -100);
* ``goal_reached``  = ``w_goal_reached`` on the step whose outcome is ``success``, else 0 (paper: 500);
* ``collision``     = ``w_collision`` on the step whose outcome is ``collision``, else 0 (paper: -500).
* leaving the world (outcome ``out_of_bounds``, open space only) is a failure that costs as much as a collision: it pays ``collision`` too.

Every weight multiplies its quantity and the product is added: penalties have negative weights.
``F_social`` is :attr:`crowdnav.Simulator.robot_social_force`: the summed social-force
repulsion of all humans on the robot at the new state (dimensionless, see
:mod:`crowdnav.sim.forces`). A collision wins over a goal reached in the same step (the
simulator's outcome is then ``collision``), so at most one of the two event terms is paid.
The reward is the sum of the terms, in the order above.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TypeVar

import numpy as np

from crowdnav.scenario.reward_presets import REWARD_TERMS
from crowdnav.scenario.schema import RewardWeights
from crowdnav.sim.events import StepEvents
from crowdnav.sim.robot_view import RobotWorld

__all__ = ["REWARD_TERMS", "Reward", "reward_terms"]  # REWARD_TERMS: names in summation order, keys of info["reward_terms"]

F = TypeVar("F", float, np.ndarray)
"""A Python float (one world) or a (K,) array (K worlds)."""

PAID_ON = {"goal_reached": ("success",), "collision": ("collision", "out_of_bounds")}
"""The event terms and the outcomes (:data:`crowdnav.sim.events.OUTCOMES`) whose step pays them."""


def reward_terms(
    weights: Mapping[str, float], previous_distance: F, distance: F, social_force: F, outcome: str | None | np.ndarray
) -> tuple[F, dict[str, F]]:
    """The kernel: (reward, terms) of one step, for one world (Python floats) or K worlds ((K,) arrays).

    ``weights``: term -> weight; ``previous_distance`` / ``distance``: the robot-goal centre
    distance before and after the step; ``social_force``: ``|F_social|`` after it; ``outcome``:
    the step's outcome (:func:`crowdnav.sim.events.outcome_of`, None while running; K worlds: the
    (K,) object array of :func:`crowdnav.sim.events.outcomes`). Only elementwise float operations, in
    the order of the module doc, so a world's terms have the same bits either way.
    """
    progress = weights["goal_progress"] * (previous_distance - distance)
    social = weights["social"] * social_force
    # the isinstance test in place (not in a flag), so that mypy knows F in each branch
    if isinstance(distance, np.ndarray):
        terms = {"step": np.full(np.shape(distance), weights["step"]), "goal_progress": progress, "social": social}
        for term, paid_on in PAID_ON.items():
            terms[term] = np.where(np.logical_or.reduce([outcome == name for name in paid_on]), weights[term], 0.0)
    else:
        terms = {"step": weights["step"], "goal_progress": progress, "social": social}
        for term, paid_on in PAID_ON.items():
            terms[term] = weights[term] if outcome in paid_on else 0.0
    reward = terms["step"] + terms["goal_progress"] + terms["social"] + terms["goal_reached"] + terms["collision"]
    return reward, terms


class Reward:
    """Computes the reward terms of one episode; call :meth:`reset` after each simulator reset."""

    def __init__(self, weights: RewardWeights):
        self.weights = weights
        self._weights = {term: float(getattr(weights, term)) for term in REWARD_TERMS}
        self._previous_distance = 0.0

    def reset(self, sim: RobotWorld) -> None:
        """Remember the initial robot-goal distance (the potential of the progress term)."""
        self._previous_distance = float(sim.robot_goal_distance)

    @property
    def previous_distance(self) -> float:
        """The robot-goal distance at the last step (or reset): the progress term's memory (a world state keeps it)."""
        return self._previous_distance

    @previous_distance.setter
    def previous_distance(self, distance: float) -> None:
        self._previous_distance = float(distance)

    def __call__(self, sim: RobotWorld, events: StepEvents) -> tuple[float, dict[str, float]]:
        """(reward, terms) for the step the simulator just took; ``terms`` is a new dict."""
        distance = float(sim.robot_goal_distance)
        previous, self._previous_distance = self._previous_distance, distance
        return reward_terms(self._weights, previous, distance, abs(complex(sim.robot_social_force)), events.outcome)
