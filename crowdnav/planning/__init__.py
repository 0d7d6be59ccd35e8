"""What drives the robot without learning: planners on a space-time lattice and the scripted robot policies.

- :class:`OraclePlanner` (``baseline:oracle``): knows the humans' future; the ceiling of a scenario.
- :class:`PredictivePlanner` (``baseline:predictive``): the true current state, the map and a
  constant-velocity prediction, replanned every step over a short horizon.
- :class:`crowdnav.planning.onboard.OnboardPlanner` (``baseline:onboard``): the same planner fed by the
  robot's own sensing (its tracker, its pose, the map): the ``plan`` modality's move, executed.
- :mod:`crowdnav.planning.scripted`: the scripted robot policies (straight to the goal, random, social force, ORCA)
  and :data:`~crowdnav.planning.scripted.SCRIPTED_POLICIES`, the names scripted robots go by (``crowdnav render
  --policy``, ``other_robots``, evaluation's baselines), the planners above included; their batched twins, for the
  stacked engines, are :mod:`crowdnav.batch.robot_policies`. It was ``crowdnav.policies``, a path that still imports
  (:mod:`crowdnav.legacy_paths`).
"""

from crowdnav.planning.oracle import OraclePlanner, PlannerUnavailable

__all__ = ["OraclePlanner", "PlannerUnavailable"]
