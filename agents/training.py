"""``train(config)``: one training run, counted in episodes, with checkpoints that can be resumed.

Output folder (``config.out``):

* ``config.yaml``: the resolved configuration;
* ``episodes.csv``: one row per training episode (index, seed, outcome, return, length, ...);
* ``checkpoint/``: the latest resumable checkpoint (see :mod:`crowdnav.agents.checkpoint`), rewritten
  every ``checkpoint_every`` episodes and at the end;
* ``snapshots/episode_<N>/``: the policy after N episodes (no replay buffer), for evaluation
  along training; ``snapshots/steps_<N>/`` after N env steps with ``checkpoint_every_steps``;
* ``tensorboard/`` with ``tensorboard: true``.

``resume=True`` continues from ``checkpoint/``: the episode count, the episode seeds, the
model and (if saved) the replay buffer carry on; the budget is still ``config.episodes`` (or
``config.timesteps``) in all. With ``num_envs > 1`` the run collects from that many worlds of the
native vector env (:func:`crowdnav.agents.factory.make_vec_env`); a resume needs the same number.

This module trains the Stable-Baselines3 algorithms; a registered algorithm outside SB3
(:mod:`crowdnav.agents.algorithm_protocol`) goes to :func:`crowdnav.agents.protocol_training.train_registered`.
"""

from __future__ import annotations

import importlib.util
import json
import shutil
import time
import warnings
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import gymnasium as gym
import torch
import yaml
from crowdnav.agents.algorithm_kinds import off_policy, replay_buffer
from crowdnav.agents.callbacks import EpisodeCallback
from crowdnav.agents.checkpoint import (
    ENCODER_FILE,
    LEGACY_FILES,
    MODEL_FILE,
    find_checkpoint,
    load_model,
    read_policy_info,
    restore_pickled_rng_state,
    resume_model,
    save_checkpoint,
)
from crowdnav.agents.config import ConfigError, TrainConfig, config_from_mapping, config_to_dict, load_config
from crowdnav.agents.episode_log import EpisodeLogError, prepare_log
from crowdnav.agents.factory import (
    OFF_POLICY,
    env_options,
    hyperparameters,
    load_leog_weights,
    make_env,
    make_model,
    make_vec_env,
    observation_normalization,
    precomputes_leog,
)
from crowdnav.agents.resume_point import STEPS_AFTER_KEY, ResumePoint, end_open_episodes
from crowdnav.agents.resume_state import (
    REPLAY_ARRAYS,
    ROLLOUT_ARRAYS,
    STATE_FILE,
    ActionLog,
    ResumeStateError,
    load_replay_buffer,
    restore_training_state,
)
from crowdnav.agents.run_folder import REPLAY_FILE, RNG_FILE, checkpoint_dir, episode_log, recover_checkpoint, snapshot_dir, snapshot_folders, writing
from crowdnav.agents.seeding import EpisodeSeedCounter, train_seed
from crowdnav.agents.train_result import TrainResult as TrainResult
from crowdnav.agents.vec_env import CrowdNavSB3VecEnv
from crowdnav.agents.wrappers import scales_from_json, scales_to_json
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

from crowdnav.registry import algorithm_spec


def train(config: TrainConfig | Mapping[str, Any] | str | Path, *, resume: bool = False,
          on_checkpoint: Callable[[int], None] | None = None, trust_pickle: bool = False) -> TrainResult:
    """Train an agent as ``config`` says (a TrainConfig, a mapping, or a YAML file path).

    ``on_checkpoint(episodes)`` is called after each checkpoint is saved (the evaluation runner
    saves its timing there, so a kill loses no recorded time). A resume reads no pickle
    (:mod:`crowdnav.agents.resume_state`); a checkpoint of an older crowdnav, whose state is pickled, is
    refused unless ``trust_pickle`` (its worlds mid-episode are then not continued).
    """
    if isinstance(config, (str, Path)):
        config = load_config(config)
    elif isinstance(config, Mapping):
        config = config_from_mapping(config)
    # a TrainConfig was checked when it was built: not again here (one validation per run)
    if config.agents == "robots":  # every robot of a multi-robot scenario, one shared policy: SuperSuit + SB3's PPO
        from crowdnav.agents.marl import train_robots

        return train_robots(config, resume=resume, on_checkpoint=on_checkpoint)
    torch.set_num_threads(config.torch_threads)
    if algorithm_spec(config.algo).builder is not None:  # a registered algorithm: crowdnav.agents.algorithm_protocol
        from crowdnav.agents.protocol_training import check_supported, train_registered

        check_supported(config)
        with writing(config.out):
            return train_registered(config, resume, on_checkpoint)
    with writing(config.out):  # one process writes a run at a time
        return _train(config, resume, on_checkpoint, trust_pickle)


