"""Evaluate any policy on a scenario's fixed held-out test episodes, in the protocol's own format.

``crowdnav evaluate POLICY --scenario NAME`` and :func:`evaluate_policy`. POLICY is one of:

* ``baseline:NAME`` (:data:`crowdnav.evaluation.baselines.BASELINES`: straight, social_force, orca,
  onboard, predictive, oracle): the scripted robots, privileged (they read the simulator; the oracle
  even the humans' future, docs/planning.md) but for ``onboard``, which reads only what the ``plan``
  observation carries (the humans its tracker reports, its pose and the map) and declares ``plan``;
  ``straight_shield`` and ``social_force_shield`` play those two with the action-time shield (its defaults) in
  their loop, the rows to show beside a shielded agent;
* ``module:function``: a Python callable ``function(observation) -> action`` taking one
  observation dict of :class:`crowdnav.envs.CrowdNavEnv` (raw units) and returning 2 numbers.
  This imports and runs that module: code by request (docs/security.md);
* a ``.zip`` saved by Stable-Baselines3 (SAC, TD3, DDPG, A2C, PPO with ``MultiInputPolicy``),
  trained on the scenario's observation ``Dict`` (``--modalities``). Only its parameters and
  plain JSON are read, never its pickled objects (:mod:`crowdnav.agents.sb3.model_zip`), so custom policy
  classes and sb3-contrib's algorithms are refused; a crowdnav checkpoint's own ``model.zip``
  loads as its checkpoint folder;
* a crowdnav training run folder or checkpoint (its own modalities and scenario settings unless
  ``--scenario`` names another scenario); only its parameters are loaded;
* a shared robot policy's run or checkpoint (``crowdnav train --agents robots``): its network drives
  every robot of the scenario (:class:`crowdnav.evaluation.robot_rollout.RobotEpisodes`), one row per
  robot per test episode, as an experiment with ``agents: robots`` evaluates it; on a track with
  several robots it drives the first robot only, the others social-force robots, as the track
  defines (:class:`crowdnav.evaluation.robot_rollout.FirstRobot`). Another scenario, ``--set`` or
  ``--modalities`` is refused in one line where it changes its robots or what its network reads.

The episodes are the test seeds ``test_seed_base``, ``test_seed_base + 1``, ... (default 0-19,
the protocol's held-out episodes; use e.g. 500 for final rankings): the same for every policy.
Results are keyed by what they measured, (policy, scenario, test set): the rows land in
``OUT/evaluate/<name>--<scenario>/seeds_<first>-<last>/`` (``test_episodes.csv`` and
``meta.json``, the columns of every protocol run), ``<scenario>`` the scenario's name (a file's
stem) with a short hash of its path and overrides when there are any. A folder that already
holds results is never replaced unless ``force=True`` (``--force``). ``crowdnav leaderboard OUT``
ranks them with any ``crowdnav benchmark`` results, one table per scenario and test set.

A policy that raises (or exits) while acting is one :class:`PolicyError` line naming it and the
exception; ``--traceback`` shows where.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import os
import re
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from crowdnav.evaluation.played_options import OptionRefusedError, check_played_world, refuse_modalities, run_env_options
from crowdnav.evaluation.result_table import episode_csv
from crowdnav.evaluation.robot_rollout import ROBOTS_AGENTS

from crowdnav.errors import CrowdNavError

EXPERIMENT = "evaluate"


Act = Callable[[Any], Any]
"""A policy as evaluation calls it: stacked observations (a privileged one: a simulator) -> actions."""


class PolicyError(CrowdNavError, ValueError):
    """A POLICY that cannot be loaded, whose spaces do not fit the scenario, or that raised while acting; one line."""


class ResultsExistError(CrowdNavError, FileExistsError):
    """The results folder of this (policy, scenario, test set) is already there and ``force`` was not given."""


def _load_sb3_zip(path: Path, options: Mapping[str, Any]) -> Act:
    """A zip saved by SB3 itself, rebuilt from its parameters and JSON (nothing unpickled)."""
    from crowdnav.agents.sb3.model_zip import ModelZipError, describe_shapes, zip_policy
    from crowdnav.agents.training.space_checks import box_space, dict_space

    from crowdnav.envs import CrowdNavEnv

    env = CrowdNavEnv(**options)
    try:
        act, shapes = zip_policy(path, env.observation_space, env.action_space)
    except ModelZipError as error:
        raise PolicyError(str(error)) from None
    finally:
        env.close()
    if act is None:  # the zip's observation shapes (never None then) differ from the scenario's
        scenario = describe_shapes({key: box_space(env.observation_space, key).shape for key in dict_space(env.observation_space).spaces})
        raise PolicyError(f"{path} expects observations {describe_shapes(shapes or {})}, but the scenario with modalities "
                          f"{list(options.get('modalities') or [])} gives {scenario}; pass the --modalities it was trained on")
    return act


def is_code_policy(spec: str) -> bool:
    """True for a POLICY that :func:`resolve_policy` would import as ``module:function`` (it runs that module's code)."""
    return not spec.startswith("baseline:") and not Path(spec).exists() and _CALLABLE.fullmatch(spec) is not None


_CALLABLE = re.compile(r"[A-Za-z_][\w.]*:[A-Za-z_]\w*")


def resolve_policy(spec: str, env_options: Mapping[str, Any], *, allow_import: bool = True) -> tuple[str, str, Act, bool, dict[str, Any]]:
    """(configuration name, label, act, privileged, env options) for a POLICY string.

    ``act`` maps stacked observations (or, with ``privileged``, a simulator) to actions. A
    ``module:function`` imports that module from the current folder or ``sys.path`` (it runs its
    code); with ``allow_import=False`` (a POLICY read from a file) it is refused instead.
    """
    options = dict(env_options)
    if spec.startswith("baseline:"):
        from crowdnav.evaluation.baselines import BASELINE_PREFIX, BASELINES, scripted_policy, unknown_baseline

        name = spec.removeprefix("baseline:").replace("-", "_")  # the render spelling (social-force) is accepted
        refusal = unknown_baseline(name)
        if refusal:
            raise PolicyError(refusal)
        from crowdnav.evaluation.baselines import baseline_observations

        reads = baseline_observations(name)
        _refused(refuse_modalities, spec, options, f"only {', '.join(reads)}" if isinstance(reads, list) else "the simulator's state")
        from crowdnav.evaluation.baselines import shielded

        return f"{BASELINE_PREFIX}{name}", BASELINES[name], scripted_policy(name), True, shielded(name, options)
    path = Path(spec)
    from crowdnav.agents.runs.folder import POLICY_FILE

    if path.suffix == ".zip" and path.is_file() and (path.parent / POLICY_FILE).is_file():
        path = path.parent  # a crowdnav checkpoint's own model.zip: its folder's config rebuilds the network
        spec = str(path)
    elif path.suffix == ".zip" and path.is_file():
        if not options.get("modalities"):  # the zip knows its observation keys: no --modalities needed
            options["modalities"] = _zip_modalities(path)
        return _safe(path.stem), path.stem, _load_sb3_zip(path, options), False, options
    if path.exists():
        from crowdnav.agents import load_policy
        from crowdnav.agents.runs.folder import training_run

        path = training_run(path)
        try:
            policy = load_policy(path)
        except (FileNotFoundError, ValueError) as error:
            raise PolicyError(f"{path}: {error}") from None
        # its own settings, changed where --scenario and --set say; what its network cannot take is refused in one line
        played = _refused(run_env_options, spec, policy.env_options, options)
        _refused(check_played_world, spec, policy, played)
        return _safe(_run_name(Path(spec))), _run_name(Path(spec)), policy, False, played
    if _CALLABLE.fullmatch(spec):
        if not allow_import:
            raise PolicyError(f"{spec[:200]}: a module:function read from a file is never imported; name it on the command line")
        module_name, function_name = spec.split(":")
        if os.getcwd() not in sys.path and "" not in sys.path:
            sys.path.insert(0, os.getcwd())  # as `python -m` does: a module next to where the command runs imports
        try:
            function = getattr(importlib.import_module(module_name), function_name)
        except (ImportError, AttributeError) as error:
            raise PolicyError(f"{spec}: cannot import {function_name!r} from {module_name!r} ({error})") from None

        def act(batch: Mapping[str, np.ndarray]) -> np.ndarray:  # the callable takes one observation at a time
            from crowdnav.envs.core import real_array

            count = len(next(iter(batch.values())))
            actions = [real_array(function({key: value[i] for key, value in batch.items()}), f"the action {spec} returned") for i in range(count)]
            wrong = next((action.shape for action in actions if action.shape != (2,)), None)
            if wrong is not None:
                raise ValueError(f"the action {spec} returned must be 2 numbers, got shape {wrong}")
            return np.stack(actions).astype(np.float32)

        return _safe(f"{module_name}_{function_name}"), spec, act, False, options
    from crowdnav.evaluation.baselines import BASELINES

    raise PolicyError(f"{spec}: expected a run folder or checkpoint, an SB3 model .zip, module:function, or baseline:NAME "
                      f"({', '.join(f'baseline:{name}' for name in BASELINES)})")


def _refused(check: Callable[..., Any], *args: Any) -> Any:
    """``check(*args)``, its :class:`OptionRefusedError` as a PolicyError (the same one line)."""
    try:
        return check(*args)
    except OptionRefusedError as error:
        raise PolicyError(str(error)) from None


def _zip_modalities(path: Path) -> list[str] | None:
    """The observation keys an SB3 zip was trained on, read from its JSON (None when it does not say)."""
    from crowdnav.agents.sb3.model_zip import ModelZipError, observation_shapes, read_model_zip

    try:
        shapes = observation_shapes(read_model_zip(path, read=()))  # the JSON only: no tensor is decompressed
    except ModelZipError as error:
        raise PolicyError(str(error)) from None
    return list(shapes) if shapes else None


def scenario_key(scenario: str, overrides: Mapping[str, Any]) -> str:
    """A folder-safe key of the environment: the library name, or a file's stem plus a hash of its path and overrides."""
    path = Path(scenario)
    library = not path.suffix and os.sep not in scenario
    if library and not overrides:
        return _safe(scenario)
    identity = json.dumps({"scenario": scenario if library else str(path.resolve()), "overrides": overrides}, sort_keys=True, default=str)
    return f"{_safe(path.stem)}-{hashlib.sha256(identity.encode()).hexdigest()[:8]}"


def _guarded(act: Act, spec: str) -> Act:
    """``act`` whose exceptions (and exits) become one PolicyError line naming the policy (:class:`_Guarded`)."""
    return _Guarded(act, spec)


class _Guarded:
    """A policy whose failures are one PolicyError line; a recurrent one keeps its ``recurrent`` flag and ``predict``."""

    def __init__(self, act: Act, spec: str):
        self.act, self.spec = act, spec
        self.recurrent = bool(getattr(act, "recurrent", False))

    def __call__(self, batch: Any) -> Any:
        return self._guard(self.act, batch)

    def predict(self, batch: Any, state: Any = None, episode_start: Any = None) -> Any:
        return self._guard(self.act.predict, batch, state, episode_start)  # type: ignore[attr-defined]

    def _guard(self, function: Callable[..., Any], *args: Any) -> Any:
        try:
            return function(*args)
        except PolicyError:
            raise
        except (Exception, SystemExit) as error:  # any failure of the user's policy is reported, not a crash
            message = str(error).splitlines()[0] if str(error) else ""
            raise PolicyError(f"{self.spec} raised {type(error).__name__}{': ' + message if message else ''} while acting "
                              "(--traceback shows where)") from error


def _run_name(path: Path) -> str:
    """``lidar_seed_2`` for EXPERIMENT/lidar/seed_2, ``sac`` for runs/sac/checkpoint."""
    from crowdnav.agents.runs.folder import CHECKPOINT_DIR, POLICY_FILE
    from crowdnav.evaluation.storage import SEED_PREFIX, TRAIN_DIR

    parts = [part for part in path.resolve().parts if part not in (CHECKPOINT_DIR, POLICY_FILE, TRAIN_DIR)]
    return f"{parts[-2]}_{parts[-1]}" if parts[-1].startswith(SEED_PREFIX) and len(parts) > 1 else parts[-1]


def _safe(name: str) -> str:
    cleaned = re.sub(r"[^A-Za-z0-9_.-]", "_", name).lstrip("._-")[:100]
    return cleaned or "policy"


def evaluate_policy(spec: str, scenario: str | None, out: str | Path, *, modalities: Sequence[str] | None = None,
                    episodes: int = 20, test_seed_base: int = 0, overrides: Mapping[str, Any] | None = None,
                    name: str | None = None, force: bool = False, progress: bool = False, track: Any = None) -> Path:
    """Play POLICY on ``episodes`` fixed test episodes of ``scenario``; returns the run folder written.

    Raises :class:`ResultsExistError` when this (policy, scenario, test set) has results in
    ``out`` already and ``force`` is False; ``progress`` shows a bar over the episodes.
    ``track`` (a :class:`crowdnav.evaluation.track.Track`) replaces the scenario, overrides, episodes
    and seeds with the track's, refuses observation keys it does not allow, and records its name and
    version in ``meta.json`` (the folder is ``<name>--track-<track>-v<version>``). Torch-free for the
    scripted baselines and ``module:function`` policies (no pandas either).
    """
    from crowdnav.evaluation.protocol import Protocol
    from crowdnav.evaluation.provenance import git_commit, package_versions
    from crowdnav.evaluation.storage import (
        META_FILE,
        TEST_FILE,
        atomic_write_json,
        atomic_write_text,
        evaluated_run_name,
        install_result,
        result_lock,
    )
    from crowdnav.evaluation.unit_spec import RUN_COLUMNS

    from crowdnav.paths import inside
    from crowdnav.sim.simulator import OUTCOMES

    if track is not None:
        if overrides:
            raise PolicyError(f"--set changes the scenario, which track {track.name} fixes; leave it out, or evaluate with --scenario")
        scenario, episodes, test_seed_base = track.scenario, track.test_episodes, track.test_seed_base
        overrides = track.env_options()["overrides"]
    if scenario is None:
        raise PolicyError("name a scenario (--scenario) or a track (--track)")
    if not 1 <= episodes <= MAX_EPISODES:  # the rows are kept until written: a bound on memory (docs/security.md)
        raise OptionRefusedError(f"--episodes must be from 1 to {MAX_EPISODES:,}, got {episodes:,}")
    options: dict[str, Any] = {"scenario": scenario, "modalities": list(modalities) if modalities else None,
                               "overrides": dict(overrides or {})}
    options = {key: value for key, value in options.items() if value is not None}
    robots: Any = None
    declared: list[str] | str
    from crowdnav.evaluation.evaluate_robots import RobotsPolicyError, is_shared_robots_policy, resolve_robots_policy, robot_keys

    if is_shared_robots_policy(spec):  # one network for every robot: its own rows (load_policy refuses it)
        try:
            run, robots, env_options = resolve_robots_policy(spec, options, track)
        except (OptionRefusedError, RobotsPolicyError) as error:
            raise PolicyError(str(error)) from None
        label = _run_name(run)  # the run's name, also for its checkpoint's model.zip
        configuration = _safe(label)
        act, privileged, declared = robots, False, robot_keys(env_options)
    else:
        configuration, label, act, privileged, env_options = resolve_policy(spec, options)
        declared = _declared_observations(spec, privileged, env_options)
    if track is not None:
        env_options = {**env_options, "scenario": track.scenario, "overrides": dict(options["overrides"])}  # a run's own settings never win
        if isinstance(declared, list):  # what it reads must be allowed (baseline:onboard: the plan observation's inputs)
            track.check_observations(declared)
        from crowdnav.evaluation.track import track_key

        environment = track_key(track)
    else:
        environment = scenario_key(scenario, options.get("overrides", {}))
    configuration = f"{_safe(name) if name else configuration}--{environment}"
    label = name or label  # --name names the row in tables and figures too
    folder = inside(out, f"{EXPERIMENT}/{evaluated_run_name(configuration, test_seed_base, test_seed_base + episodes - 1)}")
    with result_lock(folder):  # one writer at a time; a second one is refused at once, naming this one's PID
        if not force and (folder / META_FILE).exists():
            raise ResultsExistError(f"{folder} already holds this policy's results on this scenario and test set; "
                                    "pass --force (force=True) to replace them, or --out another folder")
        protocol = Protocol(train_episodes=1, eval_every=1, test_episodes=episodes, seeds=1, test_seed_base=test_seed_base,
                            final_evaluations=1)
        started = time.perf_counter()
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=episodes, unit="ep", desc=f"evaluate {label}", leave=False)
        leading = dict(zip((*RUN_COLUMNS, "training_episodes", "evaluation"), (EXPERIMENT, configuration, label, 0, 0, 0), strict=True))
        on_end = bar.update if bar is not None else None
        try:
            if robots is not None and track is None:  # every robot driven by the shared network: one row per robot
                from crowdnav.evaluation.evaluate_robots import play_robots

                table, steps, outcomes = play_robots(robots, env_options, protocol.test_seeds, leading, on_end)
            else:
                if robots is not None:  # the track's game: the first robot evaluated, the env's social-force robots the others
                    from crowdnav.evaluation.evaluate_robots import observation_space
                    from crowdnav.evaluation.robot_rollout import FirstRobot

                    act = FirstRobot(robots, observation_space(env_options))
                table, steps, outcomes = _play(_guarded(act, spec), env_options, protocol.test_seeds, privileged, leading, on_end)
        except PolicyError:
            raise
        except (ValueError, TypeError) as error:  # an action of the wrong shape or type, from the user's policy
            raise PolicyError(f"{spec}: {str(error).splitlines()[0]}") from error
        finally:
            if bar is not None:
                bar.close()
        meta = {
            "experiment": EXPERIMENT, "configuration": configuration, "label": label, "seed": 0, "status": "complete",
            "kind": "evaluated", "policy": spec, "scenario": scenario, "env": env_options, "protocol": protocol.to_dict(),
            # what to load again for a replay (crowdnav trajectories): a file by its absolute path; a module:function is
            # imported again only when the user names it on the command line (docs/security.md)
            "policy_source": str(Path(spec).resolve()) if Path(spec).exists() else spec,
            "versions": package_versions(),
            "git_commit": git_commit(), "wall_time_s": round(time.perf_counter() - started, 3),
            "env_steps": {"train": 0, "test": steps, "total": steps}, "training_episodes": 0, "test_episodes": len(outcomes),
            "resumed": False, "final": {outcome: round(outcomes.count(outcome) / len(outcomes), 6) for outcome in OUTCOMES},
            "observations": declared,
        }
        if track is not None:
            meta["track"] = track.identity()
        if robots is not None:  # whom the shared network drove; env.agents: the robots-only env played every robot
            meta["robots"] = robots.robots if track is None else robots.robots[:1]
            if track is None:
                meta["env"] = {**env_options, "agents": ROBOTS_AGENTS}
        return install_result(folder, lambda staging: (atomic_write_text(staging / TEST_FILE, table), atomic_write_json(staging / META_FILE, meta)))


