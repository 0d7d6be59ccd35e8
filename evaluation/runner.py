"""One unit of work: train one configuration with one seed and evaluate it along the protocol.

:func:`run_unit` is a plain function of plain data (a :class:`UnitSpec`, or its dict, and a
folder) returning a plain dict, so a process pool, a Ray task or a test can call it alike.
It is idempotent: a finished run is skipped; an interrupted one resumes training from its
last checkpoint and evaluates only the evaluation points not yet on disk; nothing already
written is overwritten.

How the protocol maps onto training: ``crowdnav.agents.train`` saves a policy snapshot every
``eval_every`` episodes (``checkpoint_every``), or every ``eval_every_steps`` env steps
(``checkpoint_every_steps``) for a protocol in env steps, and each snapshot is evaluated on the
held-out test episodes with the deterministic policy. Evaluating a saved snapshot is the
same as evaluating during training (the test episodes touch neither the model nor its replay
buffer), and it lets a resumed run evaluate what the interrupted one had trained.

What a run is (:class:`UnitSpec`, :data:`PROTOCOL_FIELDS`, :data:`PRETRAINED`, :data:`RUN_COLUMNS`) lives
in :mod:`crowdnav.evaluation.unit_spec`, and the provenance every result records (:func:`git_commit`,
:func:`package_versions`) in :mod:`crowdnav.evaluation.provenance`; both are importable from here too.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from crowdnav.agents.runs.folder import (
    POLICY_FILE,
    checkpoint_dir,
    checkpoint_info,
    episode_log,
    policy_snapshots,
    recover_checkpoint,
    writing,
)
from crowdnav.evaluation.protocol import AXIS_LABELS, Protocol
from crowdnav.evaluation.provenance import git_commit as git_commit
from crowdnav.evaluation.provenance import package_versions as package_versions
from crowdnav.evaluation.robot_rollout import ROBOTS_AGENTS
from crowdnav.evaluation.storage import (
    EVALUATIONS_DIR,
    META_FILE,
    SPEC_FILE,
    TEST_FILE,
    TRAIN_DIR,
    TRAINING_FILE,
    ResultsError,
    atomic_write_csv,
    atomic_write_json,
    clean_temporaries,
    read_json,
    run_damage,
    table_damage,
)
from crowdnav.evaluation.unit_spec import PRETRAINED as PRETRAINED
from crowdnav.evaluation.unit_spec import PROTOCOL_FIELDS as PROTOCOL_FIELDS
from crowdnav.evaluation.unit_spec import RUN_COLUMNS as RUN_COLUMNS
from crowdnav.evaluation.unit_spec import UnitSpec as UnitSpec
from crowdnav.evaluation.unit_spec import run_identity

from crowdnav.sim.simulator import OUTCOMES as OUTCOMES

if TYPE_CHECKING:
    from crowdnav.agents.marl.robots import RobotsPolicy
    from crowdnav.agents.runs.checkpoint import AgentPolicy
    from crowdnav.agents.training.config import TrainConfig
    from crowdnav.evaluation.robot_rollout import RobotEpisodes
    from crowdnav.evaluation.rollout import HeldOutEpisodes

EventHook = Callable[[str, dict[str, Any]], None]
"""``hook(event, data)``: ``"trained"`` ({episodes}, and {steps} for a protocol in env steps) and ``"evaluated"``
({evaluation, training_episodes}, {training_steps} for a protocol in env steps, and the rate of each of
:data:`OUTCOMES`: success, collision, out_of_bounds, truncated)."""


def run_unit(spec: UnitSpec | Mapping[str, Any], out_dir: str | Path, *, on_event: EventHook | None = None) -> dict[str, Any]:
    """Train and evaluate one run into ``out_dir`` (resuming or skipping as needed); returns its summary.

    Summary: experiment, configuration, seed, ``status`` (``"done"`` or ``"skipped"`` when it
    was already complete), ``resumed``, final rate of each outcome (``final_<outcome>``, one per
    :data:`OUTCOMES`; a run finished before ``out_of_bounds`` existed has no ``final_out_of_bounds``),
    env steps, wall time and the folder.
    """
    spec = spec if isinstance(spec, UnitSpec) else UnitSpec.from_dict(spec)
    out_dir = Path(out_dir)
    hook = on_event or (lambda event, data: None)
    _claim(out_dir, spec)
    meta = out_dir / META_FILE
    if meta.is_file() and not _damage(out_dir):
        return _summary(spec, out_dir, read_json(meta), "skipped")
    with writing(out_dir):  # one process per run: a second one (an orphaned worker, another sweep) is refused
        damage = _damage(out_dir) if meta.is_file() else []
        if meta.is_file() and not damage:  # finished (or repaired) by the process that held the lock before
            return _summary(spec, out_dir, read_json(meta), "skipped")
        try:
            return _train_and_evaluate(spec, out_dir, hook, [f"{problem}: rebuilt" for problem in damage])
        except Exception:
            if meta.is_file():  # damaged beyond repair: no longer a finished run anywhere (the document is kept aside)
                meta.replace(meta.with_name(META_FILE + ".damaged"))
            raise


def _damage(out_dir: Path) -> list[str]:
    """What is missing or damaged in a finished run's tables (:func:`crowdnav.evaluation.storage.run_damage`)."""
    try:
        return run_damage(out_dir, read_json(out_dir / META_FILE))
    except (OSError, ValueError, KeyError, TypeError):
        return [f"{META_FILE} is unreadable"]