def _train(config: TrainConfig, resume: bool, on_checkpoint: Callable[[int], None] | None, trust_pickle: bool = False) -> TrainResult:
    out = Path(config.out)
    checkpoint = checkpoint_dir(out)
    if resume:
        recover_checkpoint(out)  # a kill during a checkpoint swap leaves a complete .partial or .old
    state = _resume_state(checkpoint, config, trust_pickle) if resume else None
    if state and state["normalization"] is None and config.normalize_observations:
        # a checkpoint from before observation normalisation: its model was trained on raw observations
        warnings.warn(f"{checkpoint} predates observation normalisation; resuming on raw observations "
                      "(normalize_observations: false)", stacklevel=2)
        config = config.model_copy(update={"normalize_observations": False})
    if not resume and checkpoint.exists():
        raise ConfigError(f"{out} already holds a run (checkpoint/); resume it with --resume or choose another --out")
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.yaml").write_text(yaml.safe_dump(config_to_dict(config), sort_keys=False), encoding="utf-8")
    _prepare_episode_log(out, state["episodes"] if state else 0)  # header on disk before anything can be killed mid-episode

    encoder, saved_encoder = load_leog_weights(config)
    precompute = precomputes_leog(config)
    first_episode = state["episodes"] if state else 0
    stored = state["normalization"] if state else None
    batched = config.num_envs > 1  # the native vector env (every algorithm), or one env as the published results were trained
    # batched: episodes end in another order than they start, so the first one not yet started can be past the count
    # (only used when the checkpoint's own vector env is not restored: its counter goes on)
    first_started = (state.get("next_episode") or first_episode) if state and batched else first_episode
    leog, saved_scales = encoder if precompute else None, scales_from_json(stored) if stored is not None else None
    # collecting: what the model steps; on-policy and batched checkpoints store its worlds mid-episode (crowdnav.agents.resume_worlds)
    if batched:
        vector = make_vec_env(config, leog, first_started, saved_scales)
        env: gym.Env | CrowdNavSB3VecEnv = vector
        collecting: gym.Env | VecEnv = ActionLog(vector)
        max_steps = vector.env.scenario.max_steps
    else:
        single = make_env(config, leog, first_started, saved_scales)
        env = collecting = single
        if config.algo not in OFF_POLICY:
            collecting = ActionLog(DummyVecEnv([lambda: single]))
        max_steps = _scenario_max_steps(single)
    scales = observation_normalization(env)
    unit = "steps" if config.checkpoint_every_steps is not None else "episodes"  # what snapshots and checkpoints count
    tensorboard_log = _tensorboard_folder(config, out)
    on_start = None
    saved_streams = None
    if state and state["legacy"]:  # trust_pickle: an older crowdnav's pickles (SB3's full load included)
        model = load_model(checkpoint, env=collecting, device=config.device)
        if tensorboard_log is not None:
            model.tensorboard_log = tensorboard_log
        if config.algo in OFF_POLICY and (checkpoint / REPLAY_FILE).is_file():
            off_policy(model).load_replay_buffer(checkpoint / REPLAY_FILE)
        saved_streams = restore_pickled_rng_state(model, checkpoint / RNG_FILE)
    elif state:  # tensors, JSON and arrays only
        with _resume_errors(_restart_hint(out)):
            model = resume_model(checkpoint, config, collecting, saved_encoder, tensorboard_log)
        if config.algo in OFF_POLICY and (checkpoint / REPLAY_ARRAYS).is_file():
            with _resume_errors(f"; remove {checkpoint / REPLAY_ARRAYS} to resume with an empty replay buffer"):
                load_replay_buffer(replay_buffer(model), checkpoint / REPLAY_ARRAYS)
    else:
        model = make_model(config, collecting, saved_encoder, tensorboard_log)
        from crowdnav.agents.demonstrations import warm_start

        warm_start(model, config)  # demonstrations (off by default); a resumed run carries them in its weights and buffer
    rewinds = config.algo in OFF_POLICY and not batched
    resume_point = ResumePoint(model, off_policy=config.algo in OFF_POLICY, batched=batched)
    # the resumed run is the uninterrupted one: single-env off-policy checkpoints are rewound to an episode end,
    # the others carry their worlds mid-episode (without them, e.g. an older crowdnav's: a close resume)
    worlds = bool(state and not state["legacy"] and not rewinds and (checkpoint / ROLLOUT_ARRAYS).is_file())
    if worlds:
        from crowdnav.agents.resume_worlds import load_rollout

        with _resume_errors(f"; remove {checkpoint / ROLLOUT_ARRAYS} to resume with new episodes in every world"):
            resume_point.restore_rollout(load_rollout(checkpoint / ROLLOUT_ARRAYS, model))
    elif state and batched and config.algo in OFF_POLICY:
        end_open_episodes(getattr(model, "replay_buffer", None))  # the worlds start new episodes
    if state and not state["legacy"]:  # building the model re-seeded every stream: continue the saved ones (last: nothing draws after)
        with _resume_errors(_restart_hint(out)):
            saved_streams = restore_training_state(model, checkpoint / STATE_FILE)
    exact = bool(state) and saved_streams is not None and (rewinds or worlds)
    if state and saved_streams is not None:
        steps_after = int(saved_streams.get(STEPS_AFTER_KEY, 0))
        on_start = lambda: resume_point.continue_run(steps_after)  # noqa: E731 (once SB3's logger exists)
    # copied into every checkpoint, so a checkpoint stands alone
    encoder_copy = out / ENCODER_FILE if precompute else None
    if encoder_copy is not None and not resume:
        shutil.copyfile(_encoder_path(config), encoder_copy)

    def info(episodes: int) -> dict[str, Any]:
        started = {"next_episode": _next_episode(model)} if batched else {}
        return {"algo": config.algo, "env": env_options(config),
                "observation_normalization": None if scales is None else scales_to_json(scales),
                "episodes": episodes, "timesteps": model.num_timesteps, **started,
                "successes": callback.successes, "hyperparameters": hyperparameters(config), "config": config_to_dict(config)}

    def save_snapshot(point: int) -> None:
        save_checkpoint(model, snapshot_folder(out, point, unit), info(callback.done), encoder_file=encoder_copy)

    def save(episodes: int, final: bool = False) -> None:
        # The snapshot first: once the checkpoint says N episodes, snapshot N exists, so a kill
        # between the two writes cannot lose an evaluation point. (The callback usually took it
        # already, when episode N ended; a rollout can run past it before the checkpoint.)
        point = episodes if unit == "episodes" else callback.point
        if point and not snapshot_folder(out, point, unit).is_dir():
            save_snapshot(point)
        # a batched run ends inside a step (SB3 stops before it stores the step's transitions and observations):
        # its worlds cannot be continued, a resume with a larger budget starts new episodes (next_episode on)
        rollout = None if final and batched else resume_point.rollout_state()
        with resume_point.rewound() as streams:  # the checkpoint is the last episode's end, not the rollout's
            save_checkpoint(model, checkpoint, info(episodes), encoder_file=encoder_copy,
                            replay_buffer=config.save_replay_buffer and config.algo in OFF_POLICY,
                            rng_state=streams if streams is not None else True, rollout_state=rollout)
        if on_checkpoint is not None:
            on_checkpoint(episodes)

    callback = EpisodeCallback(
        config.episodes, first_episode, lambda episode: train_seed(config.seed, episode),
        checkpoint_every=config.checkpoint_every, save=save, snapshot=save_snapshot, on_start=on_start, log_file=episode_log(out),
        progress=config.progress, successes_before=state["successes"] if state else 0, resume_point=resume_point,
        timesteps=config.timesteps, checkpoint_every_steps=config.checkpoint_every_steps,
    )
    if unit == "steps":
        every = config.checkpoint_every_steps
        callback.point = model.num_timesteps // every * every if state and every else 0
        _set_aside_snapshots_after(out, model.num_timesteps if state else 0, unit)
    else:
        _set_aside_snapshots_after(out, state["episodes"] if state else 0, unit)
        if state and not snapshot_folder(out, state["episodes"]).is_dir():
            save_snapshot(state["episodes"])  # a run checkpointed by an older crowdnav, killed before its snapshot
    started = time.perf_counter()
    start_steps = model.num_timesteps
    callback.model = model  # the budget check reads its step count before learn() binds it
    if not callback.finished:
        # an upper bound (the callback stops on the budget), and the same total as an uninterrupted run's,
        # so a learning-rate schedule sees the same progress after a resume
        # (B worlds finish N episodes of at most max_steps within ceil(N / B) * max_steps steps each; one env: as before batching)
        other_worlds = config.num_envs - 1
        total = config.timesteps if config.timesteps is not None else (config.episodes + other_worlds) * max_steps + 1
        budget = total - model.num_timesteps  # enough: the steps already taken count
        if state and not exact and config.timesteps is None:  # the steps of the interrupted episodes are taken again
            budget = max(budget, (config.episodes - callback.done + other_worlds) * max_steps + 1)
        model.learn(budget, callback=callback, reset_num_timesteps=state is None, tb_log_name=config.algo)
        save(callback.done, final=True)
    seconds = time.perf_counter() - started
    collecting.close()
    return TrainResult(
        out=out, checkpoint=checkpoint, episodes=callback.done, timesteps=model.num_timesteps, successes=callback.successes,
        seconds=seconds, steps_per_second=(model.num_timesteps - start_steps) / seconds if seconds > 0 else 0.0,
        records=callback.records, model=model,
    )


