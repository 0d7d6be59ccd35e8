"""Evaluate any policy on a scenario's fixed held-out test episodes, in the protocol's own format.

``crowdnav evaluate POLICY --scenario NAME`` and :func:`evaluate_policy`. POLICY is one of:

* ``baseline:straight`` / ``baseline:social_force``: the scripted robots (privileged: they read
  the simulator);
* ``module:function``: a Python callable ``function(observation) -> action`` taking one
  observation dict of :class:`crowdnav.envs.CrowdNavEnv` (raw units) and returning 2 numbers;
* a ``.zip`` saved by Stable-Baselines3 (SAC, TD3, DDPG, A2C, PPO; sb3-contrib's algorithms too
  when installed), trained on the scenario's observation ``Dict`` (``--modalities``). Loading an
  SB3 zip unpickles it: evaluate only models you trust (docs/security.md);
* a crowdnav training run folder or checkpoint (its own modalities and scenario settings unless
  ``--scenario`` names another scenario); only its parameters are loaded.

The episodes are the test seeds ``test_seed_base``, ``test_seed_base + 1``, ... (default 0-19,
the protocol's held-out episodes; use e.g. 500 for final rankings): the same for every policy.
Each policy's rows land in ``OUT/evaluate/<name>/eval/`` (``test_episodes.csv`` and ``meta.json``,
the columns of every protocol run), so ``crowdnav leaderboard OUT`` ranks them together and with
any ``crowdnav benchmark`` results.
"""

from __future__ import annotations

import importlib
import re
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

EXPERIMENT = "evaluate"


class PolicyError(ValueError):
    """A POLICY that cannot be loaded, or whose spaces do not fit the scenario; one line."""


def _sb3_classes() -> list[Any]:
    from stable_baselines3 import A2C, DDPG, PPO, SAC, TD3

    classes = [SAC, TD3, DDPG, PPO, A2C]
    try:  # optional: sb3-contrib's algorithms load the same way
        import sb3_contrib

        classes += [getattr(sb3_contrib, name) for name in ("TQC", "CrossQ", "RecurrentPPO", "ARS", "TRPO") if hasattr(sb3_contrib, name)]
    except ImportError:
        pass
    return classes


def _load_sb3_zip(path: Path) -> Any:
    for algorithm in _sb3_classes():
        try:
            return algorithm.load(path, device="cpu")
        except Exception:  # noqa: BLE001 - the wrong class for this zip: try the next
            continue
    raise PolicyError(f"cannot load checkpoint {path}: not a model zip that Stable-Baselines3 (or sb3-contrib) can load")


def _check_spaces(label: str, model_space: Any, env_space: Any, modalities: Sequence[str] | None) -> None:
    def describe(space: Any) -> str:
        if hasattr(space, "spaces"):
            return "{" + ", ".join(f"{key}: {tuple(sub.shape)}" for key, sub in space.spaces.items()) + "}"
        return f"{type(space).__name__}{tuple(getattr(space, 'shape', ()) or ())}"

    if describe(model_space) != describe(env_space):
        raise PolicyError(f"{label} expects observations {describe(model_space)}, but the scenario with modalities "
                          f"{list(modalities or [])} gives {describe(env_space)}; pass the --modalities it was trained on")


def resolve_policy(spec: str, env_options: Mapping[str, Any]) -> tuple[str, str, Callable, bool, dict[str, Any]]:
    """(configuration name, label, act, privileged, env options) for a POLICY string.

    ``act`` maps stacked observations (or, with ``privileged``, a simulator) to actions.
    """
    options = dict(env_options)
    if spec.startswith("baseline:"):
        from crowdnav.evaluation.baselines import BASELINE_PREFIX, BASELINES, scripted_policy

        name = spec.removeprefix("baseline:")
        if name not in BASELINES:
            raise PolicyError(f"unknown baseline {name!r}; expected one of: {', '.join(f'baseline:{n}' for n in BASELINES)}")
        return f"{BASELINE_PREFIX}{name}", BASELINES[name], scripted_policy(name), True, options
    path = Path(spec)
    if path.suffix == ".zip" and path.is_file():
        model = _load_sb3_zip(path)
        from crowdnav.envs import CrowdNavEnv

        env = CrowdNavEnv(**options)
        _check_spaces(str(path), model.observation_space, env.observation_space, options.get("modalities"))
        env.close()
        return _safe(path.stem), path.stem, lambda batch: model.predict(batch, deterministic=True)[0], False, options
    if path.exists():
        from crowdnav.agents import load_policy

        if (path / "train" / "checkpoint").is_dir():  # a protocol run folder: its training run is in train/
            path = path / "train"

        try:
            policy = load_policy(path)
        except (FileNotFoundError, ValueError) as error:
            raise PolicyError(f"{path}: {error}") from None
        trained = dict(policy.env_options)
        if options.get("scenario") not in (None, trained["scenario"]):
            trained["scenario"] = options["scenario"]  # the same observations, in another scenario
            trained["overrides"] = dict(options.get("overrides", {}))
        return _safe(_run_name(Path(spec))), _run_name(Path(spec)), policy, False, trained
    if re.fullmatch(r"[A-Za-z_][\w.]*:[A-Za-z_]\w*", spec):
        module_name, function_name = spec.split(":")
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
    raise PolicyError(f"{spec}: expected a run folder or checkpoint, an SB3 model .zip, module:function, or baseline:NAME "
                      "(baseline:straight, baseline:social_force)")


