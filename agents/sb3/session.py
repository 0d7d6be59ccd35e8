"""One Stable-Baselines3 training run as a session: ``restore``, ``build``, ``run``, with ``save`` between.

:func:`crowdnav.agents.training.run.train` runs ``TrainingSession(config, resume, ...).run()`` for the algorithms whose
registered builder is the Stable-Baselines3 one (:meth:`crowdnav.agents.sb3.algorithm.SB3SessionBuilder.train_run`).
The session is a strategy of the one run loop (:class:`crowdnav.agents.training.run_loop.RunLoop`: the run folder,
the resume decision, the final checkpoint and the result); what it supplies:

* :meth:`TrainingSession.read_checkpoint`: on a resume, what the checkpoint continues from (refused in one line
  when it cannot be), called by :meth:`~crowdnav.agents.training.run_loop.RunLoop.restore`;
* :meth:`TrainingSession.build`: the environment the model collects from, the model (new, or the
  checkpoint's with its replay buffer, worlds mid-episode and random streams) and the episode
  callback, which calls :meth:`TrainingSession.save` and :meth:`TrainingSession.save_snapshot`;
* :meth:`TrainingSession.learn`: SB3's ``learn`` for the rest of the budget (:meth:`TrainingSession.budget`).

Every piece of state is an attribute set by the step that makes it; nothing is a closure.
"""

from __future__ import annotations

import shutil
import warnings
from collections.abc import Callable
from functools import partial
from typing import Any

from crowdnav.agents.runs.checkpoint import ENCODER_FILE, load_model, restore_pickled_rng_state, resume_model, save_checkpoint
from crowdnav.agents.runs.folder import REPLAY_FILE, RNG_FILE, episode_log, snapshot_dir
from crowdnav.agents.runs.resume_point import STEPS_AFTER_KEY, ResumePoint, end_open_episodes
from crowdnav.agents.runs.resume_state import REPLAY_ARRAYS, ROLLOUT_ARRAYS, STATE_FILE, load_replay_buffer, restore_training_state
from crowdnav.agents.sb3.callbacks import EpisodeCallback
from crowdnav.agents.sb3.factory import (
    env_options,
    hyperparameters,
    load_leog_weights,
    make_model,
    make_vec_env,
    observation_normalization,
    precomputes_leog,
)
from crowdnav.agents.sb3.kinds import off_policy, replay_buffer
from crowdnav.agents.training.checks import (
    ResumeInfo,
    encoder_path,
    next_episode,
    restart_hint,
    resume_errors,
    resume_info,
    set_aside_snapshots_after,
    tensorboard_folder,
)
from crowdnav.agents.training.config import TrainConfig, config_to_dict
from crowdnav.agents.training.run_loop import Progress, RunLoop
from crowdnav.agents.training.seeding import train_seed
from crowdnav.agents.training.wrappers import scales_from_json, scales_to_json

from crowdnav.registry import algorithm_spec


