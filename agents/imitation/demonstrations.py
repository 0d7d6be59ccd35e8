"""Demonstrations: a warm start from the privileged social-force robot, before (and under) RL.

Off by default (``demonstrations.episodes: 0``): the main job and every published run are pure RL.
With ``episodes: N`` a new run (never a resumed one: its weights and buffer carry the warm start
already) does, right after its model is made (:func:`warm_start`):

1. **Collect** (:func:`collect_demonstrations`): :class:`crowdnav.planning.scripted.SocialForceRobot`, which
   reads the true simulator state, drives N episodes of the run's environment (its scenario,
   overrides, modalities, sensors and reward), one single env per running episode, the episodes
   stepped side by side in lock-step. Episode ``i`` uses seed
   :func:`~crowdnav.agents.training.seeding.demonstration_seed` ``(config.seed, i)``: never a held-out test
   seed, a grid-collection seed or one of the run's training episodes. Observations are what the
   agent receives: normalised with the training env's scales (``NormalizeObservation`` /
   ``CrowdNavSB3VecEnv``), the LEOG grid replaced by the frozen encoder's latent when the run
   precomputes it; this is applied to all steps at once. Actions are the expert's, as
   ``env.step`` takes them: float32 (2,) in [-1, 1] (robot-frame velocity in max-speed units for
   a holonomic robot, forward speed and turn rate for a unicycle).
2. **Clone** (:func:`behaviour_cloning`) the SB3 policy's actor on (observation, expert action),
   with a fresh Adam (the algorithm's own optimizer is left untouched):

   * PPO / A2C: mean squared error of the Gaussian's mean; then its state-independent
     ``log_std`` is set to ``log(action_std)`` (the clone's exploration when fine-tuning starts);
   * SAC: mean squared error of the deterministic action ``tanh(mean)``, and of the log-std
     head's output against ``log(action_std)``;
   * TD3 / DDPG: mean squared error of the actor's (tanh) action; the target actor is synced.

   With ``value_pretraining`` the value function (PPO/A2C; through its own layers, on the
   extractor's detached features when the extractor is shared with the actor) or both critics
   at the demonstrated actions (SAC/TD3/DDPG; target critics synced) are fitted to the
   demonstrations' discounted returns-to-go, at the algorithm's ``gamma`` and ``reward_scale``.
   An episode cut by the time limit is not bootstrapped (rare for the expert).
3. **DAgger** (``dagger_rounds``): the clone drives ``episodes`` further episodes (deterministic
   actions; the next demonstration seeds), the expert labels every state it visits, and
   cloning continues on everything collected so far.
4. **Replay buffer** (SAC/TD3/DDPG, ``into_replay_buffer``): every collected transition (the
   executed action, the reward the algorithm learns from) is added as an ordinary transition,
   laid out so that n-step returns never run from one episode into another
   (:func:`add_to_replay_buffer`); the FIFO overwrites them like any other.

A report (transitions, expert outcomes, losses before and after) is returned and written to
``OUT/demonstrations.json``. Every random choice (minibatch order) is drawn from a generator
seeded with the run's seed; the expert is deterministic.

Why not the ``imitation`` package: its latest release (1.0.1) requires ``gymnasium~=0.29`` and
``stable-baselines3~=2.2.1``; installing it would downgrade crowdnav's gymnasium 1.x and SB3 2.9
(and bring ~50 packages: datasets, optuna, sacred, tensorboard). Its BC is also a policy-only
trainer on SB3's own ``ActorCriticPolicy``; it neither clones SAC/TD3 actors nor fills their
replay buffers. The in-house path is the few loops below.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from crowdnav.agents.imitation.cloning import Demonstrations, behaviour_cloning
from crowdnav.agents.sb3.factory import env_options, hyperparameters, load_leog_weights, precomputes_leog
from crowdnav.agents.sb3.kinds import replay_buffer
from crowdnav.agents.sb3.vec_env import CrowdNavSB3VecEnv
from crowdnav.agents.training import wrappers
from crowdnav.agents.training.config import TrainConfig
from crowdnav.agents.training.seeding import demonstration_seed
from crowdnav.agents.training.wrappers import LeogLatentWrapper, NormalizeObservation, ObservationScales, agent_observation
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.buffers import DictReplayBuffer
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnvWrapper

from crowdnav.files import atomic_write_text
from crowdnav.registry import is_off_policy

REPORT_FILE = "demonstrations.json"
EXPERT = "social-force"

Learner = Callable[[Mapping[str, np.ndarray]], np.ndarray]
"""Agent-view observations stacked per key, (N, ...) -> actions (N, 2): the clone driving DAgger episodes."""


def declared_scales(config: TrainConfig) -> ObservationScales | None:
    """The scales a new run's env applies (the modalities' declared ones; None without normalisation)."""
    if not config.normalize_observations:
        return None
    from crowdnav.envs import CrowdNavEnv

    env = CrowdNavEnv(**env_options(config))
    scales = wrappers.declared_scales(env.core.modalities)
    env.close()
    return scales


def agent_view(env: Any) -> tuple[ObservationScales | None, Any]:
    """``(scales, frozen encoder)`` of a training env (:func:`make_vec_env`'s, or SB3's ``DummyVecEnv`` of :func:`make_env`'s)."""
    while isinstance(env, VecEnvWrapper):
        env = env.venv
    if isinstance(env, CrowdNavSB3VecEnv):
        return env.scales, env.encoder
    if isinstance(env, DummyVecEnv):
        scales, encoder, inner = None, None, env.envs[0]
        while isinstance(inner, gym.Wrapper):
            if isinstance(inner, NormalizeObservation):
                scales = inner.scales
            if isinstance(inner, LeogLatentWrapper):
                encoder = inner.encoder
            inner = inner.env
        return scales, encoder
    raise TypeError(f"cannot read the observation scaling of {type(env).__name__}; pass scales and encoder explicitly")


def collect_demonstrations(config: TrainConfig | Mapping[str, Any], episodes: int | None = None, *, first_episode: int = 0,
                           scales: ObservationScales | None | str = "declared", encoder: Any = "config", learner: Learner | None = None,
                           worlds: int | None = None) -> Demonstrations:
    """Play demonstration episodes ``first_episode`` .. ``first_episode + episodes - 1`` in the run's environment.

    ``episodes``: default ``config.demonstrations.episodes``. ``scales``: the agent's observation
    scaling (``"declared"``: the modalities' own when ``config.normalize_observations``, what
    a new run uses; None: raw). ``encoder``: the frozen LEOG encoder whose latent replaces the
    grid (``"config"``: the config's, when it precomputes the latent; None: keep the grid).
    ``learner``: drives instead of the expert (DAgger); the expert still labels every state.
    ``worlds``: episodes played side by side (default ``config.num_envs``). The result does not
    depend on ``worlds``: each episode is its own seeded env.
    """
    from crowdnav.envs import CrowdNavEnv
    from crowdnav.planning.scripted import SocialForceRobot

    if not isinstance(config, TrainConfig):
        from crowdnav.agents.training.config import config_from_mapping

        config = config_from_mapping(config)
    episodes = config.demonstrations.episodes if episodes is None else episodes
    if episodes < 1:
        raise ValueError(f"expected at least one demonstration episode, got {episodes}")
    demonstration_seed(config.seed, first_episode + episodes - 1)  # the last seed is in the band (ValueError otherwise)
    if isinstance(scales, str):
        scales = declared_scales(config)
    if isinstance(encoder, str):
        encoder = load_leog_weights(config)[0] if precomputes_leog(config) else None
    expert = SocialForceRobot()
    envs = [CrowdNavEnv(**env_options(config)) for _ in range(min(worlds or config.num_envs, episodes))]
    steps: dict[int, list[tuple[Any, ...]]] = {}
    outcomes: dict[int, str] = {}
    playing: list[int | None] = [None] * len(envs)
    current: list[dict[str, np.ndarray]] = [{} for _ in envs]  # each world's last observation (set by its first reset)
    upcoming = iter(range(first_episode, first_episode + episodes))

    def start(w: int) -> None:
        index = next(upcoming, None)
        playing[w] = index
        if index is not None:
            current[w] = envs[w].reset(seed=demonstration_seed(config.seed, index))[0]
            steps[index] = []

    for w in range(len(envs)):
        start(w)
    while live := [(w, index) for w, index in enumerate(playing) if index is not None]:
        labels = np.stack([np.asarray(expert(envs[w].simulator), dtype=np.float32) for w, _ in live])
        if learner is None:
            actions = labels
        else:
            batch = agent_observation({key: np.stack([current[w][key] for w, _ in live]) for key in current[live[0][0]]}, scales, encoder)
            actions = np.clip(np.asarray(learner(batch), dtype=np.float32).reshape(len(live), -1), -1.0, 1.0)
        for (w, index), action, label in zip(live, actions, labels, strict=True):
            observation, reward, terminated, truncated, info = envs[w].step(action)
            steps[index].append((current[w], observation, action, label, reward, terminated, truncated))
            current[w] = observation
            if terminated or truncated:
                outcomes[index] = str(info.get("outcome", "truncated"))
                start(w)
    for env in envs:
        env.close()
    rows = [row for index in sorted(steps) for row in steps[index]]
    keys = list(rows[0][0])
    raw = {key: np.stack([row[0][key] for row in rows]) for key in keys}
    raw_next = {key: np.stack([row[1][key] for row in rows]) for key in keys}
    driver = "clone" if learner is not None else EXPERT
    return Demonstrations(
        observations=agent_observation(raw, scales, encoder), next_observations=agent_observation(raw_next, scales, encoder),
        actions=np.stack([row[2] for row in rows]).astype(np.float32), expert_actions=np.stack([row[3] for row in rows]),
        rewards=np.array([row[4] for row in rows], dtype=np.float32), terminated=np.array([row[5] for row in rows], dtype=bool),
        truncated=np.array([row[6] for row in rows], dtype=bool),
        episode=np.concatenate([np.full(len(steps[index]), index, dtype=np.int64) for index in sorted(steps)]),
        outcomes={index: outcomes[index] for index in sorted(steps)}, driver={index: driver for index in steps},
    )


# ------------------------------------------------------------------------------------------ replay buffer


def add_to_replay_buffer(model: BaseAlgorithm, demonstrations: Demonstrations, reward_scale: float = 1.0) -> int:
    """Add the demonstrations to an off-policy model's replay buffer as ordinary transitions; returns how many.

    The buffer keeps ``n_envs`` columns (one per world), and n-step returns run down a column.
    The transitions, in episode order, are cut into ``n_envs`` equal runs, one per column; the
    last transition of each run that does not end its episode is marked a time-limit truncation
    (bootstrapped from its true next observation, never summed into the next run or into the
    training transitions written after it). The remainder (fewer than ``n_envs``) is left out,
    and so are the oldest rows when they would not fit in the buffer.
    """
    buffer = replay_buffer(model)
    if not isinstance(buffer, DictReplayBuffer):  # crowdnav's observations are dicts (make_model's PackedGridReplayBuffer)
        raise TypeError(f"expected a buffer of dict observations, got {type(buffer).__name__}")
    columns = buffer.n_envs
    rows = min(len(demonstrations) // columns, buffer.buffer_size)
    if rows == 0:
        return 0
    skip = len(demonstrations) // columns - rows  # rows that would not fit: drop the oldest of each run
    dones = demonstrations.dones
    starts = np.arange(columns) * (len(demonstrations) // columns) + skip
    for row in range(rows):
        index = starts + row
        cut = (row == rows - 1) & ~dones[index]
        timeouts = demonstrations.truncated[index] | cut
        buffer.add(
            {key: values[index] for key, values in demonstrations.observations.items()},
            {key: values[index] for key, values in demonstrations.next_observations.items()},
            demonstrations.actions[index], demonstrations.rewards[index] * reward_scale, dones[index] | cut,
            [{"TimeLimit.truncated": bool(t)} for t in timeouts],
        )
    return rows * columns


# --------------------------------------------------------------------------------------------- warm start


def warm_start(model: BaseAlgorithm, config: TrainConfig) -> dict[str, Any] | None:
    """Warm-start a NEW model from demonstrations as ``config.demonstrations`` says; None (and nothing done) when off.

    Called once by :func:`crowdnav.agents.train` after a new model is made, never on resume.
    Writes the report to ``OUT/demonstrations.json`` when ``config.out`` exists.
    """
    settings = config.demonstrations
    if settings.episodes == 0:
        return None
    scales, encoder = agent_view(model.get_env())
    hyper = hyperparameters(config)
    cloning = {"epochs": settings.epochs, "batch_size": settings.batch_size, "learning_rate": settings.learning_rate,
               "action_std": settings.action_std, "value_pretraining": settings.value_pretraining, "gamma": hyper["gamma"],
               "reward_scale": config.reward_scale, "seed": config.seed}
    demonstrations = collect_demonstrations(config, settings.episodes, scales=scales, encoder=encoder)
    rounds = [{"driver": EXPERT, "episodes": settings.episodes, "success_rate": demonstrations.success_rate(),
               **behaviour_cloning(model, demonstrations, **cloning)}]
    for round_index in range(1, settings.dagger_rounds + 1):
        def learner(obs: Mapping[str, np.ndarray]) -> np.ndarray:
            return model.policy.predict(dict(obs), deterministic=True)[0]

        more = collect_demonstrations(config, settings.episodes, first_episode=round_index * settings.episodes, scales=scales,
                                      encoder=encoder, learner=learner)
        demonstrations = demonstrations + more
        rounds.append({"driver": "clone", "dagger_round": round_index, "episodes": settings.episodes, "success_rate": more.success_rate(),
                       **behaviour_cloning(model, demonstrations, **{**cloning, "seed": config.seed + round_index})})
    report: dict[str, Any] = {"expert": EXPERT, "episodes": demonstrations.episodes, "transitions": len(demonstrations),
                              "expert_success_rate": demonstrations.success_rate(EXPERT), "rounds": rounds, "replay_buffer": 0}
    if is_off_policy(config.algo) and settings.into_replay_buffer:
        report["replay_buffer"] = add_to_replay_buffer(model, demonstrations, config.reward_scale)
    out = Path(config.out)
    if out.is_dir():
        atomic_write_text(out / REPORT_FILE, json.dumps(report, indent=2) + "\n")  # replaces a link, never writes through it
    return report
