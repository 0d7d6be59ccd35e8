"""``train(config)``: one training run, counted in episodes, with checkpoints that can be resumed.

Output folder (``config.out``):

* ``config.yaml``: the resolved configuration;
* ``episodes.csv``: one row per training episode (index, seed, outcome, return, length, ...);
* ``checkpoint/``: the latest resumable checkpoint (see :mod:`crowdnav.agents.runs.checkpoint`), rewritten
  every ``checkpoint_every`` episodes and at the end;
* ``snapshots/episode_<N>/``: the policy after N episodes (no replay buffer), for evaluation
  along training; ``snapshots/steps_<N>/`` after N env steps with ``checkpoint_every_steps``;
* ``tensorboard/`` with ``tensorboard: true``.

``resume=True`` continues from ``checkpoint/``: the episode count, the episode seeds, the
model and (if saved) the replay buffer carry on; the budget is still ``config.episodes`` (or
``config.timesteps``) in all. Every run, whatever its algorithm and loop, collects from ``num_envs`` worlds
of the one vector stack (:func:`crowdnav.agents.sb3.factory.make_vec_env` over the native vector env), one world
included: ``num_envs`` is a size, not a fork. An SB3 resume needs the same number.

Every run goes through the one run loop (:class:`crowdnav.agents.training.run_loop.RunLoop`: the run folder, its
writer lock, the resume decision, the final checkpoint, the result); what learns inside it is read from the
algorithm's registered builder, for every algorithm alike (:func:`trainer_of`): crowdnav's episode loop around the
agent's ``learn`` (:func:`crowdnav.agents.training.episode_loop.train_registered`), or the builder's own
(:class:`crowdnav.agents.training.algorithm_protocol.RunTrainer`): the Stable-Baselines3 builder's
:class:`crowdnav.agents.sb3.session.TrainingSession`. ``agents: robots`` runs the shared robot PPO loop
(:func:`crowdnav.agents.marl.robots.train_robots`).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from functools import partial
from pathlib import Path
from typing import Any

from crowdnav.agents.runs.folder import snapshot_dir
from crowdnav.agents.runs.result import TrainResult as TrainResult
from crowdnav.agents.training.config import ConfigError, TrainConfig, config_from_mapping, load_config
from crowdnav.agents.training.run_loop import writing_run


def train(config: TrainConfig | Mapping[str, Any] | str | Path, *, resume: bool = False,
          on_checkpoint: Callable[[int], None] | None = None, trust_pickle: bool = False) -> TrainResult:
    """Train an agent as ``config`` says (a TrainConfig, a mapping, or a YAML file path).

    ``on_checkpoint(episodes)`` is called after each checkpoint is saved (the evaluation runner
    saves its timing there, so a kill loses no recorded time). A resume reads no pickle
    (:mod:`crowdnav.agents.runs.resume_state`); a checkpoint of an older crowdnav, whose state is pickled, is
    refused unless ``trust_pickle`` (its worlds mid-episode are then not continued).
    """
    if isinstance(config, (str, Path)):
        config = load_config(config)
    elif isinstance(config, Mapping):
        config = config_from_mapping(config)
    # a TrainConfig was checked when it was built: not again here (one validation per run)
    if config.agents == "robots":  # every robot of a multi-robot scenario, one shared policy: the registry's robots trainer
        return robots_trainer_of(config.algo)(config, resume=resume, on_checkpoint=on_checkpoint)
    trainer = trainer_of(config, trust_pickle)  # before the run folder is touched: refusals leave nothing behind
    with writing_run(config):  # one process writes a run at a time
        return trainer(config, resume, on_checkpoint)


def robots_trainer_of(algo: str) -> Callable[..., TrainResult]:
    """The ``robots_trainer`` of the registered algorithm ``algo`` (``agents: robots``), imported if its spec names it."""
    from crowdnav.agents.training.algorithm_protocol import import_reference

    from crowdnav.registry import algorithm_spec

    trainer = algorithm_spec(algo).robots_trainer
    if trainer is None:  # a config validated before the registry changed
        raise ConfigError(f"algo: {algo!r} has no robots_trainer in its registry entry; agents: robots cannot train it")
    found: Callable[..., TrainResult] = import_reference(trainer) if isinstance(trainer, str) else trainer
    return found


Trainer = Callable[[TrainConfig, bool, "Callable[[int], None] | None"], TrainResult]
"""``trainer(config, resume, on_checkpoint)``: one run, as :func:`train` calls it."""


def trainer_of(config: TrainConfig, trust_pickle: bool = False) -> Trainer:
    """The loop that trains ``config.algo``, read from its registered builder: the one place that tells them apart.

    A :class:`~crowdnav.agents.training.algorithm_protocol.RunTrainer` builder (the Stable-Baselines3 one: a TrainingSession,
    SB3's loop with an exact mid-episode resume) trains the run itself; any other builder's agent learns in
    crowdnav's episode loop (:func:`crowdnav.agents.training.episode_loop.train_registered`), after the settings
    that loop does not take are refused (ConfigError, one line).
    """
    from crowdnav.agents.training.algorithm_protocol import RunTrainer, builder_of

    try:
        builder = builder_of(config.algo)
    except ValueError as error:  # e.g. a spec without a builder, or one whose module does not import
        raise ConfigError(f"algo: {error}") from None
    if isinstance(builder, RunTrainer):
        return partial(_own_loop, builder, trust_pickle=trust_pickle)
    from crowdnav.agents.training.episode_loop import check_supported, train_registered

    check_supported(config)
    return train_registered


def _own_loop(builder: Any, config: TrainConfig, resume: bool, on_checkpoint: Callable[[int], None] | None,
              trust_pickle: bool = False) -> TrainResult:
    result: TrainResult = builder.train_run(config, resume, on_checkpoint, trust_pickle)
    return result


def snapshot_folder(out: Path, point: int, unit: str = "episodes") -> Path:
    """Where a run saves its policy after ``point`` training episodes (or env steps, ``unit="steps"``)."""
    return snapshot_dir(out, point, unit)


def describe_run(result: TrainResult) -> str:
    """One-paragraph summary for the command line."""
    return json.dumps({
        "out": str(result.out), "episodes": result.episodes, "timesteps": result.timesteps,
        "success_rate": round(result.success_rate, 3), "steps_per_second": round(result.steps_per_second, 1),
        "seconds": round(result.seconds, 1),
    })

