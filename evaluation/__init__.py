"""crowdnav's evaluation: the paper's protocol as reproducible runs, per-episode metrics,
learning curves and a leaderboard.

* :class:`Protocol` (crowdnav.evaluation.protocol): when and on which held-out episodes a policy is tested;
* experiments (crowdnav.evaluation.experiment): YAML lists of configurations x seeds, shipped in
  ``evaluation/experiments/`` (:func:`load_experiment`);
* :func:`run_unit` (crowdnav.evaluation.runner): one (configuration, seed) run, idempotent and resumable;
  :func:`run_experiment` (crowdnav.evaluation.benchmark): all of them through an executor, then the report;
* :func:`make_executor` (crowdnav.evaluation.executors): ``serial``, ``local`` (process pool) or ``ray``
  (crowdnav.evaluation.ray_executor, needs the ray extra);
* :mod:`crowdnav.evaluation.metrics`: per-episode metrics from a trajectory (pure functions);
* :func:`plot_curves`, :func:`write_leaderboard`, :func:`load_results`: any results folder.

Names are imported on first use, so ``import evaluation`` stays cheap (no torch, pandas or
matplotlib until needed).
"""

from __future__ import annotations

from crowdnav.lazy_exports import lazy_exports

_EXPORTS = {
    "Protocol": "crowdnav.evaluation.protocol",
    "QUICK": "crowdnav.evaluation.protocol",
    "Experiment": "crowdnav.evaluation.experiment",
    "Configuration": "crowdnav.evaluation.experiment",
    "ExperimentError": "crowdnav.evaluation.experiment",
    "load_experiment": "crowdnav.evaluation.experiment",
    "shipped_experiments": "crowdnav.evaluation.experiment",
    "UnitSpec": "crowdnav.evaluation.unit_spec",
    "run_unit": "crowdnav.evaluation.runner",
    "make_executor": "crowdnav.evaluation.executors",
    "run_experiment": "crowdnav.evaluation.benchmark",
    "BenchmarkReport": "crowdnav.evaluation.benchmark",
    "write_report": "crowdnav.evaluation.benchmark",
    "Trajectory": "crowdnav.evaluation.metrics",
    "episode_metrics": "crowdnav.evaluation.metrics",
    "HeldOutEpisodes": "crowdnav.evaluation.rollout",
    "RobotEpisodes": "crowdnav.evaluation.robot_rollout",
    "robot_rates": "crowdnav.evaluation.robot_rollout",
    "ResultsError": "crowdnav.evaluation.storage",
    "load_results": "crowdnav.evaluation.storage",
    "rate_curves": "crowdnav.evaluation.curves",
    "curves_figure": "crowdnav.evaluation.curves",
    "plot_curves": "crowdnav.evaluation.curves",
    "leaderboard_table": "crowdnav.evaluation.leaderboard",
    "write_leaderboard": "crowdnav.evaluation.leaderboard",
}

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
