"""The SARL-style agent: a value network over joint states, acting by a one-step lookahead over 81 actions.

Acting (:meth:`SarlAgent.predict`): for every action of :func:`~crowdnav.agents.sarl.lookahead.action_set` the
robot and the tracked humans move one step (the humans at their observed velocities) and the action scores
``r + gamma^(dt * v_pref) * V(next)`` with ``r`` the reward the agent predicts for that step (0 for ``V`` after a
predicted collision or goal); the best action is taken. All actions of all observations go through the network
in one forward pass.

Learning (:meth:`SarlAgent.learn`, deep V-learning as in Chen et al. 2019): epsilon-greedy episodes (epsilon
decays linearly with the episodes played) fill a replay memory of observed transitions, collected from the run's
``num_envs`` worlds at once (one batched ``predict`` per step; at one world the episodes of the single env); after
every episode (several ending in one step: one after the other, in world order) a few minibatches regress
``V(s)`` on ``r + gamma^(dt * v_pref) * V_target(s')`` (``r`` the env's reward, no bootstrap after the episode
ended), and every ``target_update_every`` episodes the target network copies the
value network. By default the agent learns from its own episodes only (pure RL); ``imitation_episodes: N`` first
plays N episodes of a scripted teacher (:mod:`~crowdnav.agents.sarl.imitation`, RL + demonstrations) and
regresses V on their discounted returns for ``imitation_epochs`` passes before V-learning starts (epsilon decays
from there). With several worlds the first N episodes to start are the teacher's, each world's teacher reading
that world's simulator; episodes that start while they run are the agent's own (their transitions join the
memory, V-learning waits for the imitation).

Options (``algo_kwargs``): :data:`DEFAULTS`. ``gamma`` (default 0.9) is the discount per second at full speed,
as SARL's; ``learning_rate`` (default 1e-3) Adam's, constant, or with ``learning_rate_schedule: linear`` falling
linearly to 0 at the episode budget (a resume with a larger budget stretches it, as SB3's schedules).
``ensemble: K`` values a state by the mean of K value networks initialised apart
(:class:`~crowdnav.agents.sarl.network.ValueEnsemble`), each regressing on the same minibatches and target.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np
import torch
from crowdnav.agents.sarl.files import load_weights, read_state, refuse
from crowdnav.agents.sarl.imitation import Demonstrations, make_teacher, world_simulators
from crowdnav.agents.sarl.lookahead import (
    FEATURE_SCALE,
    GEODESIC_KEY,
    OPTIONAL_KEYS,
    REQUIRED_KEYS,
    ROBOT_FEATURES,
    STATIC_KEY,
    Physics,
    action_set,
    backup,
    bounded_weights,
    decode,
    deepen,
    features,
    lookahead,
    value_ceiling,
)
from crowdnav.agents.sarl.memory import ReplayMemory
from crowdnav.agents.sarl.network import ValueEnsemble, ValueNetwork, evaluate, value_network
from crowdnav.agents.sarl.options import check_options, check_sizes
from crowdnav.agents.sarl.sensing import check_shapes, check_world
from crowdnav.agents.sb3.factory import observation_normalization
from crowdnav.agents.training.algorithm_protocol import AgentState
from crowdnav.agents.training.config import ConfigError
from crowdnav.agents.training.run_loop import torch_threads

if TYPE_CHECKING:
    from stable_baselines3.common.vec_env import VecEnv

DEFAULTS: dict[str, Any] = {
    "width": 64,  # hidden layer size of every MLP of the value network
    "batch_size": 100,
    "updates_per_episode": 25,  # minibatches after each episode
    "target_update_every": 50,  # episodes between copies into the target network
    "memory_size": 50_000,  # transitions
    "epsilon_start": 0.5,
    "epsilon_end": 0.1,
    "epsilon_decay_episodes": 1000,
    "imitation_episodes": 0,  # teacher episodes before V-learning (0: pure RL)
    "imitation_teacher": "predictive",  # crowdnav.agents.sarl.imitation.TEACHERS
    "imitation_epochs": 50,  # passes of the value regression over the demonstrations
    "lookahead_depth": 1,  # greedy actions (evaluation): 1 step as SARL; 2 refines the best actions one step further
    "lookahead_width": 8,  # depth 2: how many of the best one-step actions are expanded
    "ensemble": 1,  # value networks averaged (1: one network, as the published runs)
    "value_bound": False,  # V capped by the largest return reachable from the goal distance (lookahead.value_ceiling)
    "human_margin": 0.0,  # m: a move predicted to pass a tracked human closer than this counts as a collision when acting
}
"""The agent's options (``algo_kwargs``) and their defaults."""
GAMMA = 0.9
LEARNING_RATE = 1e-3