class TrainingSession(RunLoop):
    """One SB3 run of ``config`` in ``config.out`` (``resume``: from its checkpoint); see the module docstring."""

    def __init__(self, config: TrainConfig, resume: bool, on_checkpoint: Callable[[int], None] | None = None,
                 trust_pickle: bool = False):
        super().__init__(config, resume, on_checkpoint)
        self.trust_pickle = trust_pickle
        self.batched = config.num_envs > 1
        """Several worlds: their episodes end out of order, so checkpoints keep every world mid-episode (one world:
        off-policy checkpoints are rewound to its last episode end). Every world count collects from the same stack, the
        native vector env (:func:`make_vec_env`, one world held as one env inside); a checkpoint stores its worlds' states."""
        self.off_policy = algorithm_spec(config.algo).off_policy
        self.unit = "steps" if config.checkpoint_every_steps is not None else "episodes"  # what snapshots and checkpoints count
        self.state: ResumeInfo | None = None
        self.exact = False
        """A resume that continues the interrupted run bit for bit (rewound to an episode end, or its worlds restored)."""

    # ---------------------------------------------------------------- restore

    def read_checkpoint(self) -> Progress:
        """The checkpoint a resume continues from, refused in one line when it cannot continue this run."""
        self.state = resume_info(self.checkpoint, self.config, self.trust_pickle)
        if self.state.normalization is None and self.config.normalize_observations:
            # a checkpoint from before observation normalisation: its model was trained on raw observations
            warnings.warn(f"{self.checkpoint} predates observation normalisation; resuming on raw observations "
                          "(normalize_observations: false)", stacklevel=3 + self.caller_frames)
            self.config = self.config.model_copy(update={"normalize_observations": False})
        return Progress(self.state.episodes, self.state.timesteps)

    # ------------------------------------------------------------------ build

    def build(self) -> None:
        """The environment, the model (new or resumed), its resume point and the episode callback."""
        config, state = self.config, self.state
        encoder, saved_encoder = load_leog_weights(config)
        precompute = precomputes_leog(config)
        self._build_env(encoder if precompute else None)
        tensorboard_log = tensorboard_folder(config, self.out)
        if state and state.legacy:  # trust_pickle: an older crowdnav's pickles (SB3's full load included)
            self.model = load_model(self.checkpoint, env=self.collecting, device=config.device)
            if tensorboard_log is not None:
                self.model.tensorboard_log = tensorboard_log
        elif state:  # tensors, JSON and arrays only
            with resume_errors(restart_hint(self.out)):
                self.model = resume_model(self.checkpoint, config, self.collecting, saved_encoder, tensorboard_log)
        else:
            self.model = make_model(config, self.collecting, saved_encoder, tensorboard_log)
            from crowdnav.agents.imitation.demonstrations import warm_start

            warm_start(self.model, config)  # demonstrations (off by default); a resumed run carries them in its weights and buffer
        self.resume_point = ResumePoint(self.model, off_policy=self.off_policy, batched=self.batched)
        self._steps_after: int | None = self._restore_progress() if state else None
        # copied into every checkpoint, so a checkpoint stands alone
        self.encoder_copy = self.out / ENCODER_FILE if precompute else None
        if self.encoder_copy is not None and not self.resume:
            shutil.copyfile(encoder_path(config), self.encoder_copy)
        self.callback = EpisodeCallback(
            config.episodes, self.first_episode, partial(train_seed, config.seed),
            checkpoint_every=config.checkpoint_every, save=self.save, snapshot=self.save_snapshot,
            on_start=self._continue_run if self._steps_after is not None else None, log_file=episode_log(self.out),
            progress=config.progress, successes_before=state.successes if state else 0, resume_point=self.resume_point,
            timesteps=config.timesteps, checkpoint_every_steps=config.checkpoint_every_steps,
        )
        self.callback.model = self.model  # the budget check reads its step count before learn() binds it
        every = config.checkpoint_every_steps
        if self.unit == "steps":
            self.callback.point = self.model.num_timesteps // every * every if state and every else 0
            set_aside_snapshots_after(self.out, self.model.num_timesteps if state else 0, self.unit)
        else:
            set_aside_snapshots_after(self.out, self.first_episode, self.unit)
            if state and not snapshot_dir(self.out, state.episodes, "episodes").is_dir():
                self.save_snapshot(state.episodes)  # a run checkpointed by an older crowdnav, killed before its snapshot
        self.built = True

    def _build_env(self, leog: Any) -> None:
        """``env`` (what the observation scales are read from) and ``collecting`` (what the model steps)."""
        config, state = self.config, self.state
        # batched: episodes end in another order than they start, so the first one not yet started can be past the count
        # (only used when the checkpoint's own vector env is not restored: its counter goes on)
        first_started = (state.next_episode or state.episodes) if state and self.batched else self.first_episode
        saved_scales = scales_from_json(state.normalization) if state and state.normalization is not None else None
        # on-policy and batched checkpoints store the collecting env's worlds mid-episode, as their states
        # (crowdnav.agents.runs.resume_worlds): nothing records the steps (format 1's ActionLog did)
        self.env = make_vec_env(config, leog, first_started, saved_scales)
        self.collecting = self.env
        self.max_steps = self.env.env.scenario.max_steps
        self.scales = observation_normalization(self.env)

    def _restore_progress(self) -> int | None:
        """A resume: the replay buffer, the worlds mid-episode and the random streams; the steps left after the episode end."""
        assert self.state is not None
        model, checkpoint, legacy = self.model, self.checkpoint, self.state.legacy
        saved_streams = None
        if legacy:
            if self.off_policy and (checkpoint / REPLAY_FILE).is_file():
                off_policy(model).load_replay_buffer(checkpoint / REPLAY_FILE)
            saved_streams = restore_pickled_rng_state(model, checkpoint / RNG_FILE)
        elif self.off_policy and (checkpoint / REPLAY_ARRAYS).is_file():
            with resume_errors(f"; remove {checkpoint / REPLAY_ARRAYS} to resume with an empty replay buffer"):
                load_replay_buffer(replay_buffer(model), checkpoint / REPLAY_ARRAYS)
        rewinds = self.off_policy and not self.batched
        # the resumed run is the uninterrupted one: single-env off-policy checkpoints are rewound to an episode end,
        # the others carry their worlds mid-episode (without them, e.g. an older crowdnav's: a close resume)
        worlds = not legacy and not rewinds and (checkpoint / ROLLOUT_ARRAYS).is_file()
        if worlds:
            from crowdnav.agents.runs.resume_worlds import load_rollout

            with resume_errors(f"; remove {checkpoint / ROLLOUT_ARRAYS} to resume with new episodes in every world"):
                self.resume_point.restore_rollout(load_rollout(checkpoint / ROLLOUT_ARRAYS, model))
        elif self.batched and self.off_policy:
            end_open_episodes(getattr(model, "replay_buffer", None))  # the worlds start new episodes
        if not legacy:  # building the model re-seeded every stream: continue the saved ones (last: nothing draws after)
            with resume_errors(restart_hint(self.out)):
                saved_streams = restore_training_state(model, checkpoint / STATE_FILE)
        self.exact = saved_streams is not None and (rewinds or worlds)
        return None if saved_streams is None else int(saved_streams.get(STEPS_AFTER_KEY, 0))

    def _continue_run(self) -> None:
        """The callback's ``on_start`` (once SB3's logger exists): the resumed run's catch-up."""
        self.resume_point.continue_run(self._steps_after or 0)

    # ------------------------------------------------------------------- save

    def info(self, episodes: int) -> dict[str, Any]:
        """The checkpoint's ``policy.json``: what the run is and how far it got."""
        config, model = self.config, self.model
        started = {"next_episode": next_episode(model)} if self.batched else {}
        return {"algo": config.algo, "env": env_options(config),
                "observation_normalization": None if self.scales is None else scales_to_json(self.scales),
                "episodes": episodes, "timesteps": model.num_timesteps, **started,
                "successes": self.callback.successes, "hyperparameters": hyperparameters(config), "config": config_to_dict(config)}

    def save_snapshot(self, point: int) -> None:
        """The policy after ``point`` episodes (or env steps), without the replay buffer."""
        save_checkpoint(self.model, snapshot_dir(self.out, point, self.unit), self.info(self.callback.done),
                        encoder_file=self.encoder_copy)

    def save(self, episodes: int, final: bool = False) -> None:
        """The resumable checkpoint after ``episodes`` episodes; ``final``: the one at the end of the budget."""
        # The snapshot first: once the checkpoint says N episodes, snapshot N exists, so a kill
        # between the two writes cannot lose an evaluation point. (The callback usually took it
        # already, when episode N ended; a rollout can run past it before the checkpoint.)
        point = episodes if self.unit == "episodes" else self.callback.point
        if point and not snapshot_dir(self.out, point, self.unit).is_dir():
            self.save_snapshot(point)
        # a batched run ends inside a step (SB3 stops before it stores the step's transitions and observations):
        # its worlds cannot be continued, a resume with a larger budget starts new episodes (next_episode on)
        rollout = None if final and self.batched else self.resume_point.rollout_state()
        with self.resume_point.rewound() as streams:  # the checkpoint is the last episode's end, not the rollout's
            save_checkpoint(self.model, self.checkpoint, self.info(episodes), encoder_file=self.encoder_copy,
                            replay_buffer=self.config.save_replay_buffer and self.off_policy,
                            rng_state=streams if streams is not None else True, rollout_state=rollout)
        self.announce_checkpoint(episodes)

    # -------------------------------------------------------------------- run

    @property
    def finished(self) -> bool:
        return self.callback.finished

    @property
    def timesteps(self) -> int:
        return int(self.model.num_timesteps)

    @property
    def tally(self) -> EpisodeCallback:
        return self.callback

    def learn(self) -> None:
        self.model.learn(self.budget(), callback=self.callback, reset_num_timesteps=self.state is None, tb_log_name=self.config.algo)

    def save_final(self) -> None:
        self.save(self.callback.done, final=True)

    def close(self) -> None:
        self.collecting.close()

    def budget(self) -> int:
        """The steps ``learn`` is given: an upper bound (the callback stops on the budget).

        The same total as an uninterrupted run's, so a learning-rate schedule sees the same progress
        after a resume (B worlds finish N episodes of at most max_steps within ceil(N / B) * max_steps
        steps each; one world: N * max_steps, as the published ``num_envs: 1`` runs had).
        """
        config, model = self.config, self.model
        other_worlds = config.num_envs - 1
        total = config.timesteps if config.timesteps is not None else (config.episodes + other_worlds) * self.max_steps + 1
        budget = total - model.num_timesteps  # enough: the steps already taken count
        if self.state and not self.exact and config.timesteps is None:  # the steps of the interrupted episodes are taken again
            budget = max(budget, (config.episodes - self.callback.done + other_worlds) * self.max_steps + 1)
        return budget
