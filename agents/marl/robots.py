"""Shared-parameter PPO for the robots of a multi-robot scenario (``agents: robots`` in a TrainConfig).

No episode loop of crowdnav's own: :class:`crowdnav.agents.marl.vec_env.RobotsVecEnv` plays
``num_envs`` worlds of the robots-only env (stacked in one batch where the scenario allows,
:mod:`crowdnav.envs.engines.robots`) and gives Stable-Baselines3 one vector row per robot per world;
SB3's PPO trains one ``MlpPolicy`` on every row, so every robot acts with the same network (told
apart by the one-hot of ``agent_identity``). :class:`RobotsRun` is that run as a strategy of the one run loop
(:class:`crowdnav.agents.training.run_loop.RunLoop`, which owns the run folder, the resume decision and the result).

The output folder is a run folder like a single-agent run's (:mod:`crowdnav.agents.runs.folder`):
``config.yaml``, ``episodes.csv`` (one row per *robot* episode: a world's episode with three
robots adds three rows, each with that robot's outcome, return and length), ``checkpoint/`` and
``snapshots/`` (``policy.json`` + ``model.zip``, loaded without unpickling by
:func:`load_robots_policy`). Budgets and checkpoints count what SB3 counts: ``timesteps`` are
robot steps (one per robot row per world step), ``episodes`` robot episodes.

A folder that holds a run is refused unless ``resume``. A resume is exact: the checkpoint after
each point is taken at the end of the PPO rollout it falls in, with the rollout, the worlds
mid-episode and every random stream (:mod:`crowdnav.agents.marl.resume`), so a run killed
anywhere and resumed is the run never killed, bit for bit. The final checkpoint (inside the step
that spent the budget) keeps no worlds: resumed with a larger budget, every world starts a new
episode (the numbering carries on, so no seed repeats).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from functools import partial
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
from crowdnav.agents.marl.actions import RobotActions
from crowdnav.agents.marl.env import RobotObservations, robots_env
from crowdnav.agents.marl.networks import KindActorCriticPolicy, robot_kinds
from crowdnav.agents.marl.resume import has_state, load_state, pending_update, save_resumable
from crowdnav.agents.marl.vec_env import RobotsVecEnv
from crowdnav.agents.runs.checkpoint import (
    MODEL_FILE,
    check_network_size,
    find_checkpoint,
    load_parameters,
    read_policy_info,
    save_checkpoint,
)
from crowdnav.agents.runs.episode_log import EpisodeLogWriter, prepare_log
from crowdnav.agents.runs.folder import episode_log, snapshot_dir
from crowdnav.agents.runs.result import TrainResult
from crowdnav.agents.runs.resume_state import STATE_FILE, restore_training_state
from crowdnav.agents.sb3.callbacks import EpisodeRecord
from crowdnav.agents.sb3.factory import LinearDecay, env_options, hyperparameters
from crowdnav.agents.sb3.model_zip import read_model_zip
from crowdnav.agents.training.config import ConfigError, TrainConfig, config_from_mapping, config_to_dict
from crowdnav.agents.training.run_loop import Progress, RunLoop, writing_run
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.utils import set_random_seed

from crowdnav.scenario.loader import load_scenario

MAX_INPUTS = 65_536
"""Most inputs a loaded shared robot network may declare (a 360-beam LIDAR and the goal: 363)."""

ROBOTS_KIND = "robots"
"""``policy.json``'s ``agents`` for a shared robot policy (single-agent checkpoints have none)."""


def make_robots_vec_env(config: TrainConfig, first_episode: int = 0) -> RobotsVecEnv:
    """``num_envs`` worlds of the run's robots as one SB3 VecEnv (one row per robot per world)."""
    return RobotsVecEnv.make(config, first_episode)


