"""Where a resumable checkpoint puts an off-policy run: the end of its last episode, exactly.

A checkpoint is written when SB3's rollout ends. With ``train_freq`` above one step, that is up
to ``train_freq - 1`` steps into the next episode, and a resumed run restarts that episode: it
would collect those steps a second time, with other random numbers, and train at other moments.
So the checkpoint is rewound to the episode's end instead:

* when an episode ends, :meth:`ResumePoint.mark` notes the step count, the replay buffer's
  write position (after the episode's last transition) and every random stream;
* the checkpoint saves the model with that step count, the buffer with that position (the
  slots after it hold the next episode's first steps, which nothing reads before they are
  written again with the same data) and those random streams, plus how many steps the
  interrupted rollout had left after the episode end;
* a resumed run collects exactly those steps as its first rollout, then trains as the
  uninterrupted run did (:meth:`ResumePoint.continue_run`).

With the default ``train_freq`` of one step, the episode end is the rollout end and the first
thing a resumed run does is the gradient update the checkpoint preceded.

On-policy algorithms (A2C, PPO) cannot be rewound: their rollout spans episodes and is trained
on as a whole. Their checkpoint (written when the rollout is complete, before SB3 trains on it)
keeps the rollout buffer, the environments mid-episode, the last observation and a recurrent
policy's LSTM states (:meth:`ResumePoint.rollout_state`, stored as arrays by :mod:`crowdnav.agents.runs.resume_worlds`: each world
as its episode's seed and the actions taken since); a resumed run puts them back and takes
that update first.

Batched training (``num_envs > 1``) cannot be rewound either, for any algorithm: when one world's
episode ends the others are mid-episode. Its checkpoints (written at a rollout's end, before the
update that follows it) keep the vector env with every world mid-episode and the last
observation, as the on-policy ones do, plus the replay buffer off-policy; a resumed run puts
them back and takes the pending update first. The final checkpoint is taken inside the step that
spent the budget (SB3 stops before storing it), so it keeps no worlds: a resume with a larger
budget starts new episodes, numbered after every episode already started, and the abandoned
ones end in the replay buffer (:func:`end_open_episodes`).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from crowdnav.agents.runs.resume_state import rng_state
from crowdnav.agents.sb3.kinds import off_policy, on_policy, train_freq
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.type_aliases import TrainFreq, TrainFrequencyUnit

STEPS_AFTER_KEY = "steps_after_episode_end"
"""Key of the RNG file holding how many steps the interrupted rollout had left after the episode end."""


@dataclass
class _EpisodeEnd:
    timesteps: int
    buffer_position: tuple[int, bool] | None
    """The replay buffer's (pos, full) when the episode ended, before its last transition was stored."""
    rng: dict[str, Any]