def _train_and_evaluate(spec: UnitSpec, out_dir: Path, hook: EventHook, repairs: list[str] | None = None) -> dict[str, Any]:
    from crowdnav.agents import load_policy, train

    clean_temporaries(out_dir)  # files a kill left half-written before their rename
    clock = _Clock(out_dir / "timing.json")
    protocol = Protocol(**spec.protocol)
    config = spec.config_for(out_dir)
    train_dir = out_dir / TRAIN_DIR
    trained = _trained(train_dir, recover_checkpoint(train_dir), protocol)
    resumed = trained > 0 or (out_dir / EVALUATIONS_DIR).is_dir()
    # the run's own TrainConfig rebuilds each snapshot's network: validated once, at experiment load
    loader: Callable[[Path], Any] = lambda folder: load_policy(folder, config=config)  # noqa: E731
    rows = protocol.test_episodes
    if config.agents == ROBOTS_AGENTS:  # one shared policy for every robot: one row per robot per test episode
        from crowdnav.agents.marl.robots import load_robots_policy
        from crowdnav.agents.sb3.factory import env_options
        from crowdnav.evaluation.robot_rollout import robot_count

        loader = lambda folder: load_robots_policy(folder, config=config)  # noqa: E731
        rows *= robot_count(env_options(config))
    evaluator = _Evaluator(spec, out_dir, protocol, loader, clock, hook, repairs, rows)
    if trained < protocol.budget:
        evaluator.evaluate_available(train_dir)  # before resuming replaces the checkpoint
        result = train(config, resume=checkpoint_dir(train_dir).exists(), on_checkpoint=lambda episodes: clock.save())
        clock.save()
        hook("trained", {"episodes": protocol.train_episodes} if protocol.unit == "episodes" else
             {"episodes": result.episodes, "steps": protocol.train_steps})
    evaluator.evaluate_available(train_dir)
    evaluator.close()
    missing = [k for k in range(protocol.evaluations) if not evaluator.done(k)]
    if missing:
        raise ResultsError(f"{train_dir}: no policy snapshot for evaluation(s) {missing} "
                           f"(after {[protocol.evaluation_points[k] for k in missing]} {AXIS_LABELS[protocol.unit]})"
                           + "".join(f"; {note}" for note in evaluator.repairs if "evaluated again" not in note))
    return _finish(spec, out_dir, protocol, config, clock, resumed, evaluator.repairs)


def _trained(train_dir: Path, episodes: int, protocol: Protocol) -> int:
    """How far the checkpoint has trained, in the protocol's unit (``episodes``: what recover_checkpoint returned)."""
    if protocol.unit == "episodes":
        return episodes
    return int((checkpoint_info(train_dir) or {}).get("timesteps", 0))


def _claim(out_dir: Path, spec: UnitSpec) -> None:
    """Write spec.json, or check that the folder holds this run.

    A folder of the same experiment, configuration and seed whose training config, protocol or
    label changed (the experiment file was edited; the protocol's ``seeds`` does not count: see
    :func:`~crowdnav.evaluation.unit_spec.run_identity`) is moved aside to ``<folder>.replaced-N`` and
    the run starts afresh: nothing is overwritten (a protocol whose budget changed unit, episodes
    or env steps, is such a change: its snapshots and rows are never mixed). A folder of another
    run is refused.
    """
    path = out_dir / SPEC_FILE
    if path.is_file():
        existing = run_identity(read_json(path))
        wanted = run_identity(spec.to_dict())
        if existing != wanted:
            changed = sorted(key for key in wanted if existing.get(key) != wanted[key])
            if any(existing.get(key) != wanted[key] for key in ("experiment", "configuration", "seed")):
                raise ResultsError(f"{out_dir} holds a different run (its {', '.join(changed)} differ from this experiment's); "
                                   "use another output folder or remove that one")
            aside = next(out_dir.with_name(f"{out_dir.name}.replaced-{n}") for n in range(1, 10_000)
                         if not out_dir.with_name(f"{out_dir.name}.replaced-{n}").exists())
            out_dir.rename(aside)  # the edited configuration's old run, kept
            out_dir.mkdir(parents=True)
    if not path.is_file():
        atomic_write_json(path, spec.to_dict())


