"""crowdnav's episode loop around :meth:`Algorithm.learn <crowdnav.agents.algorithm_protocol.Algorithm.learn>`: :func:`train_registered`.

It trains every algorithm whose registered builder is not a
:class:`~crowdnav.agents.algorithm_protocol.RunTrainer` (:func:`crowdnav.agents.training.trainer_of`; the built-in
Stable-Baselines3 algorithms have a loop of their own), into the run folder SB3 runs write too.

The run folder is the one :mod:`crowdnav.agents.training` writes: ``config.yaml``, ``episodes.csv`` (a row per
training episode, seeded ``train_seed(seed, i)``), ``checkpoint/`` (``policy.json`` and ``algorithm/``, what the
agent's :meth:`~crowdnav.agents.algorithm_protocol.Algorithm.save` wrote) every ``checkpoint_every`` episodes and at
the end, ``snapshots/episode_<N>/`` after N episodes. ``--resume`` loads the agent from ``checkpoint/`` and goes
on from its episode count, with the episode seeds the uninterrupted run would have had: an agent whose state is
all in what it saves continues exactly. One env (``num_envs: 1``); a budget in episodes or ``timesteps``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, SupportsFloat

import gymnasium as gym
import yaml
from crowdnav.agents.algorithm_protocol import ALGORITHM_FOLDER, Algorithm, Continuing, builder_of, load_algorithm
from crowdnav.agents.callbacks import EpisodeRecord
from crowdnav.agents.checkpoint import POLICY_FORMAT, find_checkpoint, read_policy_info, replace_folder, staging_folder
from crowdnav.agents.config import ConfigError, TrainConfig, config_to_dict
from crowdnav.agents.episode_log import EpisodeLogWriter
from crowdnav.agents.factory import env_options, make_env, observation_normalization
from crowdnav.agents.run_folder import POLICY_FILE, checkpoint_dir, episode_log, recover_checkpoint, snapshot_dir
from crowdnav.agents.seeding import train_seed
from crowdnav.agents.train_result import TrainResult
from crowdnav.agents.training_checks import prepare_episode_log
from crowdnav.agents.wrappers import scales_from_json, scales_to_json


def train_registered(config: TrainConfig, resume: bool, on_checkpoint: Callable[[int], None] | None = None) -> TrainResult:
    """Train ``config.algo``, a registered algorithm (:mod:`crowdnav.agents.algorithm_protocol`); ``resume``: from ``checkpoint/``."""
    out = Path(config.out)
    checkpoint = checkpoint_dir(out)
    check_supported(config)
    if resume:
        recover_checkpoint(out)
    info = _resume_info(checkpoint, config) if resume else None
    if not resume and checkpoint.exists():
        raise ConfigError(f"{out} already holds a run (checkpoint/); resume it with --resume or choose another --out")
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.yaml").write_text(yaml.safe_dump(config_to_dict(config), sort_keys=False), encoding="utf-8")
    first = int(info["episodes"]) if info else 0
    prepare_episode_log(out, first, stacklevel=3)  # as before: the warning points at train_registered's caller
    saved = info.get("observation_normalization") if info else None
    inner = make_env(config, None, first, scales_from_json(saved) if saved is not None else None)
    scales = observation_normalization(inner)
    env = EpisodeEnds(inner, int(info["timesteps"]) if info else 0)
    agent: Algorithm = load_algorithm(find_checkpoint(checkpoint), config.algo) if info else builder_of(config.algo)(env, config)
    if info and isinstance(agent, Continuing):  # e.g. a learning-rate schedule over the resumed run's budget
        agent.continue_with(config)
    session = _Session(config, out, agent, env, first, int(info.get("successes", 0)) if info else 0,
                       None if scales is None else scales_to_json(scales), on_checkpoint)
    started, start_steps = time.perf_counter(), env.steps
    if not session.finished:
        agent.learn(env, session.keep_going)
        session.keep_going()  # episodes that ended after the agent's last call
    session.finish()
    env.close()
    seconds = time.perf_counter() - started
    return TrainResult(out=out, checkpoint=checkpoint, episodes=session.done, timesteps=env.steps, successes=session.successes,
                       seconds=seconds, steps_per_second=(env.steps - start_steps) / seconds if seconds > 0 else 0.0,
                       records=session.records, model=agent)


class EpisodeEnds(gym.Wrapper):
    """Counts the env steps (``steps``, over the whole run) and keeps the final info of each episode that ends (``ended``)."""

    def __init__(self, env: gym.Env, steps: int = 0):
        super().__init__(env)
        self.steps = steps
        self.ended: list[tuple[dict[str, Any], int]] = []
        """(info of the episode's last step, env steps after it), oldest first; the session empties it."""

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        self.steps += 1
        if terminated or truncated:
            self.ended.append((info, self.steps))
        return observation, reward, terminated, truncated, info


class _Session:
    """Counts, logs and checkpoints the episodes that end, each time the agent calls ``keep_going``."""

    def __init__(self, config: TrainConfig, out: Path, agent: Algorithm, env: EpisodeEnds, first: int, successes: int,
                 normalization: dict[str, Any] | None, on_checkpoint: Callable[[int], None] | None):
        self.config, self.out, self.agent, self.env = config, out, agent, env
        self.done = self.saved = first
        self.successes = successes
        self.normalization = normalization
        self.on_checkpoint = on_checkpoint
        self.records: list[EpisodeRecord] = []
        self._log = EpisodeLogWriter(episode_log(out))
        self._start = time.perf_counter()

    @property
    def finished(self) -> bool:
        """Whether the budget (episodes, or env steps with ``timesteps``) is spent."""
        if self.config.timesteps is not None:
            return self.env.steps >= self.config.timesteps
        return self.done >= self.config.episodes

    def keep_going(self) -> bool:
        """The agent's call after an episode: log the episodes that ended, checkpoint on schedule, say whether to go on."""
        ended, self.env.ended = self.env.ended, []
        for info, steps in ended:
            if self.config.timesteps is None and self.done >= self.config.episodes:
                break  # the run is exactly `episodes` long
            self._record(info, steps)
        return not self.finished

    def _record(self, info: dict[str, Any], steps: int) -> None:
        episode = info.get("episode", {})  # the Monitor's: the env's own return, before reward scaling
        record = EpisodeRecord(episode=self.done, seed=train_seed(self.config.seed, self.done), outcome=info.get("outcome", "truncated"),
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
        self.save(checkpoint_dir(self.out))
        self.saved = self.done
        if self.on_checkpoint is not None:
            self.on_checkpoint(self.done)

    def save(self, folder: Path) -> None:
        """A checkpoint (or snapshot) folder: ``policy.json`` and the agent's own ``algorithm/``."""
        staging = staging_folder(folder)
        (staging / ALGORITHM_FOLDER).mkdir()
        self.agent.save(staging / ALGORITHM_FOLDER)
        document = {"format": POLICY_FORMAT, "algo": self.config.algo, "env": env_options(self.config),
                    "observation_normalization": self.normalization, "episodes": self.done, "timesteps": self.env.steps,
                    "successes": self.successes, "hyperparameters": {}, "config": config_to_dict(self.config), "leog_encoder": None}
        (staging / POLICY_FILE).write_text(json.dumps(document, indent=2, default=str) + "\n", encoding="utf-8")
        replace_folder(staging, folder)

    def finish(self) -> None:
        """The final checkpoint (unless the last episode's was taken), and the log closed."""
        if self.saved != self.done or not checkpoint_dir(self.out).is_dir():
            self._checkpoint()
        self._log.close()


def check_supported(config: TrainConfig) -> None:
    """ConfigError for the settings only the SB3 path has."""
    if config.num_envs != 1:
        raise ConfigError(f"num_envs: algorithm {config.algo!r} trains on one env; set num_envs: 1")
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
