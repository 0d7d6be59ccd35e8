"""Planners that drive the robot on a space-time lattice: the privileged ceiling and the predictive baseline.

- :class:`OraclePlanner` (``baseline:oracle``): knows the humans' future; the ceiling of a scenario.
- :class:`PredictivePlanner` (``baseline:predictive``): the true current state, the map and a
  constant-velocity prediction, replanned every step over a short horizon.
"""

from crowdnav.planning.oracle import OraclePlanner, PlannerUnavailable

__all__ = ["OraclePlanner", "PlannerUnavailable"]