BATCH_EPISODES = 500
"""Test episodes played side by side at most (a batch's envs and step logs are freed before the next): memory stays
bounded whatever ``episodes``; 500, the final rankings' count, plays as one batch as before batches existed."""
MAX_EPISODES = 100_000
"""The most test episodes one evaluation plays (their CSV rows are kept until written: ~0.5 KB each)."""


def _play(act: Act, env_options: Mapping[str, Any], seeds: Sequence[int], privileged: bool, leading: Mapping[str, Any],
          on_end: Callable[[], None] | None) -> tuple[str, int, list[str]]:
    """(CSV text of the episode rows, env steps, outcomes) of one episode per seed, played :data:`BATCH_EPISODES` at a time.

    Each episode is its seed's alone (world i of a batch is the single env seeded with seed i), so
    the batches give the rows one batch of all seeds would.
    """
    from crowdnav.evaluation.rollout import HeldOutEpisodes

    parts, steps, outcomes = [], 0, []
    for first in range(0, len(seeds), BATCH_EPISODES):
        held_out = HeldOutEpisodes(env_options, seeds[first:first + BATCH_EPISODES])
        try:
            rows = held_out.run(act, privileged=privileged, on_end=on_end)
        finally:
            held_out.close()
        for row in rows:
            row["test_episode"] += first  # numbered over the whole test set, not the batch
        text = episode_csv([{**leading, **row} for row in rows])
        parts.append(text if first == 0 else text.partition("\n")[2])  # the header once
        steps += sum(int(row["steps"]) for row in rows)
        outcomes += [str(row["outcome"]) for row in rows]
    return "".join(parts), steps, outcomes


def _declared_observations(spec: str, privileged: bool, env_options: Mapping[str, Any]) -> list[str] | str:
    """What the results declare the policy observed: its observation keys, or that it read the simulator's state."""
    if not privileged:
        return _observation_keys(env_options)
    from crowdnav.evaluation.baselines import baseline_observations

    return baseline_observations(spec.removeprefix("baseline:").replace("-", "_"))


def _observation_keys(env_options: Mapping[str, Any]) -> list[str]:
    """The observation keys a policy reads in ``env_options`` (its modalities, or the scenario's default ones)."""
    if env_options.get("modalities"):
        return list(env_options["modalities"])
    from crowdnav.envs import CrowdNavEnv

    env = CrowdNavEnv(**env_options)
    try:
        return list(env.observation_space.keys())  # type: ignore[attr-defined]
    finally:
        env.close()
