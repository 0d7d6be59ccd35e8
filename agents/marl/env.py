"""The robots of a multi-robot scenario as the robots' vector env and one shared network take them (``agents: robots``).

:class:`RobotsTrainingEnv` is a PettingZoo ParallelEnv over crowdnav's robots-only env
(``crowdnav.parallel_env(..., humans_as_agents=False, fixed_agents=True, flat_observations=True)``):
every robot is an agent every step (a robot that ended is inactive: zero observation, reward 0),
the humans follow the scenario's crowd model. :class:`crowdnav.agents.marl.vec_env.RobotsVecEnv`
plays ``num_envs`` such worlds as one SB3 vector env through one engine (:mod:`crowdnav.envs.engines.robots`),
with the same additions, row for row and bit for bit (this env per world is its reference in the tests, and
what SuperSuit's chain takes). What it adds for shared-parameter training:

* **observations** through :class:`RobotObservations`: each modality scaled by the scale it
  declares (as the single-agent runs' ``normalize_observations``), then, with
  ``agent_identity``, a one-hot of the robot's index, so one network can act for robots of
  different kinematics or speeds;
* **actions** through :class:`crowdnav.agents.marl.actions.RobotActions` (``robot_actions``):
  each robot's own action (native), or a desired velocity in its own or its goal's frame, which
  a unicycle tracks;
* **training seeds**: world ``w`` of ``B`` plays its ``k``-th episode with
  :func:`crowdnav.agents.training.seeding.train_seed` ``(seed, first_episode + k * B + w)``, whatever seed
  the caller passes: the training band, never a held-out test seed, the same for the same seed;
* **infos**: ``episode_seed`` on every robot at every step (not at reset: the vector env merges the
  next episode's reset infos into the last step's), and SB3's ``TimeLimit.truncated`` when the episode
  hits the time limit (so PPO bootstraps the value there rather than treating it as an end).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from crowdnav.agents.marl.actions import RobotActions
from crowdnav.agents.training.config import ConfigError
from crowdnav.agents.training.seeding import MAX_TRAIN_EPISODES, train_seed
from crowdnav.agents.training.wrappers import declared_scales
from gymnasium import spaces
from pettingzoo.utils.env import ParallelEnv

from crowdnav.envs import CrowdNavParallelEnv, parallel_env


class RobotsConfigError(ConfigError):
    """A scenario or option that shared-parameter robot training cannot take (one line)."""


def robots_env(options: Mapping[str, Any]) -> CrowdNavParallelEnv:
    """The robots-only, fixed-agent, flat-observation PettingZoo env of ``options`` (CrowdNavEnv's keyword arguments)."""
    env = parallel_env(**options, humans_as_agents=False, fixed_agents=True, flat_observations=True)
    if env.simulator.team is None:
        env.close()
        raise RobotsConfigError(f"agents: robots needs a scenario with several robots (robots:), and {options['scenario']!r} has one; "
                                "train it with agents: robot")
    return env


class RobotObservations:
    """A robot's flat observation -> the shared network's input: declared scales applied, the robot's one-hot appended.

    Every robot must observe the same modalities (one network reads them all); the scales are
    those the modalities declare (:meth:`crowdnav.sensors.Modality.scale`), fixed numbers that
    travel with the checkpoint's ``policy.json``.
    """

    def __init__(self, env: CrowdNavParallelEnv, *, normalize: bool, identity: bool):
        robots = env.core.robot_names
        shapes = {name: env.core.robot_spaces[k] for k, name in enumerate(robots)}
        first = shapes[robots[0]]
        differing = [name for name, space in shapes.items() if space != first]
        if differing:
            other = shapes[differing[0]]
            keys = [key for key in {**first.spaces, **other.spaces} if first.spaces.get(key) != other.spaces.get(key)]
            raise RobotsConfigError(f"agents: robots trains one network for every robot, but {differing[0]!r} and {robots[0]!r} "
                                    f"observe {keys} differently (other modalities, sensor settings or, for velocity, "
                                    "kinematics); give the robots the same observation")
        self.robots = list(robots)
        self.identity = bool(identity)
        size = int(spaces.flatdim(first))
        self.offset = np.zeros(size, np.float32)
        self.scale = np.ones(size, np.float32)
        if normalize:  # flattened in the Dict's key order, as the env flattens its observations
            declared = declared_scales(env.core.modalities)
            # keys without a declared scale (the uint8 grid) pass unscaled
            ones = {key: (np.zeros(space.shape or (), np.float32), np.ones(space.shape or (), np.float32)) for key, space in first.spaces.items()}
            pairs = {key: declared.get(key, ones[key]) for key in first.spaces}
            self.offset = np.asarray(spaces.flatten(first, {key: pair[0] for key, pair in pairs.items()}), np.float32)
            self.scale = np.asarray(spaces.flatten(first, {key: pair[1] for key, pair in pairs.items()}), np.float32)
        width = size + (len(self.robots) if self.identity else 0)
        self.space = spaces.Box(-np.inf, np.inf, shape=(width,), dtype=np.float32)

    def __call__(self, index: int, flat: np.ndarray, active: bool = True) -> np.ndarray:
        """Robot ``index``'s input; an inactive robot's stays all zero (PettingZoo's "black death" for an agent that left)."""
        scaled = (np.asarray(flat, np.float32) - self.offset) / self.scale if active else np.zeros_like(self.offset)
        if not self.identity:
            return scaled.astype(np.float32, copy=False)
        one_hot = np.zeros(len(self.robots), np.float32)
        one_hot[index] = 1.0
        return np.concatenate([scaled, one_hot]).astype(np.float32, copy=False)

    def rows(self, flat: np.ndarray, active: np.ndarray) -> np.ndarray:
        """:meth:`__call__` of every robot of many worlds: ``flat`` (W, R, D) raw observations, ``active`` (W, R) bool ->
        (W * R, inputs) float32, row ``w * R + k`` robot ``k`` of world ``w`` (the same elementwise float32 operations)."""
        scaled = (np.asarray(flat, np.float32) - self.offset) / self.scale
        scaled = np.where(active[..., None], scaled, np.float32(0.0)).astype(np.float32, copy=False)
        if self.identity:
            one_hot = np.broadcast_to(np.eye(len(self.robots), dtype=np.float32), (*scaled.shape[:2], len(self.robots)))
            scaled = np.concatenate([scaled, one_hot], axis=2)
        return scaled.reshape(-1, scaled.shape[2])

    @classmethod
    def from_json(cls, document: Mapping[str, Any]) -> RobotObservations:
        """The settings :meth:`to_json` stored with a checkpoint (what a loaded policy applies)."""
        inputs = cls.__new__(cls)
        inputs.robots = list(document["robots"])
        inputs.identity = bool(document["identity"])
        inputs.offset = np.asarray(document["offset"], np.float32)
        inputs.scale = np.asarray(document["scale"], np.float32)
        width = len(inputs.offset) + (len(inputs.robots) if inputs.identity else 0)
        inputs.space = spaces.Box(-np.inf, np.inf, shape=(width,), dtype=np.float32)
        return inputs

    def to_json(self) -> dict[str, Any]:
        return {"robots": self.robots, "identity": self.identity, "offset": self.offset.tolist(), "scale": self.scale.tolist()}

    def matches(self, document: Mapping[str, Any]) -> bool:
        """Whether a checkpoint's stored observation settings are these (a scenario edited since would differ)."""
        return (list(document["robots"]) == self.robots and bool(document["identity"]) == self.identity
                and np.array_equal(np.asarray(document["offset"], np.float32), self.offset)
                and np.array_equal(np.asarray(document["scale"], np.float32), self.scale))


class RobotsTrainingEnv(ParallelEnv):  # type: ignore[misc]  # pettingzoo is untyped
    """Robots-only crowdnav env with the shared network's observations and training-band seeds (module docstring)."""

    metadata = {"name": "crowdnav_robots_v0", "is_parallelizable": True}

    def __init__(self, options: Mapping[str, Any], *, normalize: bool, identity: bool, run_seed: int, first_episode: int = 0,
                 actions: str = "native"):
        self.env = robots_env(options)
        self.inputs = RobotObservations(self.env, normalize=normalize, identity=identity)
        self.commands = RobotActions.for_env(actions, self.env)
        """The network's actions -> each robot's env action (``robot_actions``; native: unchanged)."""
        self.observed: Mapping[str, np.ndarray] = {}
        """The raw observations the network acts on next (goal_velocity reads each robot's goal direction there)."""
        self.possible_agents = list(self.env.possible_agents)
        self.agents: list[str] = []
        self.render_mode = None
        self.run_seed, self.first_episode = int(run_seed), int(first_episode)
        self.world, self.worlds, self.played = 0, 1, 0
        self.episode_seed: int | None = None
        self.actions: list[np.ndarray] | None = []
        """Every robot's action from the network (rows in ``possible_agents`` order) at each step since this episode's reset, what a
        resumable checkpoint replays (:mod:`crowdnav.agents.marl.resume`); None after a step that did not act for every robot."""

    def assign_world(self, world: int, worlds: int) -> None:
        """This env is world ``world`` of ``worlds`` (set on every world before the first reset: it numbers their episodes)."""
        self.world, self.worlds = int(world), int(worlds)

    @property
    def next_episode(self) -> int:
        """The episode number this world starts next."""
        return self.first_episode + self.played * self.worlds + self.world

    def observation_space(self, agent: str) -> spaces.Space[Any]:
        return self.inputs.space

    def action_space(self, agent: str) -> spaces.Space[Any]:
        return self.env.action_space(agent)

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        # the caller's seed (or none, at an autoreset) is replaced: every episode's seed comes from the run's band
        episode = self.next_episode
        if episode >= MAX_TRAIN_EPISODES:
            raise RuntimeError(f"a run may start at most {MAX_TRAIN_EPISODES:,} training episodes (crowdnav.agents.training.seeding)")
        self.played += 1
        self.episode_seed = train_seed(self.run_seed, episode)
        observations, infos = self.env.reset(seed=self.episode_seed)
        self.observed = observations
        self.agents = list(self.env.agents)
        self.actions = []
        return self._inputs(observations, infos), infos  # no episode_seed here: an autoreset's infos are merged over the last step's

    def step(self, actions: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any], dict[str, Any], dict[str, Any]]:
        if self.actions is not None and all(name in actions for name in self.possible_agents):
            self.actions.append(np.stack([actions[name] for name in self.possible_agents]))
        else:  # the vector env acts for every robot each step (fixed agents); another caller may not, and cannot be replayed
            self.actions = None
        observations, rewards, terminations, truncations, infos = self.env.step(self.commands(actions, self.possible_agents, self.observed))
        self.observed = observations
        self.agents = list(self.env.agents)
        truncated = any(truncations.values()) and not all(terminations.values())
        return self._inputs(observations, infos), rewards, terminations, truncations, self._tag(infos, truncated)

    def replay(self, first_episode: int, played: int, actions: np.ndarray) -> dict[str, np.ndarray]:
        """Rebuild this world mid-episode: its counters as they were, its episode's reset, then ``actions`` (steps, robots, 2).

        The simulator's generator, seeded at reset, is an episode's only randomness, so this is the
        world bit for bit; returns the observations the last step gave (the reset's for no steps).
        """
        self.first_episode, self.played = int(first_episode), int(played) - 1
        observations, _ = self.reset()
        for step in actions:
            observations = self.step({name: step[k] for k, name in enumerate(self.possible_agents)})[0]
        return observations

    def _inputs(self, observations: Mapping[str, np.ndarray], infos: Mapping[str, Mapping[str, Any]]) -> dict[str, np.ndarray]:
        return {name: self.inputs(k, observations[name], bool(infos[name].get("active", True)))
                for k, name in enumerate(self.possible_agents)}

    def _tag(self, infos: dict[str, dict[str, Any]], truncated: bool) -> dict[str, dict[str, Any]]:
        for name in self.possible_agents:
            infos[name]["episode_seed"] = self.episode_seed
            if truncated:
                infos[name]["TimeLimit.truncated"] = True
        return infos

    def close(self) -> None:
        self.env.close()
