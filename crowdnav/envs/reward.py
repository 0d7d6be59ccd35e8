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
:mod:`crowdnav.social_force`). A collision wins over a goal reached in the same step (the
simulator's outcome is then ``collision``), so at most one of the two event terms is paid.
The reward is the sum of the terms, in the order above.
"""

from __future__ import annotations

from crowdnav.scenario.reward_presets import REWARD_TERMS
from crowdnav.scenario.schema import RewardWeights
from crowdnav.simulator import Simulator, StepEvents

__all__ = ["REWARD_TERMS", "Reward"]  # REWARD_TERMS: names in summation order, keys of info["reward_terms"]


class Reward:
    """Computes the reward terms of one episode; call :meth:`reset` after each simulator reset."""

    def __init__(self, weights: RewardWeights):
        self.weights = weights
        self._step = float(weights.step)
        self._progress = float(weights.goal_progress)
        self._social = float(weights.social)
        self._goal = float(weights.goal_reached)
        self._collision = float(weights.collision)
        self._previous_distance = 0.0

    def reset(self, sim: Simulator) -> None:
        """Remember the initial robot-goal distance (the potential of the progress term)."""
        self._previous_distance = float(sim.robot_goal_distance)

    def __call__(self, sim: Simulator, events: StepEvents) -> tuple[float, dict[str, float]]:
        """(reward, terms) for the step the simulator just took; ``terms`` is a new dict."""
        distance = float(sim.robot_goal_distance)
        progress = self._previous_distance - distance
        self._previous_distance = distance
        outcome = events.outcome
        terms = {
            "step": self._step,
            "goal_progress": self._progress * progress,
            "social": self._social * abs(complex(sim.robot_social_force)),
            "goal_reached": self._goal if outcome == "success" else 0.0,
            "collision": self._collision if outcome == "collision" or outcome == "out_of_bounds" else 0.0,
        }
        reward = terms["step"] + terms["goal_progress"] + terms["social"] + terms["goal_reached"] + terms["collision"]
        return reward, terms