class _Evaluator:
    """Evaluates the policies of the scheduled points, one CSV per evaluation."""

    def __init__(self, spec: UnitSpec, out_dir: Path, protocol: Protocol, load_policy: Callable[[Path], AgentPolicy | RobotsPolicy],
                 clock: _Clock, hook: EventHook, repairs: list[str] | None = None, rows: int | None = None):
        self.spec, self.protocol, self.load_policy, self.clock, self.hook = spec, protocol, load_policy, clock, hook
        self.rows = protocol.test_episodes if rows is None else rows
        """Rows of one evaluation's table: a test episode's (one, or one per robot for a shared robot policy)."""
        self.folder = out_dir / EVALUATIONS_DIR
        self.episodes: HeldOutEpisodes | RobotEpisodes | None = None  # the test environments, built on first use
        self.repairs = list(repairs or [])
        """What was found missing or damaged in the run's files, and what was done about it."""
        self._checked: set[int] = set()

    def _set_aside_if_damaged(self, k: int) -> None:
        """A damaged evaluation file (cut or garbage rows, a wrong count) moves to ``<name>.damaged``, to be evaluated again."""
        path = self.path(k)
        if k in self._checked or not path.is_file():
            return
        self._checked.add(k)
        fixed = {"experiment": self.spec.experiment, "configuration": self.spec.configuration, "seed": self.spec.seed, "evaluation": k}
        damage = table_damage(path, self.rows, fixed)
        if damage is not None:
            path.replace(path.with_name(path.name + ".damaged"))
            self.repairs.append(f"{EVALUATIONS_DIR}/{damage}: evaluated again from its snapshot (kept as {path.name}.damaged)")

    def path(self, k: int) -> Path:
        return self.folder / f"evaluation_{k:03d}.csv"

    def done(self, k: int) -> bool:
        return self.path(k).is_file()

    def evaluate_available(self, train_dir: Path) -> None:
        """Evaluate every scheduled point that has a saved policy and no results yet."""
        folders = policy_snapshots(train_dir, self.protocol.unit)  # a step run's snapshots are steps_<N>, named by the point
        points = self.protocol.evaluation_points
        for k, point in enumerate(points):
            self._set_aside_if_damaged(k)
            if self.done(k):
                continue
            # The policy saved at the point (a snapshot can land a few episodes late: it is taken at a rollout's end).
            upper = points[k + 1] if k + 1 < len(points) else point + self.protocol.interval
            candidates = sorted(saved for saved in folders if point <= saved < upper)
            if candidates:
                self._evaluate(k, candidates[0], folders[candidates[0]])

    def _evaluate(self, k: int, saved_at: int, folder: Path) -> None:
        import pandas as pd
        from crowdnav.evaluation.robot_rollout import RobotEpisodes
        from crowdnav.evaluation.rollout import HeldOutEpisodes

        policy = self.load_policy(folder)
        if self.episodes is None:
            robots = policy.info.get("agents") == ROBOTS_AGENTS
            self.episodes = (RobotEpisodes if robots else HeldOutEpisodes)(policy.env_options, self.protocol.test_seeds)
        rows = self.episodes.run(policy)  # type: ignore[arg-type]  # each kind of episodes gets its own kind of policy
        spec = self.spec
        frame = pd.DataFrame(rows)
        if self.protocol.unit == "episodes":  # the columns every result had before step budgets: older tables read the same
            points = {"training_episodes": saved_at}
        else:  # the point in env steps, and the episodes the run had finished by then (its snapshot records them)
            points = {"training_episodes": int(read_json(folder / POLICY_FILE)["episodes"]), "training_steps": saved_at}
        for position, (name, value) in enumerate(zip(
            (*RUN_COLUMNS, *points, "evaluation"),
            (spec.experiment, spec.configuration, spec.display_label, spec.seed, *points.values(), k), strict=True,
        )):
            frame.insert(position, name, value)
        atomic_write_csv(frame, self.path(k))
        self.clock.save()
        rates = {outcome: float((frame["outcome"] == outcome).mean()) for outcome in OUTCOMES}
        self.hook("evaluated", {"evaluation": k, **points, **rates})

    def close(self) -> None:
        if self.episodes is not None:
            self.episodes.close()