def snapshot_folder(out: Path, point: int, unit: str = "episodes") -> Path:
    """Where a run saves its policy after ``point`` training episodes (or env steps, ``unit="steps"``)."""
    return snapshot_dir(out, point, unit)


def _set_aside_snapshots_after(out: Path, point: int, unit: str) -> None:
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


def _resume_state(checkpoint: Path, config: TrainConfig, trust_pickle: bool = False) -> dict[str, Any]:
    try:
        folder = find_checkpoint(checkpoint)
    except FileNotFoundError:
        raise ConfigError(f"cannot resume: {checkpoint} holds no checkpoint (start the run without --resume)") from None
    try:
        info = read_policy_info(folder)
    except ValueError as error:
        raise ConfigError(f"cannot resume: {error}{_restart_hint(checkpoint.parent)}") from None
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
    return {"episodes": int(info["episodes"]), "successes": int(info.get("successes", 0)), "config": info.get("config"),
            "normalization": normalization, "next_episode": info.get("next_episode"), "legacy": legacy}


def _prepare_episode_log(out: Path, first_episode: int) -> None:
    """Create or repair ``episodes.csv`` (:func:`crowdnav.agents.episode_log.prepare_log`), saying what a kill had left damaged."""
    try:
        repairs = prepare_log(episode_log(out), first_episode)
    except EpisodeLogError as error:
        raise ConfigError(str(error)) from None
    for note in repairs:
        warnings.warn(f"{out}: {note}", stacklevel=3)