def _ppo(config: TrainConfig, vec: RobotsVecEnv) -> PPO:
    """SB3's PPO with crowdnav's batched PPO defaults (``hyperparameters``), on an MLP over the flat observations."""
    chosen = hyperparameters(config)
    rate = chosen["learning_rate"]
    schedule = LinearDecay(rate) if chosen["learning_rate_schedule"] == "linear" else rate
    kwargs = {"n_steps": chosen["n_steps"], "batch_size": min(chosen["batch_size"], chosen["n_steps"] * vec.num_envs),
              "gamma": chosen["gamma"], "learning_rate": schedule, **config.algo_kwargs}
    kinds = robot_kinds(vec.scenario) if config.robot_networks == "per_kind" else None
    robots_network_size(config, vec.inputs.space.shape[0], "config", len(set(kinds or [0])))
    set_random_seed(config.seed)  # not PPO(seed=...): the worlds seed their own episodes, and the runs before kept this order
    extra: dict[str, Any] = {} if kinds is None else {"robot_kinds": kinds}
    policy: str | type[ActorCriticPolicy] = "MlpPolicy" if kinds is None else KindActorCriticPolicy
    try:
        return PPO(policy, vec, policy_kwargs={"net_arch": list(chosen["net_arch"]), **extra, **config.policy_kwargs},
                   device=config.device, verbose=0, **kwargs)
    except TypeError as error:  # an algo_kwargs / policy_kwargs key PPO or its policy does not take
        raise ConfigError(f"algo_kwargs / policy_kwargs for ppo: {str(error).splitlines()[0][:200]}") from None


def robots_network_size(config: TrainConfig, inputs: int, label: str, kinds: int = 1) -> int:
    """Parameters of the shared robot network (an MLP policy on ``inputs`` values), refused above the limit before it is built.

    ``kinds``: robot kinds of ``robot_networks: per_kind``, counted as that many whole networks (a bound: their heads' biases are shared).
    """
    from crowdnav.agents.networks.size import check_parameters, describe_layers, heads

    options = {name: bool(config.policy_kwargs[name]) for name in ("share_features_extractor", "full_std") if name in config.policy_kwargs}
    net_arch = hyperparameters(config)["net_arch"]
    total = kinds * heads("actor_critic", inputs, 0, 2, net_arch, use_sde=bool(config.algo_kwargs.get("use_sde", False)), **options)
    return check_parameters(total, label, f"{inputs:,} inputs, net_arch {describe_layers(net_arch)}")


class _RobotEpisodes(BaseCallback):
    """Logs every robot episode, takes snapshots at the budget's points and stops at the budget.

    The resumable checkpoint follows a point at the end of the rollout it falls in (the one moment a
    run can be stored exactly, :mod:`crowdnav.agents.marl.resume`); a resumed run's first act is the
    update that checkpoint preceded (``pending``).
    """

    def __init__(self, config: TrainConfig, out: Path, first_episode: int, successes: int, save: Callable[[], None],
                 snapshot: Callable[[int], None]):
        super().__init__()
        self.config, self.out, self.save_checkpoint, self.snapshot = config, out, save, snapshot
        self.unit = "steps" if config.timesteps is not None else "episodes"
        self.every = (config.checkpoint_every_steps or config.timesteps or 1) if self.unit == "steps" else config.checkpoint_every
        self.done, self.successes = first_episode, successes
        self.records: list[EpisodeRecord] = []
        self.log: EpisodeLogWriter | None = None
        """The episode log, opened when learning starts (a resume that plays nothing leaves it alone)."""
        self.started = time.perf_counter()
        self.returns = np.zeros(0)
        self.lengths = np.zeros(0, dtype=int)
        """Each robot row's return and length in its current episode (set to the run's rows before ``learn``)."""
        self.point = 0
        self.due = False
        """A point passed in this rollout: checkpoint at its end."""
        self.pending: Callable[[], None] | None = None

    def _on_training_start(self) -> None:
        self.log = EpisodeLogWriter(episode_log(self.out))
        if self.pending is not None:
            self.pending()
            self.pending = None

    def _on_rollout_end(self) -> None:
        if self.due:  # the rollout is complete and not yet trained on
            self.due = False
            self.save_checkpoint()

    def _on_step(self) -> bool:
        infos, rewards = self.locals["infos"], self.locals["rewards"]
        dones = np.asarray(self.locals["dones"], dtype=bool)  # as an index, uint8 dones would pick rows 0 and 1
        if len(self.returns) != len(infos):
            self.returns, self.lengths = np.zeros(len(infos)), np.zeros(len(infos), dtype=int)
        self.returns += rewards
        for row, info in enumerate(infos):
            if info.get("outcome") is not None:  # the step this robot ended (its later rows are inactive, reward 0)
                self._record(info, float(self.returns[row]), int(self.lengths[row]) + 1)
            elif info.get("active", True) and not dones[row]:
                self.lengths[row] += 1
        self.returns[dones], self.lengths[dones] = 0.0, 0
        if self.unit == "steps" and self.num_timesteps >= self.point + self.every:
            self.point = self.num_timesteps // self.every * self.every
            self.snapshot(self.point)
            self.due = True
        budget = self.config.timesteps
        return self.num_timesteps < budget if budget is not None else self.done < self.config.episodes

    def _record(self, info: Mapping[str, Any], reward: float, length: int) -> None:
        record = EpisodeRecord(self.done, int(info["episode_seed"]), str(info["outcome"]), reward, length, self.num_timesteps,
                               time.perf_counter() - self.started)
        assert self.log is not None  # opened at the training's start
        self.log.write(f"{record.episode},{record.seed},{record.outcome},{record.reward!r},{record.length},{record.timesteps},"
                       f"{record.seconds:.3f}")
        self.records.append(record)
        self.done += 1
        self.successes += record.outcome == "success"
        if self.unit == "episodes" and self.done % self.every == 0:
            self.snapshot(self.done)
            self.due = True


