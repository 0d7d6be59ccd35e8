"""Scripted baselines on an experiment's own test episodes: the bar a learned policy must clear.

Every experiment evaluates the scripted robots of :data:`EXPERIMENT_BASELINES`
(:mod:`crowdnav.planning.scripted`) on the same held-out test episodes as its learned runs, with the same
scenario, overrides and reward (a configuration with ``agents: robots``: the baseline drives every
robot of the scenario, :mod:`crowdnav.evaluation.robot_rollout`):

* ``straight``: drive at the goal at full speed, blind to everyone. A learned policy that does
  worse has not learned to navigate, only (at best) to head for the goal;
* ``social_force``: the humans' own reactive model applied to the robot (goal attraction plus
  repulsion from the true positions of the humans and obstacles): what a purely reactive,
  position-only policy with perfect perception reaches;
* ``onboard``: the predictive planner fed by the robot's own sensing (the humans its tracker
  reports, its pose, velocity and goal, the map), the ``plan`` modality's move executed
  (:class:`crowdnav.planning.onboard.OnboardPlanner`). Not privileged: the level a learned agent
  has to beat;
* ``predictive``: the same planner fed the true current state of every human (privileged);
* ``oracle``: knows the humans' future (the ceiling, docs/planning.md).

Beside a configuration that trains with the action-time shield (``shield`` in its ``train``), the experiment
also plays ``straight_shield`` and ``social_force_shield``: the same scripted robots with that same shield in
their loop (:data:`SHIELDED_BASELINES`), so a shielded agent is shown beside what the shield alone makes of
driving straight at the goal and of the social-force robot (the shield is reported apart, never the target).

Another, ``orca`` (ORCA with the true positions and velocities of everyone, the field's standard
scripted baseline), needs the optional package pyrvo: ``crowdnav evaluate baseline:orca`` plays
it on demand; experiments do not, so their results never depend on an extra.

Each baseline is stored like a run, ``<experiment>/baseline_<name>/<env>/`` with ``meta.json``
and ``test_episodes.csv`` (the same per-episode columns as a learned run), so the leaderboard
ranks it and the notebook reads it without special cases. A scripted policy is deterministic
and the test episodes are the same at every evaluation, so it is played once and its rows are
repeated at each evaluation point (``training_episodes``, or ``training_steps`` with ``training_episodes`` 0
for a protocol in env steps: the learned runs' point columns); the curves draw it as a horizontal
reference line.
"""

from __future__ import annotations

import difflib
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from crowdnav.evaluation.protocol import Protocol
from crowdnav.evaluation.robot_rollout import ROBOTS_AGENTS
from crowdnav.evaluation.storage import (
    META_FILE,
    TEST_FILE,
    atomic_write_csv,
    atomic_write_json,
    baseline_folder,
    read_json,
    run_damage,
)

BASELINE_PREFIX = "baseline_"
"""Configuration names of baselines start with this; experiment configurations may not."""

BASELINES: dict[str, str] = {
    "straight": "straight to goal (scripted)",
    "social_force": "social force, privileged (scripted)",
    "orca": "ORCA, privileged (scripted)",
    "onboard": "onboard planner: tracker + map (scripted)",
    "predictive": "predictive planner, privileged: state + map (scripted)",
    "oracle": "oracle, privileged: knows the future (ceiling)",
    "straight_shield": "straight to goal + shield (scripted)",
    "social_force_shield": "social force, privileged, + shield (scripted)",
}
"""Baseline name (``baseline:NAME``) -> label in tables and figures."""

SHIELDED_BASELINES: dict[str, str] = {"straight_shield": "straight", "social_force_shield": "social_force"}
"""Shielded baseline -> the scripted robot inside it: played with the env's action-time shield on (``shield``: the
shielded configuration's settings; ``true``, the defaults, from ``crowdnav evaluate baseline:NAME``)."""

EXPERIMENT_BASELINES = ("straight", "social_force", "onboard", "predictive", "oracle")
"""The baselines every experiment plays (those the core install runs; ``orca`` needs pyrvo). Where the
oracle or a predictive planner (onboard, predictive) refuses a scenario (the crowd reacts to the robot,
several robots, a unicycle), the experiment says so in one line and goes on without it."""

ONBOARD_BASELINES: dict[str, list[str]] = {"onboard": ["plan"], "straight": ["goal"], "straight_shield": ["goal", "plan"]}
"""Baselines that read only what the robot senses -> the observation keys that carry what they read (``goal``: its
pose and goal; ``plan``: the tracker's rows, the robot's pose and the map, which the shield reads too); every other
baseline reads the simulator's state (privileged)."""