@contextmanager
def _resume_errors(hint: str = "") -> Iterator[None]:
    """A damaged or foreign resume file: the CLI's one-line ConfigError, ending with ``hint`` (how to go on)."""
    try:
        yield
    except ResumeStateError as error:
        raise ConfigError(f"cannot resume: {error}{hint}") from None
    except ConfigError as error:
        raise ConfigError(f"{error}{hint}") from None


def _restart_hint(out: Path) -> str:
    """How to go on from a checkpoint that cannot be resumed (cut short, damaged, foreign)."""
    return f"; this checkpoint cannot be resumed: move {out} away (its snapshots still load as policies) and train again"


def _next_episode(model: BaseAlgorithm) -> int:
    """A batched run's first episode not yet started: its worlds' episode counter (an ActionLog forwards the attribute)."""
    counter = getattr(model.get_env(), "episode_seeds", None)
    if not isinstance(counter, EpisodeSeedCounter):
        raise TypeError(f"a batched run's env counts its episodes with an EpisodeSeedCounter, got {counter!r}")
    return counter.next_episode


def _scenario_max_steps(env: gym.Env) -> int:
    """The episode length limit of the scenario of a :func:`make_env` environment."""
    from crowdnav.envs import CrowdNavEnv

    core = env.unwrapped
    if not isinstance(core, CrowdNavEnv):
        raise TypeError(f"expected a CrowdNavEnv under the wrappers, got {type(core).__name__}")
    return int(core.scenario.max_steps)


def _encoder_path(config: TrainConfig) -> Path:
    if config.encoder.weights is None:  # only frozen runs copy their encoder, and TrainConfig requires their weights
        raise ConfigError("encoder.weights: encoder mode 'frozen' needs pre-trained weights (crowdnav pretrain-encoder)")
    path = Path(config.encoder.weights)
    return path / ENCODER_FILE if path.is_dir() else path


def _tensorboard_folder(config: TrainConfig, out: Path) -> str | None:
    if not config.tensorboard:
        return None
    if importlib.util.find_spec("tensorboard") is None:
        raise ConfigError("tensorboard: true needs the tensorboard package, which is not installed: pip install 'crowdnav[tensorboard]'")
    return str(out / "tensorboard")


def describe_run(result: TrainResult) -> str:
    """One-paragraph summary for the command line."""
    return json.dumps({
        "out": str(result.out), "episodes": result.episodes, "timesteps": result.timesteps,
        "success_rate": round(result.success_rate, 3), "steps_per_second": round(result.steps_per_second, 1),
        "seconds": round(result.seconds, 1),
    })

