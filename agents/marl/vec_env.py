"""The robots of ``num_envs`` worlds as one Stable-Baselines3 ``VecEnv``: one row per robot per world (``agents: robots``).

:class:`RobotsVecEnv` holds the run's worlds, each a
:class:`crowdnav.agents.marl.env.RobotsTrainingEnv` (crowdnav's robots-only env with the shared
network's observations, actions and training seeds), and steps them in one call. Row ``w * R + k``
is robot ``k`` (the scenario's order) of world ``w``; the observations are float32
``(num_envs * R, inputs)``, rewards float32, dones bool. Its conventions are SB3's, as the
single-robot vector env's (:class:`crowdnav.agents.sb3.vec_env.CrowdNavSB3VecEnv`):

* every robot is a row every step; a robot that ended is inactive until its world's episode ends
  (zero observation, reward 0, ``infos[row]["active"]`` False), and its row is done only then;
* a world whose episode ended (every robot ended, or the time limit) is reset in the same step:
  each of its rows is done, its last observation in ``infos[row]["terminal_observation"]``, the
  new episode's first observation returned, the reset's infos merged over the last step's
  (``active`` True again); ``TimeLimit.truncated`` marks a time-limit end, so PPO bootstraps there;
* seeds come from the worlds (each plays its own episodes of the run's training band), never from
  ``VecEnv.seed``.

These are, row for row and bit for bit, what SuperSuit's ``concat_vec_envs_v1`` over
``pettingzoo_env_to_vec_env_v1`` made of the same env, the chain that collected for ``agents:
robots`` before (tests/agents/test_marl_vec_env.py steps both). :meth:`RobotsVecEnv.restore_worlds`
puts the worlds back mid-episode for an exact resume (:mod:`crowdnav.agents.marl.resume`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from crowdnav.agents.marl.env import RobotsTrainingEnv
from crowdnav.agents.sb3.factory import env_options
from crowdnav.agents.training.config import TrainConfig
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvObs, VecEnvStepReturn


class RobotsVecEnv(VecEnv):
    """``worlds`` (the run's :class:`RobotsTrainingEnv`, world ``w`` told it is ``w`` of ``len(worlds)``) as one SB3 VecEnv."""

    def __init__(self, worlds: Sequence[RobotsTrainingEnv]):
        if not worlds:
            raise ValueError("RobotsVecEnv needs at least one world")
        self.worlds = list(worlds)
        first = self.worlds[0]
        self.robots = list(first.possible_agents)
        """The robots' names, each world's rows in this order."""
        self.render_mode = None
        super().__init__(len(self.worlds) * len(self.robots), first.inputs.space, first.action_space(self.robots[0]))
        self._actions: np.ndarray | None = None

    @classmethod
    def make(cls, config: TrainConfig, first_episode: int = 0) -> RobotsVecEnv:
        """``config.num_envs`` worlds of the run's robots; their episodes are numbered from ``first_episode``."""
        worlds = [RobotsTrainingEnv(env_options(config), normalize=config.normalize_observations, identity=config.agent_identity,
                                    run_seed=config.seed, first_episode=first_episode, actions=config.robot_actions)
                  for _ in range(config.num_envs)]
        for world, env in enumerate(worlds):
            env.assign_world(world, config.num_envs)
        return cls(worlds)

    def _rows(self, observations: Sequence[Mapping[str, np.ndarray]]) -> np.ndarray:
        """Every world's robots' observations as the (rows, inputs) float32 array."""
        out = np.empty((self.num_envs, *self.worlds[0].inputs.space.shape), dtype=np.float32)
        return np.stack([world[name] for world in observations for name in self.robots], out=out)

    def reset(self) -> VecEnvObs:
        """Start a new episode in every world (each with its next training seed)."""
        observations: list[Mapping[str, np.ndarray]] = []
        self.reset_infos = []
        for world in self.worlds:
            observed, infos = world.reset()
            observations.append(observed)
            self.reset_infos.extend(infos.get(name, {}) for name in self.robots)
        self._reset_seeds()
        self._reset_options()
        return self._rows(observations)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        assert self._actions is not None, "step_async before step_wait"
        count = len(self.robots)
        actions = np.array(self._actions, dtype=np.float32).reshape(self.num_envs, -1)
        observations: list[Mapping[str, np.ndarray]] = []
        rewards = np.zeros(self.num_envs, dtype=np.float32)
        dones = np.zeros(self.num_envs, dtype=bool)
        infos: list[dict[str, Any]] = []
        for w, world in enumerate(self.worlds):
            own = actions[w * count : (w + 1) * count]
            playing = set(world.agents)
            observed, earned, terminations, truncations, stepped = world.step(
                {name: own[k] for k, name in enumerate(self.robots) if name in playing})
            ended = all(terminations[name] or truncations[name] for name in terminations)
            rows = [stepped.get(name, {}) for name in self.robots]
            for k, name in enumerate(self.robots):
                rewards[w * count + k] = earned.get(name, 0)
                dones[w * count + k] = terminations.get(name, False) or truncations.get(name, False)
            if ended:
                for row, name in zip(rows, self.robots, strict=True):
                    row["terminal_observation"] = observed[name]
                observed, first = world.reset()
                rows = [{**row, **first.get(name, {})} for row, name in zip(rows, self.robots, strict=True)]
            observations.append(observed)
            infos.extend(rows)
        return self._rows(observations), rewards, dones, infos

    def restore_worlds(self, counters: Sequence[tuple[int, int]], actions: np.ndarray, lengths: np.ndarray) -> np.ndarray:
        """A training resume: world ``w`` back in its episode after its first ``lengths[w]`` steps of ``actions[w]``
        ((worlds, steps, robots, 2), the network's own actions), its counters ``(first_episode, played)`` as saved.

        Each world is reset with its episode's seed and replays the actions
        (:meth:`RobotsTrainingEnv.replay`): the simulator's generator, seeded at reset, is an episode's
        only randomness, so the worlds are as they were, bit for bit. Returns the rows' observations.
        """
        if len(counters) != len(self.worlds) or len(actions) != len(self.worlds) or len(lengths) != len(self.worlds):
            raise ValueError(f"restore_worlds: one counter pair, action array and length per world ({len(self.worlds)})")
        observations = [world.replay(first, played, actions[w, : int(lengths[w])])
                        for w, (world, (first, played)) in enumerate(zip(self.worlds, counters, strict=True))]
        self._reset_seeds()
        return self._rows(observations)

    def close(self) -> None:
        for world in self.worlds:
            world.close()

    # Attributes and methods are the worlds' own; SB3 asks for render_mode only.

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self, attr_name) if attr_name == "render_mode" else getattr(self.worlds[self._world(i)], attr_name)
                for i in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        raise ValueError(f"set_attr({attr_name!r}): refused, the robots' worlds take their settings from the run's config")

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any) -> list[Any]:
        """``method_name`` called once on each world that holds one of the rows ``indices``; each row gets its world's result."""
        rows = [self._world(i) for i in self._get_indices(indices)]
        results = {w: getattr(self.worlds[w], method_name)(*method_args, **method_kwargs) for w in dict.fromkeys(rows)}
        return [results[w] for w in rows]

    def _world(self, row: int) -> int:
        return int(row) // len(self.robots)

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [None] * self.num_envs
