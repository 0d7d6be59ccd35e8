"""One run loop for every training run: :class:`RunLoop` does what all of them do around the learning itself.

Its strategies are the three ways crowdnav trains: crowdnav's episode loop around a registered algorithm's
``learn`` (:class:`crowdnav.agents.training.episode_loop.EpisodeLoop`), Stable-Baselines3's own loop with crowdnav's
callbacks (:class:`crowdnav.agents.sb3.session.TrainingSession`) and the shared robot PPO loop
(:class:`crowdnav.agents.marl.robots.RobotsRun`). The loop owns the run folder (:mod:`crowdnav.agents.runs.folder`):

* :func:`writing_run`: the run's torch threads and the folder's writer lock (a second writer is refused at once; a
  refusal leaves no folder behind);
* :meth:`RunLoop.restore`: a new run refuses a folder that holds a checkpoint; a resume first recovers the checkpoint
  a kill cut mid-swap, then reads what it continues from; ``config.yaml`` is written and ``episodes.csv`` prepared,
  except that a resume finding the budget spent rewrites nothing (a later extension must play what it would have);
* :meth:`RunLoop.run`: build, learn for the rest of the budget, the final checkpoint, the :class:`TrainResult`.

A strategy supplies what differs: what its checkpoint says (:meth:`~RunLoop.read_checkpoint`), the env and the learner,
new or resumed, with the episode counting that logs every episode and checkpoints on its schedule
(:meth:`~RunLoop.build`), learning until the budget (:meth:`~RunLoop.learn`), the final checkpoint
(:meth:`~RunLoop.save_final`) and what it holds open (:meth:`~RunLoop.close`). What a checkpoint holds is the
strategy's too; every one is written whole beside its folder and swapped in (:func:`crowdnav.files.swap_folder`).
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import torch
import yaml
from crowdnav.agents.runs.folder import checkpoint_dir, recover_checkpoint, writing
from crowdnav.agents.runs.result import TrainResult
from crowdnav.agents.sb3.callbacks import EpisodeRecord
from crowdnav.agents.training.checks import budget_spent, prepare_episode_log
from crowdnav.agents.training.config import ConfigError, TrainConfig, config_to_dict

from crowdnav.files import atomic_write_text


@contextmanager
def writing_run(config: TrainConfig) -> Iterator[None]:
    """The run's torch threads, and ``config.out``'s writer lock held while the body writes the run
    (:func:`crowdnav.agents.runs.folder.writing`)."""
    torch.set_num_threads(config.torch_threads)
    with writing(config.out):
        yield


@dataclass(frozen=True)
class Progress:
    """How far the checkpoint a resume continues from had got."""

    episodes: int
    timesteps: int
    """Env steps (robot steps in a shared robot run)."""


class Tally(Protocol):
    """A run's episodes so far: what its :class:`TrainResult` reports."""

    done: int
    """Episodes in all, the resumed ones included."""
    successes: int
    records: list[EpisodeRecord]
    """The episodes of this session."""


class RunLoop(ABC):
    """One run of ``config`` in ``config.out`` (``resume``: from its checkpoint); see the module docstring.

    ``on_checkpoint(episodes)`` is called after each checkpoint (:meth:`announce_checkpoint`).
    """

    caller_frames = 1
    """How far above :meth:`run` the code is that the run's warnings point at (1: the caller of ``run``)."""

    def __init__(self, config: TrainConfig, resume: bool, on_checkpoint: Callable[[int], None] | None = None):
        self.config = config
        self.resume = resume
        self.on_checkpoint = on_checkpoint
        self.out = Path(config.out)
        self.checkpoint = checkpoint_dir(self.out)
        self.progress: Progress | None = None
        """What the resume continues from (None: a new run)."""
        self.model: Any = None
        """The learner :meth:`build` makes (an SB3 model, or a registered algorithm's agent)."""
        self.built = False

    # ------------------------------------------------------------ what each strategy supplies

    @abstractmethod
    def read_checkpoint(self) -> Progress | None:
        """A resume: what ``checkpoint/`` continues from (refused in one line when it cannot continue the config's run)."""

    @abstractmethod
    def build(self) -> None:
        """The env and :attr:`model` (new, or the checkpoint's) and the episode counting (:attr:`tally`); sets :attr:`built`."""

    @property
    @abstractmethod
    def finished(self) -> bool:
        """Whether the budget (episodes, or steps with ``timesteps``) is spent."""

    @property
    @abstractmethod
    def timesteps(self) -> int:
        """Steps taken in all, the resumed ones included."""

    @property
    @abstractmethod
    def tally(self) -> Tally:
        """The episodes counted so far."""

    @abstractmethod
    def learn(self) -> None:
        """Learn for the rest of the budget, logging every episode and checkpointing on the strategy's schedule."""

    @abstractmethod
    def save_final(self) -> None:
        """The checkpoint at the end of the budget."""

    @abstractmethod
    def close(self) -> None:
        """Close what the run holds open (its envs, the episode log)."""

    # ------------------------------------------------------------ what every run does

    @property
    def first_episode(self) -> int:
        return self.progress.episodes if self.progress else 0

    @property
    def spent(self) -> bool:
        """Whether the resumed checkpoint has already spent the config's budget (the run plays nothing)."""
        return self.progress is not None and budget_spent(self.config, self.progress.episodes, self.progress.timesteps)

    def restore(self) -> None:
        """Read the checkpoint a resume continues from (refusing a new run in a folder that holds one), write ``config.yaml``,
        prepare ``episodes.csv``."""
        if self.resume:
            recover_checkpoint(self.out)  # a kill during a checkpoint swap leaves a complete copy beside it
            self.progress = self.read_checkpoint()
        elif self.checkpoint.exists():
            raise ConfigError(f"{self.out} already holds a run (checkpoint/); resume it with --resume or choose another --out")
        self.out.mkdir(parents=True, exist_ok=True)
        if not self.spent:  # a resume with nothing left to play changes nothing
            atomic_write_text(self.out / "config.yaml", yaml.safe_dump(config_to_dict(self.config), sort_keys=False))  # replaces a link
        self.prepare_log()

    def prepare_log(self) -> None:
        """``episodes.csv``: its header on disk before anything can be killed mid-episode, rows after the checkpoint set aside,
        what a kill had damaged repaired with a warning."""
        prepare_episode_log(self.out, self.first_episode, stacklevel=4 + self.caller_frames)

    def announce_checkpoint(self, episodes: int) -> None:
        """Call ``on_checkpoint`` after a checkpoint (the evaluation runner saves its timing there: a kill loses no recorded time)."""
        if self.on_checkpoint is not None:
            self.on_checkpoint(episodes)

    def run(self) -> TrainResult:
        """Restore and build (unless done already), learn for the rest of the budget, save the final checkpoint."""
        if not self.built:
            self.restore()
            self.build()
        started, start_steps = time.perf_counter(), self.timesteps
        if not self.finished:
            self.learn()
            self.save_final()
        seconds = time.perf_counter() - started
        self.close()
        tally, steps = self.tally, self.timesteps
        return TrainResult(out=self.out, checkpoint=self.checkpoint, episodes=tally.done, timesteps=steps, successes=tally.successes,
                           seconds=seconds, steps_per_second=(steps - start_steps) / seconds if seconds > 0 else 0.0,
                           records=tally.records, model=self.model)


@contextmanager
def torch_threads(count: int) -> Iterator[None]:
    """torch on ``count`` threads inside the block, the process's setting restored after it (a small network acts faster on
    one thread than contending for many, and one thread sums in the same order run after run)."""
    before = torch.get_num_threads()
    torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(before)
