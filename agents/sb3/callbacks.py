"""The training callback: counts episodes (training is measured in episodes, as in the paper),
stops after the requested number, logs every episode, shows progress, and triggers checkpoints.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from crowdnav.agents.runs.episode_log import EpisodeLogWriter, prepare_log
from crowdnav.agents.runs.resume_point import ResumePoint
from stable_baselines3.common.callbacks import BaseCallback


@dataclass
class EpisodeRecord:
    """One finished training episode (a row of ``episodes.csv``)."""

    episode: int
    """0-based index over the whole run (continues after a resume)."""
    seed: int
    outcome: str
    """One of :data:`crowdnav.sim.simulator.OUTCOMES`: success, collision, out_of_bounds or truncated."""
    reward: float
    """Undiscounted return."""
    length: int
    timesteps: int
    """Model timesteps after this episode."""
    seconds: float
    """Wall time since this (possibly resumed) session started."""

    def csv(self) -> str:
        return ",".join(str(value) for value in asdict(self).values())


class EpisodeCallback(BaseCallback):
    """Stop after ``episodes`` episodes in all; ``first_episode`` were done before (resume).

    Checkpoints: every ``checkpoint_every`` episodes ``snapshot(episodes_done)`` is called at once
    (the policy does not change within a rollout, so it is the policy after exactly that many
    episodes, however long the rollout: PPO's 2,048 steps span several episodes), and
    ``save(episodes_done)`` at the end of the current rollout (for off-policy algorithms right
    after the step's transition enters the replay buffer), so the saved buffer and episode count agree.

    With ``timesteps`` (a budget in env steps over all worlds) it stops at the first step that
    reaches the budget; with ``checkpoint_every_steps`` too, ``snapshot(point)`` and ``save`` follow
    every multiple of it instead of the episode count.
    """

    def __init__(self, episodes: int, first_episode: int, seed_of: Callable[[int], int], *,
                 checkpoint_every: int, save: Callable[[int], None] | None = None,
                 snapshot: Callable[[int], None] | None = None, on_start: Callable[[], None] | None = None,
                 log_file: str | Path | None = None, progress: bool = False, successes_before: int = 0,
                 resume_point: ResumePoint | None = None, timesteps: int | None = None, checkpoint_every_steps: int | None = None):
        super().__init__()
        self.episodes = episodes
        self.timesteps = timesteps
        """A budget in env steps (over all worlds) instead of ``episodes``; ``checkpoint_every_steps``, if given, sets the points."""
        self.checkpoint_every_steps = checkpoint_every_steps
        self.point = 0
        """With a step budget: the last evaluation point (env steps) reached."""
        self.done = first_episode
        self.successes = successes_before
        self.seed_of = seed_of
        self.checkpoint_every = checkpoint_every
        self.save = save
        self.snapshot = snapshot
        self.on_start = on_start
        self.resume_point = resume_point
        self.records: list[EpisodeRecord] = []
        self._log_path = Path(log_file) if log_file is not None else None
        self._log: EpisodeLogWriter | None = None
        self._progress = progress
        self._bar = None
        self._save_due = False
        self._start_time = 0.0
        self._start_steps = 0

    @property
    def success_rate(self) -> float:
        return self.successes / self.done if self.done else 0.0

    def _on_training_start(self) -> None:
        if self.on_start is not None:  # a resumed run's catch-up, once SB3 has set up learning
            self.on_start()
        self._start_time = time.perf_counter()
        self._start_steps = self.model.num_timesteps
        if self._log_path is not None:  # training prepared it already; a callback used on its own prepares it here
            prepare_log(self._log_path, self.done)
            self._log = EpisodeLogWriter(self._log_path)
        if self._progress:
            from tqdm import tqdm

            if self.timesteps is None:
                self._bar = tqdm(total=self.episodes, initial=self.done, unit="ep", desc=f"train {type(self.model).__name__}",
                                 dynamic_ncols=True)
            else:  # a budget in env steps: the bar counts them
                self._bar = tqdm(total=self.timesteps, initial=min(self.model.num_timesteps, self.timesteps), unit="step",
                                 desc=f"train {type(self.model).__name__}", dynamic_ncols=True)

    def _on_step(self) -> bool:
        for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
            # several worlds can end in the step that reaches an episode budget: the run is exactly `episodes` long
            if done and (self.timesteps is not None or self.done < self.episodes):
                self._record(info)
        if self.timesteps is None:
            return self.done < self.episodes
        if self._bar is not None:
            self._bar.update(min(self.model.num_timesteps, self.timesteps) - self._bar.n)
        every = self.checkpoint_every_steps
        if every is not None and self.model.num_timesteps >= self.point + every:
            # the policy after the first step of all worlds that reaches the point (the policy is fixed within a step)
            self.point = self.model.num_timesteps // every * every
            if self.snapshot is not None:
                self.snapshot(self.point)
            self._save_due = self.save is not None
        return self.model.num_timesteps < self.timesteps

    @property
    def finished(self) -> bool:
        """Whether the budget (episodes, or env steps) is spent."""
        return self.done >= self.episodes if self.timesteps is None else self.model.num_timesteps >= self.timesteps

    def _record(self, info: dict[str, Any]) -> None:
        if self.resume_point is not None:
            self.resume_point.mark()
        episode = info.get("episode", {})
        # batched training: the finished world's own episode seed (episodes end in another order than they start)
        seed = info["episode_seed"] if "episode_seed" in info else self.seed_of(self.done)
        record = EpisodeRecord(
            episode=self.done, seed=seed, outcome=info.get("outcome", "truncated"),
            reward=round(float(episode.get("r", float("nan"))), 4), length=int(episode.get("l", 0)),
            timesteps=self.model.num_timesteps, seconds=round(time.perf_counter() - self._start_time, 3),
        )
        self.records.append(record)
        self.done += 1
        self.successes += record.outcome == "success"
        if self._log is not None:
            self._log.write(record.csv())
        self.logger.record("episode/success_rate", self.success_rate)
        self.logger.record("episode/return", record.reward)
        self.logger.record("episode/length", record.length)
        if self._bar is not None:
            if self.timesteps is None:
                self._bar.update(1)
            self._bar.set_postfix(success=f"{self.success_rate:.0%}", steps_per_s=f"{self.steps_per_second:.0f}", refresh=False)
        # a step budget without checkpoint_every_steps still checkpoints every checkpoint_every episodes (resumable)
        if self.checkpoint_every_steps is None and self.done % self.checkpoint_every == 0:
            if self.snapshot is not None:
                self.snapshot(self.done)
            self._save_due = self.save is not None

    @property
    def steps_per_second(self) -> float:
        elapsed = time.perf_counter() - self._start_time
        return (self.model.num_timesteps - self._start_steps) / elapsed if elapsed > 0 else 0.0

    def _on_rollout_start(self) -> None:
        if self.resume_point is not None:
            self.resume_point.rollout_started()

    def _on_rollout_end(self) -> None:
        if self.resume_point is not None:
            self.resume_point.rollout_ended()
        if self._save_due and self.save is not None:
            self._save_due = False
            if self._log is not None:  # the checkpoint about to claim these episodes: their rows on disk first
                self._log.sync()
            self.save(self.done)

    def _on_training_end(self) -> None:
        if self._log is not None:
            self._log.close()
            self._log = None
        if self._bar is not None:
            self._bar.close()
            self._bar = None