PRIVILEGED_OBSERVATIONS = "privileged: the simulator's state"
"""What a privileged baseline's results declare it observed."""

SHIELD_READS = "the shield: the humans its tracker reports and the map"
BASELINE_READS: dict[str, str] = {
    "straight": "onboard: its pose and goal",
    "social_force": PRIVILEGED_OBSERVATIONS,
    "orca": PRIVILEGED_OBSERVATIONS,
    "onboard": "onboard: the humans its tracker reports, its pose, velocity and goal, the map (the plan observation's inputs)",
    "predictive": PRIVILEGED_OBSERVATIONS,
    "oracle": PRIVILEGED_OBSERVATIONS,
    "straight_shield": f"onboard: its pose and goal; {SHIELD_READS}",
    "social_force_shield": f"privileged: the simulator's state (its forces); {SHIELD_READS}",
}
"""Baseline name -> what it reads, in words (a track's reference entry says it): the shield reads the robot's tracker
and the map, never the simulator's state, so a shielded robot is as privileged as the robot inside it."""


def baseline_observations(name: str) -> list[str] | str:
    """What baseline ``name`` reads, as results declare it: its observation keys (onboard) or :data:`PRIVILEGED_OBSERVATIONS`."""
    return list(ONBOARD_BASELINES[name]) if name in ONBOARD_BASELINES else PRIVILEGED_OBSERVATIONS


def unknown_baseline(name: str) -> str | None:
    """None for a baseline name (``social-force`` spelled as render does, too); else the one-line refusal, with a "did you mean"."""
    name = name.replace("-", "_")
    if name in BASELINES:
        return None
    close = difflib.get_close_matches(name, list(BASELINES), n=1)  # suggested as typed: baseline:NAME
    hint = f"; did you mean 'baseline:{close[0]}'?" if close else ";"
    return f"unknown baseline {name!r}{hint} expected one of: {', '.join(f'baseline:{known}' for known in BASELINES)}"


def is_baseline(configuration: str) -> bool:
    """Whether a configuration name (a results table's ``configuration`` column) is a scripted baseline."""
    return str(configuration).startswith(BASELINE_PREFIX)


def scripted_policy(name: str) -> Any:
    """The scripted robot policy of a baseline name (:data:`BASELINES`; ``orca`` raises
    :class:`crowdnav.sim.orca_solver.OrcaUnavailableError`, one line, without pyrvo)."""
    from crowdnav.planning.scripted import SCRIPTED_POLICIES

    return SCRIPTED_POLICIES[SHIELDED_BASELINES.get(name, name).replace("_", "-")]()


def shielded(name: str, options: Mapping[str, Any], shield: Any = True) -> dict[str, Any]:
    """``options`` (env options) for baseline ``name``: with ``shield`` on for a shielded baseline, unchanged otherwise."""
    return {**options, "shield": shield} if name in SHIELDED_BASELINES else dict(options)


def baseline_env_options(train: Mapping[str, Any]) -> dict[str, Any]:
    """The env options a baseline shares with a configuration: scenario, overrides, reward (its own observation: the goal)."""
    options = {"scenario": train.get("scenario", "open_space"), "modalities": ["goal"], "overrides": dict(train.get("overrides", {})),
               "reward_weights": dict(train.get("reward_weights", {}))}
    if train.get("agents") == ROBOTS_AGENTS:  # the baseline drives every robot, as the shared policy does
        options["agents"] = ROBOTS_AGENTS
    return options


def experiment_baselines(experiment: Any) -> list[tuple[str, str, dict[str, Any]]]:
    """(configuration name, label, env options) of every baseline an experiment needs.

    One set of baselines (:data:`EXPERIMENT_BASELINES`) per distinct environment of its configurations, and the
    shielded ones (:data:`SHIELDED_BASELINES`) per distinct shield its configurations train with; with several
    environments the name and label carry the first configuration trained in each.
    """
    environments: dict[str, tuple[str, dict[str, Any]]] = {}
    shields: dict[str, tuple[str, dict[str, Any]]] = {}
    for configuration in experiment.configurations:
        options = baseline_env_options(configuration.train)
        environments.setdefault(repr(sorted(options.items())), (configuration.name, options))
        if configuration.train.get("shield"):
            guarded = {**options, "shield": configuration.train["shield"]}
            shields.setdefault(repr(sorted(guarded.items())), (configuration.name, guarded))
    several = len(environments) > 1 or len(shields) > 1
    played = [(first, options, name) for first, options in environments.values() for name in EXPERIMENT_BASELINES]
    played += [(first, options, name) for first, options in shields.values() for name in SHIELDED_BASELINES]
    return [(f"{BASELINE_PREFIX}{name}" + (f"_{first}" if several else ""), BASELINES[name] + (f" [{first}]" if several else ""), options)
            for first, options, name in played]


