"""What a training session reads and checks around its run (:mod:`crowdnav.agents.sb3.session`).

A resume's checkpoint (:func:`resume_info`: refused in one line when it cannot continue the
config's run), the run folder's episode log and snapshots, the files a config names, and the
resume errors' one-line form.
"""

from __future__ import annotations

import importlib.util
import warnings
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
from crowdnav.agents.runs.checkpoint import ENCODER_FILE, LEGACY_FILES, MODEL_FILE, find_checkpoint, read_policy_info
from crowdnav.agents.runs.episode_log import EpisodeLogError, prepare_log
from crowdnav.agents.runs.folder import episode_log, snapshot_folders
from crowdnav.agents.runs.resume_state import STATE_FILE, ResumeStateError
from crowdnav.agents.training.config import ConfigError, TrainConfig
from crowdnav.agents.training.seeding import EpisodeSeedCounter
from stable_baselines3.common.base_class import BaseAlgorithm

from crowdnav.errors import install_line


@dataclass(frozen=True)
class ResumeInfo:
    """What a checkpoint says a resume continues from (its ``policy.json``)."""

    episodes: int
    successes: int
    config: Mapping[str, Any] | None
    normalization: Any
    """The observation scales as JSON, or None (raw observations)."""
    next_episode: int | None
    """A batched run's first episode not yet started."""
    legacy: bool
    """Written by an older crowdnav, whose resume state is pickled (resumed only with ``trust_pickle``)."""
    timesteps: int = 0
    """The env steps the checkpoint's run had taken."""


def budget_spent(config: TrainConfig, episodes: int, timesteps: int) -> bool:
    """Whether a run of ``episodes`` episodes and ``timesteps`` env steps has spent ``config``'s budget (a resume plays nothing)."""
    return timesteps >= config.timesteps if config.timesteps is not None else episodes >= config.episodes


def resume_info(checkpoint: Path, config: TrainConfig, trust_pickle: bool = False) -> ResumeInfo:
    """The checkpoint in ``checkpoint`` (the run folder's ``checkpoint/``), or a one-line ConfigError if it cannot continue ``config``."""
    try:
        folder = find_checkpoint(checkpoint)
    except FileNotFoundError:
        raise ConfigError(f"cannot resume: {checkpoint} holds no checkpoint (start the run without --resume)") from None
    try:
        info = read_policy_info(folder)
    except ValueError as error:
        raise ConfigError(f"cannot resume: {error}{restart_hint(checkpoint.parent)}") from None
    if not (folder / MODEL_FILE).is_file():
        raise ConfigError(f"cannot resume: {folder / MODEL_FILE} is missing")
    legacy = not (folder / STATE_FILE).is_file()  # written before resume state was stored without pickle
    if legacy and not trust_pickle:
        pickles = [name for name in LEGACY_FILES if (folder / name).is_file()]
        raise ConfigError(f"cannot resume: {folder} was written by an older crowdnav, whose resume state is pickled "
                          f"({', '.join(pickles + [MODEL_FILE + ' data'])}), and unpickling can run code; resume with "
                          "--trust-pickle (train(..., trust_pickle=True)) only if you trust where it came from")
    trained_worlds = int((info.get("config") or {}).get("num_envs", 1))  # older checkpoints: one env
    if trained_worlds != config.num_envs:
        raise ConfigError(f"cannot resume: {folder} was trained with num_envs {trained_worlds}, the config asks for {config.num_envs}")
    if info["algo"] != config.algo or info["env"]["modalities"] != list(config.modalities):
        raise ConfigError(
            f"cannot resume: {folder} was trained with algo {info['algo']} on {info['env']['modalities']}, "
            f"the config asks for {config.algo} on {config.modalities}"
        )
    raw = "observation_normalization" not in info  # written before normalisation existed: raw observations
    normalization = info.get("observation_normalization")
    if not raw and (normalization is not None) != config.normalize_observations:
        raise ConfigError(
            f"cannot resume: {folder} was trained with normalize_observations: {str(normalization is not None).lower()}, "
            f"the config asks for {str(config.normalize_observations).lower()}"
        )
    return ResumeInfo(episodes=int(info["episodes"]), successes=int(info.get("successes", 0)), config=info.get("config"),
                      normalization=normalization, next_episode=info.get("next_episode"), legacy=legacy,
                      timesteps=int(info.get("timesteps", 0)))


