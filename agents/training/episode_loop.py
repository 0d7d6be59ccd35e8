"""crowdnav's episode loop around :meth:`Algorithm.learn <crowdnav.agents.training.algorithm_protocol.Algorithm.learn>`: :func:`train_registered`.

:class:`EpisodeLoop` is a strategy of the one run loop (:class:`crowdnav.agents.training.run_loop.RunLoop`, which owns
the run folder, the resume decision and the result): it builds the agent (new, or loaded from ``checkpoint/``), lets
it learn, and counts, logs and checkpoints the episodes that end each time the agent calls ``keep_going``.

It trains every algorithm whose registered builder is not a
:class:`~crowdnav.agents.training.algorithm_protocol.RunTrainer` (:func:`crowdnav.agents.training.run.trainer_of`; the built-in
Stable-Baselines3 algorithms have a loop of their own), into the run folder SB3 runs write too.

The run folder is the one every run writes (:mod:`crowdnav.agents.runs.folder`): ``config.yaml``, ``episodes.csv`` (a row per
training episode, seeded ``train_seed(seed, i)``), ``checkpoint/`` (``policy.json`` and ``algorithm/``, what the
agent's :meth:`~crowdnav.agents.training.algorithm_protocol.Algorithm.save` wrote) every ``checkpoint_every`` episodes and at
the end, ``snapshots/episode_<N>/`` after N episodes. ``--resume`` loads the agent from ``checkpoint/`` and goes
on from its episode count, with the episode seeds the uninterrupted run would have had: an agent whose state is
all in what it saves continues exactly. A budget in episodes or ``timesteps`` (env steps of all worlds).

The agent collects from the one vector stack every algorithm uses (:func:`crowdnav.agents.sb3.factory.make_vec_env`:
``num_envs`` worlds of :class:`crowdnav.envs.vector.env.CrowdNavVectorEnv` behind SB3's ``VecEnv`` API, rewards in
float64 as the env gives them; at ``num_envs: 1`` the one world is the single env, episode for episode). Episodes
are numbered in the order they end and logged with the seed their world played. With several worlds a checkpoint
falls while the other worlds are mid-episode: a resume starts new episodes in every world, from the first episode
no world had begun (``next_episode`` in policy.json), and the unfinished ones are not played again (as SB3's
batched runs that end inside a step); at one world that is the episode the uninterrupted run played next.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from crowdnav.agents.runs.checkpoint import POLICY_FORMAT, find_checkpoint, read_policy_info, replace_folder, staging_folder
from crowdnav.agents.runs.episode_log import EpisodeLogWriter
from crowdnav.agents.runs.folder import POLICY_FILE, episode_log, snapshot_dir
from crowdnav.agents.runs.result import TrainResult
from crowdnav.agents.sb3.callbacks import EpisodeRecord
from crowdnav.agents.sb3.factory import env_options, make_vec_env, observation_normalization
from crowdnav.agents.sb3.vec_env import CrowdNavSB3VecEnv
from crowdnav.agents.training.algorithm_protocol import ALGORITHM_FOLDER, Continuing, builder_of, load_algorithm
from crowdnav.agents.training.config import ConfigError, TrainConfig, config_to_dict
from crowdnav.agents.training.run_loop import Progress, RunLoop
from crowdnav.agents.training.seeding import train_seed
from crowdnav.agents.training.wrappers import scales_from_json, scales_to_json
from stable_baselines3.common.vec_env import VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn


def train_registered(config: TrainConfig, resume: bool, on_checkpoint: Callable[[int], None] | None = None) -> TrainResult:
    """Train ``config.algo``, a registered algorithm (:mod:`crowdnav.agents.training.algorithm_protocol`); ``resume``: from ``checkpoint/``."""
    check_supported(config)
    return EpisodeLoop(config, resume, on_checkpoint).run()


class EpisodeEnds(VecEnvWrapper):
    """Counts the env steps (``steps``, of all worlds, over the whole run) and keeps the final info of each episode that ends."""

    def __init__(self, venv: CrowdNavSB3VecEnv, steps: int = 0):
        super().__init__(venv)
        self.steps = steps
        self.ended: list[tuple[dict[str, Any], int]] = []
        """(info of the episode's last step, env steps after it), in the order they ended (one step: world order); the session empties it."""

    def reset(self) -> VecEnvObs:
        return self.venv.reset()

    def step_wait(self) -> VecEnvStepReturn:
        observation, rewards, dones, infos = self.venv.step_wait()
        self.steps += self.num_envs
        if dones.any():
            self.ended.extend((infos[i], self.steps) for i in np.flatnonzero(dones))
        return observation, rewards, dones, infos

    def next_episode(self) -> int:
        """The first training episode no world has begun: the counter's next, less the worlds still at their episode's first step."""
        inner = self.venv
        assert isinstance(inner, CrowdNavSB3VecEnv) and inner.episode_seeds is not None  # make_vec_env's
        counter, (_, lengths) = inner.episode_seeds, inner.world_counts()  # the worlds reset last hold the counter's last numbers
        fresh = sum(1 for world in counter.episode_of if lengths[world] == 0)
        return counter.next_episode - fresh


class EpisodeLoop(RunLoop):
    """The :class:`RunLoop` strategy that counts, logs and checkpoints the episodes that end, each time the agent calls ``keep_going``."""

    caller_frames = 2  # as before: warnings point at train_registered's caller

    def __init__(self, config: TrainConfig, resume: bool, on_checkpoint: Callable[[int], None] | None = None):
        super().__init__(config, resume, on_checkpoint)
        self.info: dict[str, Any] | None = None
        """The resumed checkpoint's ``policy.json``."""

    def read_checkpoint(self) -> Progress:
        self.info = _resume_info(self.checkpoint, self.config)
        return Progress(int(self.info["episodes"]), int(self.info["timesteps"]))

    def build(self) -> None:
        config, info = self.config, self.info
        saved = info.get("observation_normalization") if info else None
        first_started = int(info.get("next_episode", self.first_episode)) if info else 0  # several worlds: past the count (episodes end out of order)
        inner = make_vec_env(config, None, first_started, scales_from_json(saved) if saved is not None else None, reward_dtype=np.float64)
        scales = observation_normalization(inner)
        self.normalization = None if scales is None else scales_to_json(scales)
        self.env = EpisodeEnds(inner, int(info["timesteps"]) if info else 0)
        self.model = load_algorithm(find_checkpoint(self.checkpoint), config.algo) if info else builder_of(config.algo)(self.env, config)
        if info and isinstance(self.model, Continuing):  # e.g. a learning-rate schedule over the resumed run's budget
            self.model.continue_with(config)
        self.done = self.saved = self.first_episode
        self.successes = int(info.get("successes", 0)) if info else 0
        self.records: list[EpisodeRecord] = []
        self._log = EpisodeLogWriter(episode_log(self.out))
        self._start = time.perf_counter()
        self.built = True

    @property
    def finished(self) -> bool:
        if self.config.timesteps is not None:
            return self.env.steps >= self.config.timesteps
        return self.done >= self.config.episodes

    @property
    def timesteps(self) -> int:
        return self.env.steps

    @property
    def tally(self) -> EpisodeLoop:
        return self

    def learn(self) -> None:
        self.model.learn(self.env, self.keep_going)
        self.flush()  # episodes that ended after the agent's last call

    def keep_going(self) -> bool:
        """The agent's call after each episode that ended: log the oldest one not yet logged (checkpoint on schedule), say whether to go on."""
        if self.env.ended:
            self._next(*self.env.ended.pop(0))
        return not self.finished

    def flush(self) -> None:
        """Log the episodes that ended after the agent's last call (within the budget)."""
        ended, self.env.ended = self.env.ended, []
        for info, steps in ended:
            self._next(info, steps)

    def _next(self, info: dict[str, Any], steps: int) -> None:
        if self.config.timesteps is None and self.done >= self.config.episodes:
            return  # the run is exactly `episodes` long (several worlds can end in the step that reaches it)
        self._record(info, steps)

    def _record(self, info: dict[str, Any], steps: int) -> None:
        episode = info.get("episode", {})  # the Monitor's: the env's own return, before reward scaling
        seed = int(info.get("episode_seed", train_seed(self.config.seed, self.done)))  # the seed the world played
        record = EpisodeRecord(episode=self.done, seed=seed, outcome=info.get("outcome", "truncated"),
                               reward=round(float(episode.get("r", float("nan"))), 4), length=int(episode.get("l", 0)),
                               timesteps=steps, seconds=round(time.perf_counter() - self._start, 3))
        self.records.append(record)
        self.done += 1
        self.successes += record.outcome == "success"
        self._log.write(record.csv())
        if self.done % self.config.checkpoint_every == 0:
            self._checkpoint()

    def _checkpoint(self) -> None:
        self._log.sync()  # the checkpoint about to claim these episodes: their rows on disk first
        self.save(snapshot_dir(self.out, self.done))  # first: once the checkpoint says N episodes, snapshot N exists
        self.save(self.checkpoint)
        self.saved = self.done
        self.announce_checkpoint(self.done)

    def save(self, folder: Path) -> None:
        """A checkpoint (or snapshot) folder: ``policy.json`` and the agent's own ``algorithm/``."""
        staging = staging_folder(folder)
        (staging / ALGORITHM_FOLDER).mkdir()
        self.model.save(staging / ALGORITHM_FOLDER)
        document = {"format": POLICY_FORMAT, "algo": self.config.algo, "env": env_options(self.config),
                    "observation_normalization": self.normalization, "episodes": self.done, "timesteps": self.env.steps,
                    "next_episode": self.env.next_episode(),
                    "successes": self.successes, "hyperparameters": {}, "config": config_to_dict(self.config), "leog_encoder": None}
        (staging / POLICY_FILE).write_text(json.dumps(document, indent=2, default=str) + "\n", encoding="utf-8")
        replace_folder(staging, folder)

    def save_final(self) -> None:
        """The final checkpoint, unless the last episode's was taken."""
        if self.saved != self.done or not self.checkpoint.is_dir():
            self._checkpoint()

    def close(self) -> None:
        self._log.close()
        self.env.close()


def check_supported(config: TrainConfig) -> None:
    """ConfigError for the settings only the SB3 path has."""
    if config.encoder.mode != "scratch":
        raise ConfigError(f"encoder.mode: algorithm {config.algo!r} takes the observations as they are; use encoder mode scratch")
    if config.demonstrations.episodes:
        raise ConfigError(f"demonstrations.episodes: the warm start is for SB3 algorithms, not {config.algo!r}; set it to 0")
    if config.checkpoint_every_steps is not None:
        raise ConfigError(f"checkpoint_every_steps: algorithm {config.algo!r} checkpoints every checkpoint_every episodes")


def _resume_info(checkpoint: Path, config: TrainConfig) -> dict[str, Any]:
    try:
        folder = find_checkpoint(checkpoint)
        info = read_policy_info(folder)
    except FileNotFoundError:
        raise ConfigError(f"cannot resume: {checkpoint} holds no checkpoint (start the run without --resume)") from None
    except ValueError as error:
        raise ConfigError(f"cannot resume: {error}") from None
    if info["algo"] != config.algo or info["env"].get("modalities") != list(config.modalities):
        raise ConfigError(f"cannot resume: {folder} was trained with algo {info['algo']} on {info['env'].get('modalities')}, "
                          f"the config asks for {config.algo} on {config.modalities}")
    if not (folder / ALGORITHM_FOLDER).is_dir():
        raise ConfigError(f"cannot resume: {folder / ALGORITHM_FOLDER} is missing")
    return info