def evaluate_baseline(experiment: str, configuration: str, label: str, env_options: Mapping[str, Any], protocol: Protocol,
                      out_dir: str | Path) -> Path:
    """Play the baseline on the protocol's test episodes into ``out_dir`` (skipped when already there); returns the folder."""
    import pandas as pd
    from crowdnav.evaluation.provenance import git_commit, package_versions
    from crowdnav.evaluation.robot_rollout import RobotEpisodes
    from crowdnav.evaluation.rollout import HeldOutEpisodes
    from crowdnav.evaluation.unit_spec import RUN_COLUMNS

    from crowdnav.sim.simulator import OUTCOMES

    out_dir = Path(out_dir)
    if (out_dir / META_FILE).is_file():
        meta = read_json(out_dir / META_FILE)
        if meta.get("env") == dict(env_options) and _episodes_of(Protocol(**meta["protocol"])) == _episodes_of(protocol) \
                and not run_damage(out_dir, meta):  # a missing or damaged table: played again (it is deterministic)
            return out_dir  # deterministic: the same episodes give the same rows
    started = time.perf_counter()
    name = baseline_name(configuration)
    robots = env_options.get("agents") == ROBOTS_AGENTS
    episodes = (RobotEpisodes if robots else HeldOutEpisodes)(env_options, protocol.test_seeds)
    try:
        rows = episodes.run(scripted_policy(name), privileged=True)
    finally:
        episodes.close()
    once = pd.DataFrame(rows)
    frames = []
    for k, point in enumerate(protocol.evaluation_points):
        frame = once.copy()
        # the learned runs' columns: in env steps they also say how many episodes were trained (none, here)
        points = {"training_episodes": point} if protocol.unit == "episodes" else {"training_episodes": 0, "training_steps": point}
        for position, (column, value) in enumerate(zip((*RUN_COLUMNS, *points, "evaluation"),
                                                       (experiment, configuration, label, 0, *points.values(), k), strict=True)):
            frame.insert(position, column, value)
        frames.append(frame)
    tests = pd.concat(frames, ignore_index=True)
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_csv(tests, out_dir / TEST_FILE)
    steps = int(once["steps"].sum())
    meta = {
        "experiment": experiment, "configuration": configuration, "label": label, "seed": 0, "status": "complete",
        "kind": "baseline", "policy": name, "env": dict(env_options), "protocol": protocol.to_dict(),
        "versions": package_versions(), "git_commit": git_commit(), "wall_time_s": round(time.perf_counter() - started, 3),
        "env_steps": {"train": 0, "test": steps, "total": steps}, "training_episodes": 0, "test_episodes": len(once),
        "resumed": False, "final": {outcome: round(float((once["outcome"] == outcome).mean()), 6) for outcome in OUTCOMES},
    }
    atomic_write_json(out_dir / META_FILE, meta)  # last: it marks the baseline complete
    return out_dir


def _episodes_of(protocol: Protocol) -> tuple[str, int, int, int, int]:
    """What decides a baseline's rows: the test episodes and the evaluation points in their unit (not the number of seeds)."""
    return protocol.unit, protocol.budget, protocol.interval, protocol.test_episodes, protocol.test_seed_base


def baseline_name(configuration: str) -> str:
    """The baseline (:data:`BASELINES`) a configuration ``baseline_<name>[_<first configuration>]`` plays."""
    rest = configuration.removeprefix(BASELINE_PREFIX)
    return next(name for name in sorted(BASELINES, key=len, reverse=True) if rest == name or rest.startswith(name + "_"))


def evaluate_experiment_baselines(experiment: Any, folder: str | Path) -> list[Path | str]:
    """Every baseline of ``experiment`` into its results ``folder`` (``baseline_<name>/baseline``).

    Returns each baseline's folder, or a one-line message where it could not be played (its
    environment failed to build, e.g. a scenario file gone): the learned runs then fail or
    succeed on their own, as they would without baselines.
    """
    done: list[Path | str] = []
    for configuration, label, options in experiment_baselines(experiment):
        try:
            done.append(evaluate_baseline(experiment.name, configuration, label, options, experiment.protocol,
                                          baseline_folder(folder, configuration)))
        except Exception as error:  # noqa: BLE001 - reported, and the experiment's own runs go on
            done.append(f"baseline {label} skipped: {type(error).__name__}: {str(error).splitlines()[0]}")
    return done