def prepare_episode_log(out: Path, first_episode: int, stacklevel: int = 4) -> None:
    """Create or repair ``episodes.csv`` (:func:`crowdnav.agents.runs.episode_log.prepare_log`), saying what a kill had left damaged
    (warnings at ``stacklevel`` from here: 4 points at the caller of ``train``)."""
    try:
        repairs = prepare_log(episode_log(out), first_episode)
    except EpisodeLogError as error:
        raise ConfigError(str(error)) from None
    for note in repairs:
        warnings.warn(f"{out}: {note}", stacklevel=stacklevel)


def set_aside_snapshots_after(out: Path, point: int, unit: str) -> None:
    """Move snapshots newer than the checkpoint (a kill between snapshot and checkpoint) to ``snapshots_discarded/``.

    They come from a training history that the resume throws away; the resumed run saves its
    own snapshot at the same point, and the old one is kept for inspection, not evaluated.
    """
    for number, folder in snapshot_folders(out, unit).items():
        if number > point:
            target = out / "snapshots_discarded" / folder.name
            suffix = 1
            while target.exists():
                target, suffix = out / "snapshots_discarded" / f"{folder.name}.{suffix}", suffix + 1
            target.parent.mkdir(exist_ok=True)
            folder.rename(target)


@contextmanager
def resume_errors(hint: str = "") -> Iterator[None]:
    """A damaged or foreign resume file: the CLI's one-line ConfigError, ending with ``hint`` (how to go on)."""
    try:
        yield
    except ResumeStateError as error:
        raise ConfigError(f"cannot resume: {error}{hint}") from None
    except ConfigError as error:
        raise ConfigError(f"{error}{hint}") from None


def restart_hint(out: Path) -> str:
    """How to go on from a checkpoint that cannot be resumed (cut short, damaged, foreign)."""
    return f"; this checkpoint cannot be resumed: move {out} away (its snapshots still load as policies) and train again"


def next_episode(model: BaseAlgorithm) -> int:
    """A batched run's first episode not yet started: its worlds' episode counter (a wrapper such as an ActionLog forwards it)."""
    counter = getattr(model.get_env(), "episode_seeds", None)
    if not isinstance(counter, EpisodeSeedCounter):
        raise TypeError(f"a batched run's env counts its episodes with an EpisodeSeedCounter, got {counter!r}")
    return counter.next_episode


def scenario_max_steps(env: gym.Env) -> int:
    """The episode length limit of the scenario of a :func:`crowdnav.agents.sb3.factory.make_env` environment."""
    from crowdnav.envs import CrowdNavEnv

    core = env.unwrapped
    if not isinstance(core, CrowdNavEnv):
        raise TypeError(f"expected a CrowdNavEnv under the wrappers, got {type(core).__name__}")
    return int(core.scenario.max_steps)


def encoder_path(config: TrainConfig) -> Path:
    """The frozen encoder's weights file that a run copies into every checkpoint."""
    if config.encoder.weights is None:  # only frozen runs copy their encoder, and TrainConfig requires their weights
        raise ConfigError("encoder.weights: encoder mode 'frozen' needs pre-trained weights (crowdnav pretrain-encoder)")
    path = Path(config.encoder.weights)
    return path / ENCODER_FILE if path.is_dir() else path


def tensorboard_folder(config: TrainConfig, out: Path) -> str | None:
    """Where SB3 writes the run's TensorBoard logs (None without ``tensorboard: true``)."""
    if not config.tensorboard:
        return None
    if importlib.util.find_spec("tensorboard") is None:
        raise ConfigError(f"tensorboard: true needs the tensorboard package, which is not installed: {install_line('tensorboard')}")
    return str(out / "tensorboard")