def _run_name(path: Path) -> str:
    """``lidar_seed_2`` for EXPERIMENT/lidar/seed_2, ``sac`` for runs/sac/checkpoint."""
    parts = [part for part in path.resolve().parts if part not in ("checkpoint", "policy.json", "train")]
    return f"{parts[-2]}_{parts[-1]}" if parts[-1].startswith("seed_") and len(parts) > 1 else parts[-1]


def _safe(name: str) -> str:
    cleaned = re.sub(r"[^A-Za-z0-9_.-]", "_", name).lstrip("._-")[:100]
    return cleaned or "policy"


def evaluate_policy(spec: str, scenario: str, out: str | Path, *, modalities: Sequence[str] | None = None,
                    episodes: int = 20, test_seed_base: int = 0, overrides: Mapping[str, Any] | None = None,
                    name: str | None = None) -> Path:
    """Play POLICY on ``episodes`` fixed test episodes of ``scenario``; returns the run folder written."""
    import pandas as pd
    from crowdnav.evaluation.protocol import Protocol
    from crowdnav.evaluation.rollout import HeldOutEpisodes
    from crowdnav.evaluation.runner import OUTCOMES, RUN_COLUMNS, git_commit, package_versions
    from crowdnav.evaluation.storage import META_FILE, TEST_FILE, atomic_write_csv, atomic_write_json

    from crowdnav.paths import inside

    options: dict[str, Any] = {"scenario": scenario, "modalities": list(modalities) if modalities else None,
                               "overrides": dict(overrides or {})}
    options = {key: value for key, value in options.items() if value is not None}
    configuration, label, act, privileged, env_options = resolve_policy(spec, options)
    configuration = _safe(name) if name else configuration
    protocol = Protocol(train_episodes=1, eval_every=1, test_episodes=episodes, seeds=1, test_seed_base=test_seed_base, final_evaluations=1)
    started = time.perf_counter()
    held_out = HeldOutEpisodes(env_options, protocol.test_seeds)
    try:
        rows = held_out.run(act, privileged=privileged)
    except (ValueError, TypeError) as error:  # an action of the wrong shape or type, from the user's policy
        raise PolicyError(f"{spec}: {str(error).splitlines()[0]}") from None
    finally:
        held_out.close()
    frame = pd.DataFrame(rows)
    for position, (column, value) in enumerate(zip((*RUN_COLUMNS, "training_episodes", "evaluation"),
                                                   (EXPERIMENT, configuration, label, 0, 0, 0), strict=True)):
        frame.insert(position, column, value)
    folder = inside(out, f"{EXPERIMENT}/{configuration}/eval")
    atomic_write_csv(frame, folder / TEST_FILE)
    steps = int(frame["steps"].sum())
    meta = {
        "experiment": EXPERIMENT, "configuration": configuration, "label": label, "seed": 0, "status": "complete",
        "kind": "evaluated", "policy": spec, "env": env_options, "protocol": protocol.to_dict(), "versions": package_versions(),
        "git_commit": git_commit(), "wall_time_s": round(time.perf_counter() - started, 3),
        "env_steps": {"train": 0, "test": steps, "total": steps}, "training_episodes": 0, "test_episodes": len(frame),
        "resumed": False, "final": {outcome: round(float((frame["outcome"] == outcome).mean()), 6) for outcome in OUTCOMES},
    }
    atomic_write_json(folder / META_FILE, meta)
    return folder