class SarlAgent:
    """Implements crowdnav.agents.training.algorithm_protocol.Algorithm; ``SarlAgent(env, config)`` is the builder."""

    def __init__(self, env: VecEnv, config: Any):
        name = config.algo
        space, scenario = env.observation_space, env.get_attr("scenario")[0]
        spaces = space.spaces if isinstance(space, gym.spaces.Dict) else {}
        missing = [key for key in REQUIRED_KEYS if key not in spaces]
        if missing:
            raise ConfigError(f"modalities: algorithm {name!r} reads humans, goal and velocity; add {', '.join(missing)}")
        if scenario.robot.kinematics != "holonomic":
            raise ConfigError(f"scenario: algorithm {name!r} drives a holonomic robot; set robot.kinematics: holonomic")
        unknown = sorted(set(config.algo_kwargs) - set(DEFAULTS))
        if unknown:
            raise ConfigError(f"algo_kwargs: {name!r} has no option {unknown[0]!r}; its options: {', '.join(DEFAULTS)}")
        self.options = {**DEFAULTS, **config.algo_kwargs}
        check_options(self.options, name)
        if int(self.options["imitation_episodes"]):
            make_teacher(str(self.options["imitation_teacher"]))  # an unknown teacher is refused before the run starts
        self.physics = Physics.of_scenario(scenario, config.reward_scale)
        if self.options["value_bound"] and not bounded_weights(self.physics):
            raise ConfigError(f"algo_kwargs.value_bound: {name!r} bounds V only with step, social and collision weights <= 0 "
                              "and goal_progress, goal_reached >= 0")
        scales = observation_normalization(env) or {}
        self.scales = {key: (np.asarray(offset, dtype=np.float64), np.asarray(scale, dtype=np.float64))
                       for key, (offset, scale) in scales.items() if key in (*REQUIRED_KEYS, *OPTIONAL_KEYS)}
        self.humans = int(cast(tuple[int, ...], spaces["humans"].shape)[0])
        # the walls and furniture it reads (the obstacles modality's slots; 0: it sees no static world)
        self.statics = int(cast(tuple[int, ...], spaces[STATIC_KEY].shape)[0]) if STATIC_KEY in spaces else 0
        self.geodesic = GEODESIC_KEY in spaces  # the distance to the goal around obstacles: a 4th robot feature
        # the networks, replay memory and demonstrations these sizes make, bounded before any is allocated
        check_sizes(self.options, self.humans, self.statics, self._robot_features, int(scenario.max_steps))
        if not self.statics and _furnished(scenario):
            warnings.warn(f"algorithm {name!r} reads no walls nor furniture, and this scenario has them inside its floor: "
                          f"add the modality {STATIC_KEY!r} (docs/agents.md#agents-that-read-the-room)", UserWarning, stacklevel=2)
        if self.statics and not scenario.world.boundary_walls and not scenario.sensors.obstacles.world_edge:
            # room_sarl_crowded_open_space: 8 of its 18 failures left a world whose edge nothing it read marked
            warnings.warn(f"algorithm {name!r} reads the walls and furniture but not the world's edge, and leaving this world ends "
                          "the episode: set sensors.obstacles.world_edge: true (docs/sensors.md#obstacles)", UserWarning, stacklevel=2)
        self.gamma = float(config.gamma if config.gamma is not None else GAMMA)
        self.learning_rate = float(config.learning_rate if config.learning_rate is not None else LEARNING_RATE)
        # linear: Adam's rate falls to 0 over the run's budget (as SB3's "linear"), so the last episodes move V less
        self.decay_episodes = _decay_episodes(config)
        self.episodes = 0
        self.rng = np.random.default_rng(config.seed)
        with torch.random.fork_rng():
            torch.manual_seed(config.seed)
            self.network, self.target = self._network(), self._network()
        self._setup(ReplayMemory(int(self.options["memory_size"]), self.humans, self.statics, self._robot_features), Demonstrations())
        self.target.load_state_dict(self.network.state_dict())

    @property
    def _robot_features(self) -> int:
        return ROBOT_FEATURES + int(self.geodesic)

    def _network(self) -> ValueNetwork | ValueEnsemble:
        """A value network of this agent's options and inputs (initialised from torch's global generator)."""
        return value_network(int(self.options["width"]), int(self.options["ensemble"]), self.statics > 0, self._robot_features)

    def _setup(self, memory: ReplayMemory, demonstrations: Demonstrations) -> None:
        self.memory, self.demonstrations = memory, demonstrations
        self.teacher: Any = None
        self.actions = action_set(self.physics.max_speed)
        self.discount = self.gamma ** (self.physics.time_step * self.physics.max_speed)
        # foreach: one fused pass over the parameter list instead of one per tensor (half the step's time on CPU), same bits
        self.optimizer = torch.optim.Adam(self.network.parameters(), lr=self.learning_rate, foreach=True)

    # ------------------------------------------------------------------ acting

    @property
    def epsilon(self) -> float:
        """The exploration rate of the next training episode."""
        o = self.options
        progress = min(1.0, max(self.episodes - int(o["imitation_episodes"]), 0) / max(int(o["epsilon_decay_episodes"]), 1))
        return float(o["epsilon_start"] + (o["epsilon_end"] - o["epsilon_start"]) * progress)

    def scores(self, observation: Mapping[str, np.ndarray], depth: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """(scores (B, 81), env actions (B, 81, 2)) of a batch of observations (leading axis B), looking ``depth`` steps ahead."""
        state = decode(observation, self.scales)
        human_margin = float(self.options["human_margin"])
        ahead = lookahead(state, self.physics, self.actions, human_margin)
        scores = backup(ahead, self._value, self.discount)
        if depth > 1:
            scores = deepen(ahead, scores, int(self.options["lookahead_width"]), self._value, self.physics, self.actions, human_margin,
                            self.discount)
        return scores, ahead["commands"]

    def _value(self, state: Mapping[str, np.ndarray]) -> np.ndarray:
        """V of joint states (B, M): the network on their features, under the value ceiling with ``value_bound``."""
        values = evaluate(self.network, *features(state, self.physics))
        if self.options["value_bound"]:
            goal = state["goal"]
            values = np.minimum(values, value_ceiling(np.hypot(goal[..., 0], goal[..., 1]), self.physics, self.discount))
        return values

    def predict(self, observation: Mapping[str, np.ndarray], state: AgentState = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, AgentState]:
        """(actions, None): the best-scored move of each observation (SB3's signature; the agent has no memory)."""
        return self.act(observation, deterministic), None

    def act(self, observation: Mapping[str, np.ndarray], deterministic: bool = True) -> np.ndarray:
        """The actions of :meth:`predict`: float (2,) for one observation, (N, 2) for a batch stacked per key."""
        batched = np.ndim(observation["humans"]) == 3
        check_shapes(self, {key: np.shape(value) for key, value in observation.items()}, batched)
        batch = observation if batched else {key: np.asarray(value)[None] for key, value in observation.items()}
        # training episodes (not deterministic) act on the one-step lookahead V-learning is built on; greedy acting
        # (evaluation, rendering) may search deeper
        scores, commands = self.scores(batch, int(self.options["lookahead_depth"]) if deterministic else 1)
        choice = np.argmax(scores, axis=1)
        if not deterministic:
            explore = self.rng.random(len(choice)) < self.epsilon
            choice = np.where(explore, self.rng.integers(0, len(self.actions), size=len(choice)), choice)
        actions = commands[np.arange(len(choice)), choice]
        return actions if batched else actions[0]

    def check_world(self, observation_space: gym.spaces.Dict, scenario: Any) -> None:
        """One line (:class:`~crowdnav.agents.sarl.sensing.SensorMismatchError`) if that world senses otherwise than this agent was trained to."""
        check_world(self, observation_space, scenario)

    def export_module(self, keys: Sequence[str]) -> torch.nn.Module:
        """:meth:`predict` (deterministic) as a torch module for ONNX export (:mod:`crowdnav.agents.sarl.export`)."""
        from crowdnav.agents.sarl.export import SarlPolicyModule

        return SarlPolicyModule(self, keys)

    # ------------------------------------------------------------------ learning

    def continue_with(self, config: Any) -> None:
        """A resume: the learning-rate schedule follows the resumed run's budget (as SB3's schedules do)."""
        self.decay_episodes = _decay_episodes(config)

    def learn(self, env: VecEnv, keep_going: Callable[[], bool]) -> None:
        with torch_threads(1):  # a small network: more threads only contend (25x slower on a busy 2-core machine)
            self._learn(env, keep_going)

    def _learn(self, env: VecEnv, keep_going: Callable[[], bool]) -> None:
        """Step all worlds together; every ended episode (world order) is learnt from, then ``keep_going`` is asked."""
        worlds = env.num_envs
        observation = cast(dict[str, np.ndarray], env.reset())
        state = self._observed(observation)
        self._teaching = 0  # demonstrations under way (a resume starts every world afresh)
        teaching = np.array([self._starts_demonstration() for _ in range(worlds)])
        shown: list[tuple[list[tuple[np.ndarray, ...]], list[float]]] = [([], []) for _ in range(worlds)]
        while True:
            stepped, rewards, dones, infos = env.step(self._actions(env, observation, teaching))
            observation = last = cast(dict[str, np.ndarray], stepped)
            if dones.any():  # the ended worlds' last observation (the one returned is the next episode's first)
                last = {key: value.copy() for key, value in observation.items()}
                for i in np.flatnonzero(dones):
                    for key, value in infos[i]["terminal_observation"].items():
                        last[key][i] = value
            following = self._observed(last)
            for w in range(worlds):
                terminal = bool(dones[w]) and not infos[w].get("TimeLimit.truncated", False)
                now = tuple(part[w] for part in state)
                self.memory.add(now, float(rewards[w]), tuple(part[w] for part in following), terminal)
                if teaching[w]:  # the teacher's states and rewards, for its discounted returns
                    shown[w][0].append(now)
                    shown[w][1].append(float(rewards[w]))
            state = following if last is observation else self._observed(observation)
            for i in np.flatnonzero(dones):
                self._ended(shown[i] if teaching[i] else None)
                if not keep_going():
                    return
                shown[i] = ([], [])
                teaching[i] = self._starts_demonstration()

    def _observed(self, observation: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return features(decode(observation, self.scales), self.physics)

    def _starts_demonstration(self) -> bool:
        """Whether the episode a world starts now is the teacher's: fewer than ``imitation_episodes`` played or under way."""
        if self.demonstrations.episodes + self._teaching >= int(self.options["imitation_episodes"]):
            return False
        if self.teacher is None:
            self.teacher = make_teacher(str(self.options["imitation_teacher"]))
        self._teaching += 1
        return True

    def _actions(self, env: VecEnv, observation: Mapping[str, np.ndarray], teaching: np.ndarray) -> np.ndarray:
        """Every world's action: epsilon-greedy, or the teacher's (it reads that world's simulator: demonstrations only)."""
        if not teaching.any():
            return self.act(observation, deterministic=False)
        actions = np.zeros((len(teaching), 2), dtype=np.float32) if teaching.all() else self.act(observation, deterministic=False)
        simulators = world_simulators(env)
        for i in np.flatnonzero(teaching):
            actions[i] = np.asarray(self.teacher(simulators[i]), dtype=np.float32)
        return actions

    def _ended(self, shown: tuple[list[tuple[np.ndarray, ...]], list[float]] | None) -> None:
        """What an ended episode teaches: V-learning, or (``shown``: the teacher's states and rewards) the demonstrations."""
        if shown is None:
            self._train()
        else:
            self._teaching -= 1
            self.demonstrations.add_episode(*shown, self.discount)
            if self.demonstrations.episodes == int(self.options["imitation_episodes"]):
                self._imitate()
                self.target.load_state_dict(self.network.state_dict())
        self.episodes += 1
        if self.episodes % int(self.options["target_update_every"]) == 0:
            self.target.load_state_dict(self.network.state_dict())

    def _imitate(self) -> None:
        """Regress V on the demonstrations' discounted returns (``imitation_epochs`` shuffled passes)."""
        robot, humans, statics, returns = (torch.from_numpy(array) for array in self.demonstrations.arrays())
        size = int(self.options["batch_size"])
        for _ in range(int(self.options["imitation_epochs"])):
            order = torch.from_numpy(self.rng.permutation(len(returns)))
            for start in range(0, len(order), size):
                index = order[start:start + size]
                self._step(self._loss((robot[index], humans[index], statics[index]), returns[index]))

    def _loss(self, state: tuple[torch.Tensor, ...], target: torch.Tensor) -> torch.Tensor:
        """Mean squared error of V(state) against ``target``; an ensemble: each member's, summed (each learns as one network)."""
        if isinstance(self.network, ValueEnsemble):
            return ((self.network.each(*state) - target[None]) ** 2).mean(dim=1).sum()
        return torch.nn.functional.mse_loss(self.network(*state), target)

    def _learning_rate(self) -> float:
        """Adam's rate for the updates after the episode now ending: constant, or falling linearly to 0 at the budget."""
        if self.decay_episodes is None:
            return self.learning_rate
        return self.learning_rate * max(0.0, 1.0 - (self.episodes + 1) / self.decay_episodes)

    def _step(self, loss: torch.Tensor) -> None:
        self.optimizer.zero_grad()
        loss.backward()
        self.optimizer.step()

    def _train(self) -> None:
        size = int(self.options["batch_size"])
        if self.memory.size < size:
            return
        if self.decay_episodes is not None:
            for group in self.optimizer.param_groups:
                group["lr"] = self._learning_rate()
        for _ in range(int(self.options["updates_per_episode"])):
            batch = {key: torch.from_numpy(value) for key, value in self.memory.sample(self.rng, size).items()}
            with torch.no_grad():
                following = self.target(batch["next_robot"], batch["next_humans"], batch["next_statics"])
                if self.options["value_bound"]:  # the features' first column is the goal distance, scaled
                    distance = batch["next_robot"][:, 0].numpy().astype(np.float64) / FEATURE_SCALE
                    ceiling = torch.from_numpy(value_ceiling(distance, self.physics, self.discount).astype(np.float32))
                    following = torch.minimum(following, ceiling)
                target = batch["reward"] + self.discount * (1.0 - batch["terminal"]) * following
            self._step(self._loss((batch["robot"], batch["humans"], batch["statics"]), target))

    # ------------------------------------------------------------------ checkpoints

    def save(self, folder: Path) -> None:
        arrays = {f"network.{key}": value.numpy() for key, value in self.network.state_dict().items()}
        arrays.update({f"target.{key}": value.numpy() for key, value in self.target.state_dict().items()})
        optimizer = self.optimizer.state_dict()
        for index, state in optimizer["state"].items():
            arrays.update({f"adam.{index}.{key}": torch.as_tensor(value).numpy() for key, value in state.items()})
        np.savez(folder / "weights.npz", **arrays)
        self.memory.save(folder / "memory.npz")
        self.demonstrations.save(folder / "demonstrations.npz")
        document = {"options": self.options, "physics": self.physics.to_json(), "humans": self.humans, "statics": self.statics,
                    "geodesic": self.geodesic,
                    "gamma": self.gamma,
                    "learning_rate": self.learning_rate, "decay_episodes": self.decay_episodes, "episodes": self.episodes,
                    "rng": self.rng.bit_generator.state,
                    "scales": {key: {"offset": offset.tolist(), "scale": scale.tolist()} for key, (offset, scale) in self.scales.items()},
                    "adam_groups": [{key: value for key, value in group.items() if key != "params"} for group in optimizer["param_groups"]]}
        (folder / "state.json").write_text(json.dumps(document), encoding="utf-8")

    @classmethod
    def load(cls, folder: Path) -> SarlAgent:
        """The agent saved in ``folder``; every file is checked first (:mod:`crowdnav.agents.sarl.files`): one line naming it."""
        path = folder / "state.json"
        document = read_state(path, "sarl", DEFAULTS)
        agent = cls.__new__(cls)
        # options added since a checkpoint was written take their defaults (the behaviour it was trained with)
        agent.options, agent.humans = {**DEFAULTS, **document["options"]}, int(document["humans"])
        agent.statics = int(document.get("statics", 0))  # checkpoints from before the room was read: none
        agent.geodesic = bool(document.get("geodesic", False))
        try:
            check_sizes(agent.options, agent.humans, agent.statics, agent._robot_features, None, "options")
        except ConfigError as error:
            refuse(path, str(error))
        agent.physics = Physics.from_json(document["physics"])
        agent.gamma, agent.learning_rate, agent.episodes = float(document["gamma"]), float(document["learning_rate"]), int(document["episodes"])
        agent.decay_episodes = document.get("decay_episodes")  # absent in checkpoints from before the schedule: constant
        agent.scales = {key: (np.asarray(item["offset"], dtype=np.float64), np.asarray(item["scale"], dtype=np.float64))
                        for key, item in document["scales"].items()}
        agent.rng = np.random.default_rng()
        try:
            agent.rng.bit_generator.state = document["rng"]
        except (TypeError, ValueError, KeyError, OverflowError) as error:
            refuse(path, f"rng: not a {type(agent.rng.bit_generator).__name__} state ({str(error)[:80]})")
        agent.network, agent.target = agent._network(), agent._network()
        adam = load_weights(folder / "weights.npz", agent.network, agent.target)
        agent._setup(ReplayMemory.load(folder / "memory.npz", int(agent.options["memory_size"]), agent.humans, agent.statics,
                                       agent._robot_features),
                     Demonstrations.load(folder / "demonstrations.npz", agent.humans, agent.statics, agent._robot_features,
                                         int(agent.options["imitation_episodes"])))
        groups = agent.optimizer.state_dict()["param_groups"]
        try:
            for group, saved in zip(groups, document["adam_groups"], strict=True):
                group.update({key: tuple(value) if isinstance(value, list) else value for key, value in saved.items()})
            agent.optimizer.load_state_dict({"state": adam, "param_groups": groups})
        except (TypeError, ValueError, KeyError, RuntimeError) as error:
            refuse(path, f"adam_groups: not the state of this agent's optimiser ({str(error).splitlines()[0][:80] if str(error) else 'malformed'})")
        return agent

def _decay_episodes(config: Any) -> int | None:
    """``learning_rate_schedule: linear``: the episode budget Adam's rate falls to 0 over (None: a constant rate)."""
    if config.learning_rate_schedule != "linear":
        return None
    if config.episodes is None:
        raise ConfigError(f"learning_rate_schedule: {config.algo!r} decays over an episode budget; set episodes, not timesteps")
    return int(config.episodes)


def _furnished(scenario: Any) -> bool:
    """Whether walls, furniture or a floor outline stand where the robot may drive (boundary walls alone do not count)."""
    return bool(scenario.walls or scenario.furniture or scenario.world.points is not None)