def train_robots(config: TrainConfig, *, resume: bool = False, on_checkpoint: Callable[[int], None] | None = None) -> TrainResult:
    """Train one shared PPO policy for every robot of ``config.scenario`` (``config.agents == "robots"``); see the module docstring."""
    if config.agents != ROBOTS_KIND:
        raise ConfigError(f"train_robots trains agents: robots; this config has agents: {config.agents}")
    with writing_run(config):
        return RobotsRun(config, resume, on_checkpoint).run()


class RobotsRun(RunLoop):
    """The shared robot PPO run as a strategy of the one run loop (:class:`~crowdnav.agents.training.run_loop.RunLoop`)."""

    def __init__(self, config: TrainConfig, resume: bool, on_checkpoint: Callable[[int], None] | None = None):
        super().__init__(config, resume, on_checkpoint)
        self.state: dict[str, Any] | None = None
        """The resumed checkpoint's ``policy.json``."""

    def read_checkpoint(self) -> Progress | None:
        # a resume without a checkpoint starts the run (shared robot runs always have)
        self.state = read_policy_info(self.checkpoint) if self.checkpoint.exists() else None
        return Progress(int(self.state["episodes"]), int(self.state["timesteps"])) if self.state else None

    def prepare_log(self) -> None:
        """As shared robot runs always have: repaired without a warning, and left as it is by a resume with nothing to play."""
        if not self.spent:
            prepare_log(episode_log(self.out), self.first_episode)  # a resume sets aside the rows after its checkpoint

    def build(self) -> None:
        config, state, checkpoint = self.config, self.state, self.checkpoint
        self.vec = vec = make_robots_vec_env(config, int(state["next_episode"]) if state else 0)
        self.inputs = vec.inputs
        if state and not self.inputs.matches(state["robots"]):
            raise ConfigError(f"{checkpoint}: its robots' observations differ from this config's scenario and options; "
                              "resume with the run's own config.yaml")
        self.model = model = _ppo(config, vec)
        if state:
            load_parameters(model, checkpoint / MODEL_FILE, config.device)
            model.num_timesteps = int(state["timesteps"])
        self.callback = callback = _RobotEpisodes(config, self.out, self.first_episode, int(state["successes"]) if state else 0,
                                                  partial(self.save, True), self.snapshot)
        callback.returns, callback.lengths = np.zeros(vec.num_envs), np.zeros(vec.num_envs, dtype=int)
        # a spent checkpoint is left as it is: rewriting next_episode would move a later extension's seeds
        if state and not self.spent and has_state(checkpoint):
            sums = {"returns": callback.returns, "lengths": callback.lengths}
            load_state(checkpoint, model, vec, sums)
            callback.returns, callback.lengths = sums["returns"], sums["lengths"]
            restore_training_state(model, checkpoint / STATE_FILE)  # counters and every random stream, last
            callback.pending = pending_update(model)
        callback.point = model.num_timesteps // callback.every * callback.every if callback.unit == "steps" else 0
        self.built = True

    @property
    def finished(self) -> bool:
        return self.spent  # short of the budget, a run learns (and takes its final checkpoint)

    @property
    def timesteps(self) -> int:
        return int(self.model.num_timesteps)

    @property
    def tally(self) -> _RobotEpisodes:
        return self.callback

    def learn(self) -> None:
        # an upper bound in robot steps: the callback stops at the budget (episodes of at most max_steps each)
        max_steps = self.vec.scenario.max_steps
        config = self.config
        total = config.timesteps if config.timesteps is not None else (config.episodes + self.vec.num_envs) * max_steps
        remaining = max(total - self.model.num_timesteps, 0)
        if remaining:
            self.model.learn(remaining, callback=self.callback, reset_num_timesteps=self.state is None)

    def info(self) -> dict[str, Any]:
        """The checkpoint's ``policy.json``: what the run is and how far it got."""
        config, callback = self.config, self.callback
        # the episode after every one any world has started: a resume's worlds start there, so no seed repeats
        following = self.vec.next_episode
        return {"algo": config.algo, "agents": ROBOTS_KIND, "env": env_options(config), "robots": self.inputs.to_json(),
                "episodes": callback.done, "timesteps": self.model.num_timesteps, "next_episode": following,
                "successes": callback.successes, "hyperparameters": hyperparameters(config), "config": config_to_dict(config)}

    def snapshot(self, point: int) -> None:
        save_checkpoint(self.model, snapshot_dir(self.out, point, self.callback.unit), self.info())

    def save(self, resumable: bool = False) -> None:
        """The checkpoint; ``resumable``: at a rollout's end, with the worlds, the rollout and the random streams (exact resume)."""
        callback = self.callback
        if callback.log is not None:
            callback.log.sync()  # the log holds every episode the checkpoint counts
        if resumable:
            save_resumable(self.model, self.checkpoint, self.info(), self.vec, {"returns": callback.returns, "lengths": callback.lengths})
        else:  # the budget's end, inside a step: a resume with a larger budget starts new episodes
            save_checkpoint(self.model, self.checkpoint, self.info())
        self.announce_checkpoint(callback.done)

    def save_final(self) -> None:
        callback = self.callback
        if callback.unit == "steps" and self.model.num_timesteps // callback.every * callback.every > callback.point:
            self.snapshot(self.model.num_timesteps // callback.every * callback.every)
        self.save()

    def close(self) -> None:
        if self.callback.log is not None:
            self.callback.log.close()
        self.vec.close()


class RobotsPolicy:
    """A trained shared robot policy: ``policy.act(observations, infos) -> actions`` for the robots-only env.

    ``observations``/``infos`` are what ``crowdnav.parallel_env(**policy.env_options,
    humans_as_agents=False, fixed_agents=True, flat_observations=True)`` returns (raw units);
    the stored scales and one-hot are applied here. Actions: float32 (2,) per robot, deterministic, each robot's
    env action (with ``robot_actions: velocity``, the network's velocity command as each robot's kinematics take it).
    """

    def __init__(self, network: ActorCriticPolicy, info: Mapping[str, Any]):
        self.network = network
        self.info = dict(info)
        self.env_options: dict[str, Any] = dict(info["env"])
        self.observe = RobotObservations.from_json(info["robots"])
        """The stored scales and one-hot, applied to each robot's observation as in training."""
        self.robots: list[str] = self.observe.robots
        mode = str(self.info["config"].get("robot_actions", "native"))  # a run from before the option: native
        if mode == "native":
            self.commands = RobotActions(mode, [], 1.0)
        else:
            env = self.make_env()
            self.commands = RobotActions.for_env(mode, env)
            env.close()
        """The network's actions -> each robot's env action (the run's ``robot_actions``)."""

    @property
    def algo(self) -> str:
        return str(self.info["algo"])

    def make_env(self) -> Any:
        """The robots-only env these observations come from (the one training used, without its seeds and one-hot)."""
        return robots_env(self.env_options)

    def inputs(self, observations: Mapping[str, np.ndarray], infos: Mapping[str, Mapping[str, Any]]) -> np.ndarray:
        return np.stack([self.observe(k, observations[name], bool(infos.get(name, {}).get("active", True)))
                         for k, name in enumerate(self.robots)])

    def act(self, observations: Mapping[str, np.ndarray], infos: Mapping[str, Mapping[str, Any]]) -> dict[str, np.ndarray]:
        actions, _ = self.network.predict(self.inputs(observations, infos), deterministic=True)
        chosen = {name: np.asarray(actions[k], np.float32) for k, name in enumerate(self.robots)}
        return dict(self.commands(chosen, self.robots, observations))


def load_robots_policy(path: str | Path, device: str = "cpu", *, config: TrainConfig | None = None) -> RobotsPolicy:
    """A run, checkpoint or snapshot folder of :func:`train_robots` as a :class:`RobotsPolicy`.

    The network is rebuilt from the run's config (sizes checked first) and gets the zip's
    tensors; nothing in the zip is unpickled. ``config``: the run's TrainConfig, if the caller has it.
    """
    folder = find_checkpoint(path)  # a run folder means its checkpoint/
    info = read_policy_info(folder)
    if info.get("agents") != ROBOTS_KIND:
        raise ConfigError(f"{folder}: not a shared robot policy (agents: robots); load it with crowdnav.agents.load_policy")
    label = str(folder / "policy.json")
    check_robots_info(info, label)
    if config is None:
        config = config_from_mapping({**info["config"], "device": device}, label)
    check_network_size(config, str(folder))
    width = len(info["robots"]["offset"]) + (len(info["robots"]["robots"]) if info["robots"]["identity"] else 0)
    kinds = None
    if config.robot_networks == "per_kind":  # the run's scenario says which robot has which kind
        kinds = robot_kinds(load_scenario(info["env"]["scenario"], info["env"].get("overrides") or None))
        if len(kinds) != len(info["robots"]["robots"]) or not info["robots"]["identity"]:
            raise ConfigError(f"{folder}: robot_networks: per_kind needs the robot one-hot of each of its scenario's {len(kinds)} robots")
    robots_network_size(config, width, str(folder), len(set(kinds or [0])))
    from gymnasium import spaces

    extra: dict[str, Any] = {} if kinds is None else {"robot_kinds": kinds}
    policy_class = ActorCriticPolicy if kinds is None else KindActorCriticPolicy
    try:
        network = policy_class(spaces.Box(-np.inf, np.inf, (width,), np.float32), spaces.Box(-1.0, 1.0, (2,), np.float32),
                               lambda _: 0.0, net_arch=list(hyperparameters(config)["net_arch"]), **extra, **config.policy_kwargs)
    except (TypeError, ValueError) as error:
        raise ConfigError(f"{folder}: cannot rebuild its network from policy_kwargs ({str(error).splitlines()[0][:200]})") from None
    try:
        network.load_state_dict(read_model_zip(folder / MODEL_FILE, device).parameters["policy"])
    except (RuntimeError, KeyError) as error:
        raise ConfigError(f"{folder}: its parameters do not fit the network its config describes ({str(error).splitlines()[0][:200]})") from None
    network.set_training_mode(False)
    return RobotsPolicy(network.to(device), info)


def check_robots_info(info: Mapping[str, Any], label: str) -> None:
    """ConfigError (one line, naming the field) unless a robots ``policy.json`` holds what :class:`RobotsPolicy` reads.

    ``robots``: ``robots`` (1 to 8 names), ``identity`` (a boolean), ``offset`` and ``scale`` (as many
    finite numbers, every scale positive: an input divided by zero or NaN would reach the network
    as NaN); ``env`` and ``config`` mappings; ``algo`` a name.
    """
    import math

    def refuse(field: str, expected: str) -> NoReturn:
        raise ConfigError(f"{label}: {field}: expected {expected}")

    for key in ("env", "config"):
        if not isinstance(info.get(key), Mapping):
            refuse(key, "a mapping (the run's environment options and training config)")
    if not isinstance(info.get("algo"), str):
        refuse("algo", "the algorithm's name")
    inputs = info.get("robots")
    if not isinstance(inputs, Mapping):
        refuse("robots", "a mapping of robots, identity, offset and scale (the inputs' settings the run stored)")
    names = inputs.get("robots")
    if not isinstance(names, list) or not 1 <= len(names) <= 8 or not all(isinstance(name, str) and name for name in names) \
            or len(set(names)) != len(names):
        refuse("robots.robots", "a list of 1 to 8 distinct robot names")
    if not isinstance(inputs.get("identity"), bool):
        refuse("robots.identity", "true or false")
    if not isinstance(inputs.get("offset"), list):
        refuse("robots.offset", "a list of numbers")
    width = len(inputs["offset"]) + (len(names) if inputs["identity"] else 0)
    if not 0 < width <= MAX_INPUTS:  # checked before the network is built: a hostile policy.json cannot make it allocate gigabytes
        raise ConfigError(f"{label}: declares {width:,} inputs; expected 1 to {MAX_INPUTS:,}")
    numbers = {}
    for key in ("offset", "scale"):
        values = inputs.get(key)
        if not isinstance(values, list) or not values or len(values) > MAX_INPUTS or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values):
            refuse(f"robots.{key}", f"a list of 1 to {MAX_INPUTS:,} finite numbers")
        numbers[key] = values
    if len(numbers["offset"]) != len(numbers["scale"]):
        refuse("robots.scale", f"as many values as robots.offset ({len(numbers['offset']):,}), got {len(numbers['scale']):,}")
    if not all(v > 0 for v in numbers["scale"]):
        refuse("robots.scale", "positive numbers (each input is divided by its scale)")