def _finish(spec: UnitSpec, out_dir: Path, protocol: Protocol, config: TrainConfig, clock: _Clock, resumed: bool,
            repairs: list[str]) -> dict[str, Any]:
    """Assemble the run's tables and write meta.json (last: it marks the run complete)."""
    import pandas as pd

    evaluations = [pd.read_csv(out_dir / EVALUATIONS_DIR / f"evaluation_{k:03d}.csv", keep_default_na=False, na_values=["nan"])
                   for k in range(protocol.evaluations)]
    tests = pd.concat(evaluations, ignore_index=True)
    atomic_write_csv(tests, out_dir / TEST_FILE)
    train_info = checkpoint_info(out_dir / TRAIN_DIR)
    if train_info is None:  # training returned without saving one: nothing to describe the run with
        raise ResultsError(f"{out_dir / TRAIN_DIR}: no checkpoint after training")
    training = _training_episodes(spec, episode_log(out_dir / TRAIN_DIR), int(train_info["episodes"]), repairs)
    atomic_write_csv(training, out_dir / TRAINING_FILE)
    timing = clock.save()
    final = tests[tests["evaluation"] >= protocol.evaluations - protocol.final_evaluations]
    train_steps, test_steps = int(train_info["timesteps"]), int(tests["steps"].sum())
    meta = {
        **{name: value for name, value in zip(RUN_COLUMNS, (spec.experiment, spec.configuration, spec.display_label, spec.seed),
                                              strict=True)},
        "status": "complete",
        "protocol": protocol.to_dict(),
        "config": config.model_dump(),
        "versions": package_versions(),
        # the code the run started with, and every commit a later session resumed it with
        "git_commit": timing["commits"][0],
        "git_commits": timing["commits"],
        "wall_time_s": round(timing["seconds"], 3),
        "sessions": timing["sessions"],
        "env_steps": {"train": train_steps, "test": test_steps, "total": train_steps + test_steps},
        "training_episodes": int(len(training)),
        "test_episodes": int(len(tests)),
        "resumed": resumed,
        "final": {outcome: round(float((final["outcome"] == outcome).mean()), 6) for outcome in OUTCOMES},
    }
    atomic_write_json(out_dir / META_FILE, meta)
    # an earlier session's failure, now resumed and finished: its traceback no longer describes the run
    (out_dir / "error.log").unlink(missing_ok=True)
    return {**_summary(spec, out_dir, meta, "repaired" if repairs else "done"), **({"repairs": repairs} if repairs else {})}


def _training_episodes(spec: UnitSpec, log: Path, episodes: int, repairs: list[str]) -> Any:
    """agents' episodes.csv, exactly one whole row per training episode (:func:`crowdnav.agents.runs.episode_log.read_log`), as a table.

    A cut last row a kill left is set aside first (noted in ``repairs``); a missing, damaged or
    short log is a ResultsError that names the file and line (those episodes cannot be replayed).
    """
    import pandas as pd
    from crowdnav.agents.runs.episode_log import COLUMNS, EpisodeLogError, prepare_log, read_log

    notes: list[str] = []
    try:
        notes = prepare_log(log, episodes) if log.is_file() else []
        rows = read_log(log, episodes)
    except EpisodeLogError as error:
        raise ResultsError(f"{error}{''.join(f' (found: {note})' for note in notes)}") from None
    repairs += [f"train/{note}" for note in notes]
    frame = pd.DataFrame(rows, columns=list(COLUMNS)).rename(columns={"seed": "episode_seed"})
    for position, (name, value) in enumerate(zip(
        RUN_COLUMNS, (spec.experiment, spec.configuration, spec.display_label, spec.seed), strict=True,
    )):
        frame.insert(position, name, value)
    return frame


class _Clock:
    """Wall time and code of the sessions that worked on a run, kept in timing.json.

    Each session adds the time up to its last saved result (end of training, an evaluation,
    the end); the work a crash throws away is not counted. ``commits`` lists the crowdnav
    commit each session ran (read when the session starts, the code it imported).
    """

    def __init__(self, path: Path):
        self.path = path
        self.last = time.perf_counter()
        self.first_save = True
        self.commit = git_commit()

    def save(self) -> dict[str, Any]:
        now = time.perf_counter()
        timing: dict[str, Any] = read_json(self.path) if self.path.is_file() else {"seconds": 0.0, "sessions": 0}
        commits = list(timing.get("commits", []))
        if self.first_save and (not commits or commits[-1] != self.commit):
            commits.append(self.commit)
        timing = {"seconds": timing["seconds"] + now - self.last, "sessions": timing["sessions"] + self.first_save, "commits": commits}
        atomic_write_json(self.path, timing)
        self.last, self.first_save = now, False
        return timing


def _summary(spec: UnitSpec, out_dir: Path, meta: Mapping[str, Any], status: str) -> dict[str, Any]:
    return {
        "experiment": spec.experiment, "configuration": spec.configuration, "seed": spec.seed, "status": status,
        "resumed": bool(meta.get("resumed", False)), **{f"final_{key}": value for key, value in meta["final"].items()},
        "wall_time_s": meta["wall_time_s"], "env_steps": meta["env_steps"]["total"], "out": str(out_dir),
    }

