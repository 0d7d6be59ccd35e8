"""The multi-agent environment (PettingZoo ParallelEnv): every robot, and (by default) every human, is an agent."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeAlias, cast

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from crowdnav.envs.core import EnvCore, ScenarioSource, checked_robot_action, real_array, step_info
from crowdnav.envs.human_observation import HumanObservations
from crowdnav.envs.multi_agent import (
    HumanExit,
    HumanReward,
    agent_list,
    flat_spaces,
    flatten_batch,
    global_state,
    state_space,
    unknown_agent,
)
from crowdnav.rendering.episode_view import RENDER_MODES

ROBOT = "robot"

AgentObservation: TypeAlias = Any
"""One agent's observation: a dict of arrays, or (``flat_observations``) one float32 array. Any, not their union:
which one is the env's option, so each caller reads the kind it asked for without narrowing every value."""
Infos: TypeAlias = dict[str, dict[str, Any]]
"""Each agent's info (outcome, reward terms, group, ...: values of several kinds)."""
StepReturn: TypeAlias = tuple[dict[str, AgentObservation], dict[str, float], dict[str, bool], dict[str, bool], Infos]
"""PettingZoo's (observations, rewards, terminations, truncations, infos), each keyed by agent."""


class CrowdNavParallelEnv(ParallelEnv):  # type: ignore[misc]  # pettingzoo has no type information
    """Robot and humans as PettingZoo agents, stepped together.

    **Agents.** ``possible_agents`` is ``["robot", "human_0", ..., "human_{N-1}"]`` with N the
    scenario's maximum crowd size. With a crowd-size range, ``agents`` after reset holds the
    robot and ``human_<i>`` for ``i <`` this episode's crowd size (``fixed_agents`` below
    changes that). PettingZoo's ``parallel_api_test`` warns "No agents present but not all
    possible_agents are terminated or truncated" for such an episode: it expects every possible
    agent to enter ``agents`` at some point, which a human absent this episode never does.

    **Fixed agent set** (``fixed_agents=True``, for SuperSuit's ``pettingzoo_env_to_vec_env_v1``
    and MARL tools that need the same agents every step): ``agents`` is ``possible_agents``
    from reset to the episode end, whatever this episode's crowd size. A human is *active*
    while it is in this episode's crowd and has not left through ``human_exit``; an inactive
    one has an all-zero observation (its ``active`` entry 0: the first value of the flat vector
    with ``flat_observations``), ``infos[name]["active"]`` False, reward 0, and its action is
    checked but has no effect. A human that exits stays an agent: the step it exits on gives
    its last real observation, the following steps the inactive one. No human terminates
    alone: every agent terminates or truncates at the episode end. Active humans' observations
    carry ``active`` 1; the robot is always active (its observation has no such entry).

    **Robot.** Observation: the same Dict as :class:`crowdnav.envs.single.CrowdNavEnv` (one
    key per modality); action: Box(-1, 1, (2,), float32), (vx, vy) in the robot frame times the
    robot's max speed (holonomic) or (v, omega) (unicycle); out-of-range values are clipped;
    NaN, inf or None raises ValueError (naming the robot). Reward: the terms of :mod:`crowdnav.envs.reward`, listed in
    ``infos["robot"]["reward_terms"]``; at the episode end ``infos["robot"]`` also holds
    ``outcome``, ``is_success`` and, after a collision, ``collision_kind`` / ``collision_partner``.

    **Humans.** Observation: a Dict of fixed-size float32 arrays, world frame, described in
    :mod:`crowdnav.envs.human_observation` (own state, other humans padded to N-1 with a mask,
    nearest point of each static obstacle, and the robot when the scenario's ``see_robot`` is
    on). Action: Box(-1, 1, (2,), float32), the velocity command in the world frame divided by
    the human's max speed (``max_speed`` in its observation). :class:`SocialForcePolicy` gives
    the built-in crowd's actions; members of a standing group (``behaviour: stand``) stay where
    they are whatever their action. Reward: 0, or ``human_reward(simulator)``. Info: ``group``
    (the name of its group, ``crowd`` for a file without ``humans.groups``; also at reset;
    None for a human absent this episode under ``fixed_agents``), ``goal_reached`` (it reached
    its goal this step) and, under ``fixed_agents`` only, ``active``.

    **Episode end.** Success, collision or the robot leaving the world terminates every agent,
    the time limit truncates every agent. A human also terminates alone when ``human_exit``
    says so; it then stands still, an obstacle for the others, until the episode ends. As in
    :class:`crowdnav.envs.single.CrowdNavEnv`, the robot cannot escape the task: leaving the
    world (its centre outside the ``world.min`` / ``world.max`` rectangle) is either impossible
    (``world.boundary_walls``: touching the walls is a collision) or ends the episode with
    ``infos["robot"]["outcome"] == "out_of_bounds"`` (open space), paying the ``collision`` term.

    **Several robots** (a scenario with ``robots:``, docs/environments.md#several-robots): each
    robot is an agent named after it (``robots.<i>.name``, default ``robot_<i>``; one robot keeps
    the name ``robot``), listed first in ``possible_agents``, with its own observation (its own
    modalities, in its own frame; its range sensors see the other robots, its ``humans``
    modality the humans only), action space (its own kinematics), reward terms and ``infos``
    (``outcome``, ``is_success``, ``collision_kind`` ``robot`` with the other robot's name as
    ``collision_partner``). A robot whose step ends (success, collision, out of the world) is
    terminated and leaves ``agents`` and the world (it no longer blocks or is seen); the others
    go on. The episode ends when every robot has ended (the humans then terminate) or at the
    time limit (everyone truncates). Under ``fixed_agents`` a robot that ended stays an agent,
    inactive like an absent human: its step's infos carry its outcome, later steps give an
    all-zero observation, reward 0 and ``infos[name]["active"]`` False (every robot's info has
    ``active`` under ``fixed_agents``), and it terminates with everyone at the episode end.

    **Robots only** (``humans_as_agents=False``): the agents are the robots; the humans are
    moved by the scenario's crowd model (social force or ORCA), as in the Gymnasium env. With
    ``fixed_agents=True`` and ``flat_observations=True`` this is the mode SuperSuit's
    ``pettingzoo_env_to_vec_env_v1`` takes for shared-parameter training of the robots.

    **Multi-agent plumbing** (:mod:`crowdnav.envs.multi_agent`): ``state()`` / ``state_space``,
    the global state for centralised critics; ``flat_observations=True`` gives every agent a flat
    float32 Box observation (for SuperSuit and MARL libraries); ``human_reward`` and
    ``human_exit`` plug in the humans' reward and individual termination.

    Other options are those of :class:`crowdnav.envs.core.EnvCore` (``modalities``, ``sensors``,
    ``reward_weights``, ``overrides``, ``render_mode`` (None, ``"rgb_array"`` or ``"human"``) and
    ``render_options``).
    """

    metadata = {"name": "crowdnav_v0", "render_modes": RENDER_MODES, "render_fps": 5.0, "is_parallelizable": True}

    def __init__(
        self,
        scenario: ScenarioSource | None = None,
        *,
        flat_observations: bool = False,
        human_reward: HumanReward | None = None,
        human_exit: HumanExit | None = None,
        fixed_agents: bool = False,
        humans_as_agents: bool = True,
        **options: Any,
    ):
        # The engine both envs share (simulator, sensors, reward); it takes and checks the options.
        self.core = EnvCore(scenario, **options)
        self.flat_observations = bool(flat_observations)
        self.fixed_agents = bool(fixed_agents)
        self.humans_as_agents = bool(humans_as_agents)
        if not self.humans_as_agents and (human_reward is not None or human_exit is not None):
            raise ValueError("human_reward and human_exit need the humans as agents; drop them or keep humans_as_agents=True")
        self.human_reward, self.human_exit = human_reward, human_exit
        self.render_mode = self.core.render_mode
        self.scenario = self.core.scenario
        self.simulator = self.core.simulator
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.scenario.time_step}
        self._humans = HumanObservations(self.scenario, self.simulator.obstacles, active_flag=self.fixed_agents)
        self._human_names = [f"human_{i}" for i in range(self.scenario.humans.max_count)] if self.humans_as_agents else []
        self._robot_names = self.core.robot_names
        self._several = self.simulator.team is not None
        self.possible_agents = [*self._robot_names, *self._human_names]
        self.agents: list[str] = []
        self._dict_spaces = dict(zip(self._robot_names, self.core.robot_spaces, strict=True))
        self._dict_spaces.update({name: self._humans.space() for name in self._human_names})
        self.observation_spaces: dict[str, spaces.Space[Any]] = dict(self._dict_spaces)
        if self.flat_observations:
            self.observation_spaces = dict(flat_spaces(self._dict_spaces))
        self.state_space = state_space(self.scenario.humans.max_count, len(self._robot_names))
        self.action_spaces = {name: spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32) for name in self._robot_names}
        self.action_spaces.update({name: spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32) for name in self._human_names})
        self._active_humans: list[str] = []
        self._active_robots: list[str] = []

    def state(self) -> np.ndarray:
        """The global state (:mod:`crowdnav.envs.multi_agent`): (R + N) rows of x, y, vx, vy, gx, gy, radius, active."""
        return global_state(self.simulator, self.scenario.humans.max_count)

    def observation_space(self, agent: str) -> spaces.Space[Any]:
        """``agent``'s observation space (an unknown name: a one-line KeyError listing the agents)."""
        if agent not in self.observation_spaces:
            raise unknown_agent(agent, self.possible_agents)
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Space[Any]:
        """``agent``'s action space (an unknown name: a one-line KeyError listing the agents)."""
        if agent not in self.action_spaces:
            raise unknown_agent(agent, self.possible_agents)
        return self.action_spaces[agent]

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict[str, AgentObservation], Infos]:
        """Start an episode; the same seed gives the same episode. ``options`` is accepted and unused."""
        robot_observation = self.core.reset(seed)
        self._humans.reset(self.simulator)
        self._active_humans = self._human_names[: self.simulator.n_humans]
        self._active_robots = list(self._robot_names)
        self.agents = list(self.possible_agents) if self.fixed_agents else [*self._robot_names, *self._active_humans]
        observations = self._observations(robot_observation)
        sim = self.simulator  # a human's group is fixed for the episode: named once here
        self._group_of = dict(zip(self._active_humans, (sim.groups[g].name for g in sim.human_group.tolist()), strict=self.humans_as_agents))
        if self.fixed_agents:
            infos = {name: {"group": self._group_of.get(name), "active": name in self._group_of} for name in self._human_names}
        else:
            infos = {name: {"group": group} for name, group in self._group_of.items()}
        robot_info: dict[str, Any] = {"active": True} if self.fixed_agents and self._several else {}
        return observations, {**{name: dict(robot_info) for name in self._robot_names}, **infos}

    def loaded_robots(self, running: bool) -> None:
        """After ``self.core.load`` of a robots-only world (every robot driven, humans not agents): the robots still in the
        world act, until the episode ends (``running``); what :meth:`reset` and :meth:`step` keep of an episode's agents."""
        team = self.simulator.team
        if team is None or self.humans_as_agents:
            raise ValueError("loaded_robots: a robots: scenario's env whose humans are not agents (the robots engines')")
        self._active_robots = [name for name, here in zip(self._robot_names, team.state.active.tolist(), strict=True) if here]
        self.agents = list(self.possible_agents) if running else []

    def step(self, actions: Mapping[str, Any]) -> StepReturn:
        """One action per agent in ``agents``; out-of-range values are clipped, NaN/inf raise ValueError."""
        if not isinstance(actions, Mapping):
            raise TypeError(f"step() takes a dict {{agent: action}} with one action per agent in env.agents, got {type(actions).__name__}")
        if not self.agents:
            raise RuntimeError("the episode is over or has not started: call reset() before step()")
        human_actions: np.ndarray | None = self._human_actions(actions)  # checks every agent's action, the robots' keys too
        if not self.humans_as_agents:
            human_actions = None  # the scenario's crowd model moves them
        if self._several:
            return self._step_robots(actions, human_actions)
        events, reward, terms = self.core.step(actions[ROBOT], human_actions)
        agents = self.agents
        observations = self._observations(self.core.observe())
        rewards = dict.fromkeys(agents, 0.0)
        rewards[ROBOT] = reward
        terminated = events.terminated
        truncated = events.truncated and not terminated
        terminations, truncations = dict.fromkeys(agents, terminated), dict.fromkeys(agents, truncated)
        infos: Infos = {agent: {} for agent in agents}
        infos[ROBOT] = step_info(events, terms)
        self._step_humans(rewards, terminations, infos, terminated, truncated)
        if terminated or truncated:
            self.agents = []
        return observations, rewards, terminations, truncations, infos

    def _step_robots(self, actions: Mapping[str, Any], human_actions: np.ndarray | None) -> StepReturn:
        """:meth:`step` with several robots: each its own outcome; the episode ends when every robot's has."""
        robots, fixed = self._robot_names, self.fixed_agents
        was_active = list(self._active_robots)
        results = self.core.step_robots([self._robot_action(actions, name) if name in was_active else None for name in robots], human_actions)
        agents = self.agents
        ended = [name for name, result in zip(robots, results, strict=True) if result is not None and result[0].terminated]
        still = [name for name in was_active if name not in ended]
        truncated = bool(still) and self.simulator.step_count >= self.scenario.max_steps  # time up while some robot runs
        over = not still or truncated
        observations = self._observations(None, was_active)
        if self.render_mode == "human":  # the one-robot path draws in core.observe()
            self.core.render()
        rewards = dict.fromkeys(agents, 0.0)
        terminations, truncations = dict.fromkeys(agents, False), dict.fromkeys(agents, False)
        for name in self._human_names:  # the humans end with the episode (or alone, by human_exit: below)
            if name in terminations:
                terminations[name], truncations[name] = over and not truncated, truncated
        infos: Infos = {agent: {} for agent in agents}
        for name, result in zip(robots, results, strict=True):
            if result is None:  # it left before this step: an agent still only under fixed_agents
                if name in terminations:
                    infos[name] = {"active": False}
                    terminations[name], truncations[name] = over and not truncated, truncated
                continue
            events, reward, terms = result
            rewards[name] = reward
            infos[name] = step_info(events, terms)
            if fixed:
                infos[name]["active"] = True
                terminations[name], truncations[name] = over and not truncated, truncated
            else:
                terminations[name] = events.terminated
                truncations[name] = truncated and not events.terminated
        if truncated:
            for name in still:
                infos[name].setdefault("outcome", "truncated")
                infos[name].setdefault("is_success", False)
        self._step_humans(rewards, terminations, infos, over and not truncated, truncated)
        if over:
            self.agents = []
            return observations, rewards, terminations, truncations, infos
        if ended:
            self.simulator.retire_robots([robots.index(name) for name in ended])
            self._active_robots = still
            if not fixed:
                self.agents = [agent for agent in self.agents if agent not in ended]
        return observations, rewards, terminations, truncations, infos

    @staticmethod
    def _robot_action(actions: Mapping[str, Any], name: str) -> np.ndarray:
        """An active robot's action, checked before the step (None is refused: only a robot that left has no action)."""
        action = actions[name]
        if action is None:
            raise ValueError(f"the action of {name} is None; an active robot needs 2 numbers in [-1, 1] (to stand still: [0, 0])")
        try:
            return checked_robot_action(action)
        except ValueError as error:
            raise ValueError(f"the action of {name}: {error}") from None

    def _step_humans(self, rewards: dict[str, float], terminations: dict[str, bool], infos: Infos,
                     terminated: bool, truncated: bool) -> None:
        """The humans' rewards, infos and exits of the step just taken (``terminated`` / ``truncated``: the episode's end)."""
        sim, fixed = self.simulator, self.fixed_agents
        if not self.humans_as_agents:
            return
        if fixed:  # inactive humans' infos; the active ones' are overwritten below
            infos.update((name, {"group": self._group_of.get(name), "goal_reached": False, "active": False}) for name in self._human_names)
        if self._active_humans:
            index = self._active_index
            arrived = sim.human_arrived[index]
            human_rewards = self.human_reward(sim)[index] if self.human_reward is not None else np.zeros(len(index))
            leaving = np.asarray(self.human_exit(sim), dtype=bool)[index] if self.human_exit is not None else np.zeros(len(index), bool)
            for k, name in enumerate(self._active_humans):
                rewards[name] = float(human_rewards[k])
                infos[name] = {"group": self._group_of[name], "goal_reached": bool(arrived[k])}
                if fixed:
                    infos[name]["active"] = True
                else:
                    terminations[name] = terminated or bool(leaving[k])
            if leaving.any() and not (terminated or truncated):
                sim.stop_humans(index[leaving])  # it stays in the world, standing
                self._active_humans = [name for name, gone in zip(self._active_humans, leaving, strict=True) if not gone]
                if not fixed:  # under fixed_agents it stays an agent, inactive from the next step on
                    self.agents = [agent for agent in self.agents if not agent.startswith("human_") or agent in self._active_humans]

    def render(self) -> np.ndarray | None:
        """The current frame in ``rgb_array`` mode (None in ``human`` mode, which draws at each step)."""
        return self.core.render() if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        self.core.close()

    @property
    def _active_index(self) -> np.ndarray:
        """Simulator indices (0-based among humans) of the humans still in ``agents``."""
        return np.array([int(name[len("human_") :]) for name in self._active_humans], dtype=int)

    def _observations(self, robot_observation: dict[str, np.ndarray] | None, robots: list[str] | None = None) -> dict[str, AgentObservation]:
        """Every agent's observation: the one robot's ``robot_observation``, or (several robots) those of ``robots``
        (default: every active robot), all-zero for the others under ``fixed_agents``."""
        observations: dict[str, AgentObservation] = {}
        if self._several:
            robots = self._active_robots if robots is None else robots
            for k, name in enumerate(self._robot_names):
                if name in robots:
                    observations[name] = self.core.observe_robot(k)
                elif self.fixed_agents:
                    boxes = self._dict_spaces[name].spaces.items()  # (a robot's Dict holds Boxes: a shape and a dtype each)
                    observations[name] = {key: np.zeros(cast(spaces.Box, box).shape, box.dtype) for key, box in boxes}
        else:
            observations[ROBOT] = robot_observation
        if self.flat_observations:
            for name in self._robot_names:
                if name in observations:
                    flat = cast(np.ndarray, spaces.flatten(self._dict_spaces[name], observations[name]))  # a Dict of Boxes flattens to an array
                    observations[name] = flat.astype(np.float32, copy=False)
        if self.fixed_agents and self._human_names:
            batch = self._humans.fixed(self.simulator, self._active_index)
            if self.flat_observations:
                rows = flatten_batch(self._dict_spaces[self._human_names[0]], batch, len(self._human_names))
                observations.update(zip(self._human_names, rows, strict=True))
            else:
                for i, name in enumerate(self._human_names):
                    observations[name] = {key: values[i] for key, values in batch.items()}
        elif self._active_humans:
            batch = self._humans.batch(self.simulator)
            index = self._active_index
            if self.flat_observations:
                rows = flatten_batch(self._dict_spaces[self._active_humans[0]], batch, self.simulator.n_humans)[index]
                observations.update(zip(self._active_humans, rows, strict=True))
            else:
                for name, i in zip(self._active_humans, index, strict=True):
                    observations[name] = {key: values[i] for key, values in batch.items()}
        return observations

    def _human_actions(self, actions: Mapping[str, Any]) -> np.ndarray:
        """The episode's humans' (n, 2) velocity commands / max speed, in simulator order, with clear errors.

        Every human in ``agents`` must have a valid action; only the active ones' move anyone.
        """
        humans = [agent for agent in self.agents if agent.startswith("human_")]
        if len(actions) != len(self.agents) or not all(name in actions for name in self.agents):
            missing = [agent for agent in self.agents if agent not in actions]
            unknown = [agent for agent in actions if agent not in self.agents]
            raise ValueError(f"expected exactly one action per agent in env.agents; missing: {missing}, not in env.agents: {unknown}; "
                             f"env.agents: {agent_list(self.agents)}")
        if not humans:
            return np.zeros((self.simulator.n_humans, 2))
        arrays = [real_array(actions[name], f"the action of {name}") for name in humans]
        shapes = {name: array.shape for name, array in zip(humans, arrays, strict=True) if array.shape != (2,)}
        if shapes:
            raise ValueError(f"every human action must be 2 numbers (vx, vy) / max_speed; wrong shapes: {shapes}")
        stacked = np.stack(arrays)
        finite = np.isfinite(stacked).all(axis=1)
        if not finite.all():
            bad = {humans[i]: stacked[i].tolist() for i in np.flatnonzero(~finite)}
            raise ValueError(f"human actions must be finite (no NaN or inf), got {bad}")
        index = self._active_index
        if not self.fixed_agents and len(humans) == self.simulator.n_humans:
            return stacked
        commands = np.zeros((self.simulator.n_humans, 2))  # humans that left stand still
        # rows of ``stacked``: the active humans in order, or every possible human (fixed_agents)
        commands[index] = stacked[index] if self.fixed_agents else stacked
        return commands