class ResumePoint:
    """The last episode end of an off-policy run, and how a resumed run continues from it."""

    def __init__(self, model: BaseAlgorithm, off_policy: bool, batched: bool = False):
        self.model = model
        self.off_policy = off_policy
        self.batched = batched
        self._end: _EpisodeEnd | None = None
        self._restore: tuple[TrainFreq, int] | None = None
        """A resumed run's configured (train_freq, gradient_steps) while its first, shorter rollout runs."""
        self._pending_rollout = False
        """An on-policy resume whose saved rollout still waits for its update."""

    def mark(self) -> None:
        """Called when an episode ends, before SB3 stores its last transition (callbacks run first)."""
        model = self.model
        if not self.off_policy or self.batched:
            return
        buffer = getattr(model, "replay_buffer", None)
        position = (buffer.pos, buffer.full) if buffer is not None else None
        self._end = _EpisodeEnd(model.num_timesteps, position, rng_state(model))

    @contextmanager
    def rewound(self) -> Iterator[dict[str, Any] | None]:
        """The model and buffer as they were at the last episode end (restored afterwards); yields the RNG state to save."""
        end, model = self._end, self.model
        if end is None:
            yield None
            return
        buffer = getattr(model, "replay_buffer", None)
        now = (model.num_timesteps, (buffer.pos, buffer.full) if buffer is not None else None)
        model.num_timesteps = end.timesteps
        if buffer is not None and end.buffer_position is not None:
            buffer.pos, buffer.full = _after_episode_end(buffer, end.buffer_position)
        try:
            yield {**end.rng, STEPS_AFTER_KEY: now[0] - end.timesteps}
        finally:
            model.num_timesteps = now[0]
            if buffer is not None and now[1] is not None:
                buffer.pos, buffer.full = now[1]

    def rollout_state(self) -> dict[str, Any] | None:
        """An on-policy run's collected rollout, environments and last observation (None off-policy or mid-rollout)."""
        model = self.model
        if self.off_policy and self.batched:  # the worlds mid-episode; the replay buffer is saved on its own
            return {"env": model.get_env(), "last_obs": model._last_obs, "last_original_obs": model._last_original_obs,
                    "last_episode_starts": model._last_episode_starts, "episode_num": model._episode_num}
        buffer = getattr(model, "rollout_buffer", None)
        if self.off_policy or buffer is None or not buffer.full:
            return None
        # a recurrent policy's memory after the rollout's last step: where the next rollout starts from
        return {"env": model.get_env(), "rollout_buffer": buffer, "last_obs": model._last_obs,
                "last_episode_starts": model._last_episode_starts, "lstm_states": getattr(model, "_last_lstm_states", None)}

    def restore_rollout(self, state: dict[str, Any]) -> None:
        """Take up what :func:`crowdnav.agents.runs.resume_worlds.load_rollout` read back (after loading the model, before ``learn``).

        The worlds and the rollout buffer are already in place; this sets the last observation
        and marks the update the checkpoint preceded as pending.
        """
        model = self.model
        model._last_obs, model._last_episode_starts = state["last_obs"], state["last_episode_starts"]
        if state.get("lstm_states") is not None:
            recurrent: Any = model  # sb3-contrib's RecurrentPPO: an attribute SB3's BaseAlgorithm does not declare
            recurrent._last_lstm_states = state["lstm_states"]
        if "rollout_buffer" not in state:  # batched off-policy
            model._last_original_obs, model._episode_num = state["last_original_obs"], state["episode_num"]
        self._pending_rollout = True

    def continue_run(self, steps_after: int) -> None:
        """Start of a resumed run: take the update the checkpoint preceded, or first finish the interrupted rollout."""
        if not self.off_policy:
            if self._pending_rollout:  # as SB3's loop does after a rollout
                collector = on_policy(self.model)
                collector._update_current_progress_remaining(collector.num_timesteps, collector._total_timesteps)
                collector.train()
                self._pending_rollout = False
            return
        model = off_policy(self.model)
        if self.batched:
            if self._pending_rollout and model.num_timesteps > model.learning_starts:  # as SB3's loop does after a rollout
                # gradient_steps -1: as many as the rollout's env steps (checkpoints end rollouts of train_freq steps of every world)
                steps = model.gradient_steps if model.gradient_steps >= 0 else train_freq(model).frequency * model.n_envs
                model._update_current_progress_remaining(model.num_timesteps, model._total_timesteps)
                if steps > 0:
                    model.train(batch_size=model.batch_size, gradient_steps=steps)
            self._pending_rollout = False
            return
        if steps_after <= 0:
            if model.num_timesteps > model.learning_starts:
                steps = model.gradient_steps if model.gradient_steps >= 0 else train_freq(model).frequency
                if steps > 0:
                    model.train(batch_size=model.batch_size, gradient_steps=steps)
            return
        # the first rollout is the rest of the interrupted one; then the usual rollouts
        self._restore = (train_freq(model), model.gradient_steps)
        if model.gradient_steps < 0:  # "as many updates as steps": the whole interrupted rollout's
            model.gradient_steps = train_freq(model).frequency
        # SB3 types train_freq as the constructor's argument; after set-up it holds a TrainFreq, as here
        model.train_freq = TrainFreq(steps_after, TrainFrequencyUnit.STEP)  # type: ignore[assignment]

    def rollout_ended(self) -> None:
        """End of the first rollout of a resumed run: the next rollouts have the configured length."""
        if self._restore is not None:
            off_policy(self.model).train_freq = self._restore[0]  # type: ignore[assignment]  # a TrainFreq, as SB3 stores it

    def rollout_started(self) -> None:
        """Start of the second rollout: the first one's update used the interrupted rollout's gradient steps."""
        if self._restore is not None:
            model = off_policy(self.model)
            if train_freq(model) is self._restore[0]:
                model.gradient_steps = self._restore[1]
                self._restore = None


def _after_episode_end(buffer: Any, marked: tuple[int, bool]) -> tuple[int, bool]:
    """The buffer's (pos, full) with the ended episode's last transition in it, and nothing after.

    SB3 stores that transition right after the callback marked the episode's end, unless the
    callback ended training there (the run's last episode): then the buffer is still as marked.
    """
    if (buffer.pos, buffer.full) == marked:
        return marked
    after = marked[0] + 1
    return after % buffer.buffer_size, marked[1] or after == buffer.buffer_size


def end_open_episodes(buffer: Any) -> None:
    """Mark the newest transition of every world still mid-episode as a time-limit end (bootstrapped, not terminal).

    A batched run resumed without its worlds (its final checkpoint, taken inside a step) starts
    new episodes: without the mark, n-step returns would run from the abandoned episodes into them.
    """
    if buffer is None or not (buffer.pos or buffer.full) or not getattr(buffer, "handle_timeout_termination", False):
        return
    last = (buffer.pos - 1) % buffer.buffer_size
    open_ = buffer.dones[last] == 0
    buffer.timeouts[last, open_] = 1.0
    buffer.dones[last, open_] = 1.0
