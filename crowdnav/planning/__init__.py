"""Planners that drive the robot on a space-time lattice: the privileged ceiling and the predictive baseline.

- :class:`OraclePlanner` (``baseline:oracle``): knows the humans' future; the ceiling of a scenario.
- :class:`PredictivePlanner` (``baseline:predictive``): the true current state, the map and a
  constant-velocity prediction, replanned every step over a short horizon.
- :class:`crowdnav.planning.onboard.OnboardPlanner` (``baseline:onboard``): the same planner fed by the
  robot's own sensing (its tracker, its pose, the map): the ``plan`` modality's move, executed.
"""

from crowdnav.planning.oracle import OraclePlanner, PlannerUnavailable

__all__ = ["OraclePlanner", "PlannerUnavailable"]
