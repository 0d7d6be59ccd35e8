"""The robots of ``num_envs`` worlds as one Stable-Baselines3 ``VecEnv``: one row per robot per world (``agents: robots``).

:class:`RobotsVecEnv` plays the run's worlds through a robots-only engine
(:func:`crowdnav.envs.engines.robots.robots_engine`: the worlds stacked in one batch where the scenario stacks, one
robots-only env per world otherwise) and adds what shared-parameter training needs, as
:class:`crowdnav.agents.marl.env.RobotsTrainingEnv` adds it to one world: the network's observations
(:class:`crowdnav.agents.marl.env.RobotObservations`), its actions (:class:`crowdnav.agents.marl.actions.RobotActions`)
and the training band's episode seeds. Row ``w * R + k`` is robot ``k`` (the scenario's order) of world ``w``; the
observations are float32 ``(num_envs * R, inputs)``, rewards float32, dones bool. Its conventions are SB3's, as the
single-robot vector env's (:class:`crowdnav.agents.sb3.vec_env.CrowdNavSB3VecEnv`):

* every robot is a row every step; a robot that ended is inactive until its world's episode ends
  (zero observation, reward 0, ``infos[row]["active"]`` False), and its row is done only then;
* a world whose episode ended (every robot ended, or the time limit) is reset in the same step:
  each of its rows is done, its last observation in ``infos[row]["terminal_observation"]``, the
  new episode's first observation returned, the reset's infos merged over the last step's
  (``active`` True again); ``TimeLimit.truncated`` marks a time-limit end, so PPO bootstraps there;
* every row's info has its world's ``episode_seed``; a robot that acted has ``reward_terms`` and, at its end,
  ``outcome``, ``is_success`` and after a collision ``collision_kind`` / ``collision_partner``;
* seeds come from the worlds' counters: world ``w`` of ``W`` plays its ``p``-th episode with
  :func:`crowdnav.agents.training.seeding.train_seed` ``(seed, first_episode + p * W + w)``, never from ``VecEnv.seed``.

These are, row for row and bit for bit, what the run's worlds as :class:`RobotsTrainingEnv` give stepped one by one,
and what SuperSuit's ``concat_vec_envs_v1`` over ``pettingzoo_env_to_vec_env_v1`` made of them, the chain that
collected for ``agents: robots`` before (tests/agents/test_marl_vec_env.py steps all three). For an exact resume
(:mod:`crowdnav.agents.marl.resume`) :meth:`RobotsVecEnv.snapshot` gives a world as data (:class:`RobotsWorldState`:
its engine's state and what this env keeps of it) and :meth:`RobotsVecEnv.load_worlds` puts every world back from
such states, whichever engine took them; :meth:`RobotsVecEnv.restore_worlds` rebuilds them instead from each world's
counters and the network's actions since its episode's reset (:meth:`RobotsVecEnv.episode_actions`), replayed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from crowdnav.agents.marl.actions import RobotActions
from crowdnav.agents.marl.env import RobotObservations, robots_env
from crowdnav.agents.sb3.factory import env_options
from crowdnav.agents.training.config import TrainConfig
from crowdnav.agents.training.seeding import MAX_TRAIN_EPISODES, train_seed
from gymnasium import spaces
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvObs, VecEnvStepReturn

from crowdnav.envs.engines.protocol import RobotsEngine, RobotsStep
from crowdnav.envs.engines.robots import SingleRobots, robots_engine
from crowdnav.envs.engines.world_state import WorldState
from crowdnav.envs.reward import REWARD_TERMS
from crowdnav.scenario.schema import Scenario


@dataclass(frozen=True, eq=False)
class RobotsWorldState:
    """One world of a :class:`RobotsVecEnv` (:meth:`RobotsVecEnv.snapshot`); it pickles."""

    world: WorldState
    """The engine's state of the world (:meth:`crowdnav.envs.engines.protocol.RobotsEngine.snapshot`, every robot's observation in it)."""
    first_episode: int
    played: int
    """The world's episode counters (:meth:`RobotsVecEnv.episode_counters`)."""
    active: np.ndarray
    """(R,) bool: the robots whose rows the network sees (one that ended at the last step shows it until the next)."""
    actions: np.ndarray
    """(steps, R, 2) float32: the network's actions since the episode's reset (:meth:`RobotsVecEnv.episode_actions` goes on from them)."""


class RobotsVecEnv(VecEnv):
    """``engine``'s worlds (every robot driven) as one SB3 VecEnv with the shared network's ``inputs`` and ``commands``;
    their episodes numbered from ``first_episode`` in the band of ``run_seed`` (see the module docstring)."""

    def __init__(self, engine: RobotsEngine, inputs: RobotObservations, commands: RobotActions, scenario: Scenario, *,
                 run_seed: int, first_episode: int = 0):
        self.engine, self.inputs, self.commands, self.scenario = engine, inputs, commands, scenario
        self.robots = list(engine.robot_names)
        """The robots' names, each world's rows in this order."""
        self.render_mode = None
        worlds = engine.num_worlds
        super().__init__(worlds * len(self.robots), inputs.space, spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32))
        self.run_seed = int(run_seed)
        self.first_episode = np.full(worlds, int(first_episode), dtype=np.int64)
        self.played = np.zeros(worlds, dtype=np.int64)
        """Per world: its counters (the episode it starts next is ``first_episode + played * W + w``)."""
        self.episode_seeds = [0] * worlds
        """Each world's current episode's seed."""
        self._raw = np.zeros((worlds, len(self.robots), engine.observation_size), np.float32)
        """The raw observations the network acts on next (``goal_velocity`` reads each robot's goal direction there)."""
        self._active = np.ones((worlds, len(self.robots)), dtype=bool)
        self._history: list[np.ndarray] = []
        """The network's (W, R, 2) actions of the steps since the oldest running episode's reset."""
        self._began = np.zeros(worlds, dtype=np.int64)
        self._steps = 0
        """Steps taken so far, and (``_began``) the step each world's episode started at (``_history[0]`` is step
        ``_steps - len(_history)``)."""
        self._actions: np.ndarray | None = None

    @classmethod
    def make(cls, config: TrainConfig, first_episode: int = 0, *, stacked: bool = True) -> RobotsVecEnv:
        """``config.num_envs`` worlds of the run's robots; their episodes are numbered from ``first_episode``.
        ``stacked=False``: one robots-only env per world even where the worlds stack (the same rows; what the stack is
        measured against, ``benchmarks/bench_robots_vec.py``)."""
        options = env_options(config)
        template = robots_env(options)  # one world's env: the scenario refused in the env's words, the inputs' scales
        try:
            inputs = RobotObservations(template, normalize=config.normalize_observations, identity=config.agent_identity)
            commands = RobotActions.for_env(config.robot_actions, template)
            scenario = template.scenario
        finally:
            template.close()
        engine = robots_engine(options, config.num_envs) if stacked else SingleRobots(options, config.num_envs)
        return cls(engine, inputs, commands, scenario, run_seed=config.seed, first_episode=first_episode)

    @property
    def num_worlds(self) -> int:
        return self.engine.num_worlds

    @property
    def next_episode(self) -> int:
        """The episode after every one any world has started (a resume's worlds start there, so no seed repeats)."""
        worlds = self.num_worlds
        return int((self.first_episode + self.played * worlds + np.arange(worlds)).max())

    # ------------------------------------------------------------------ reset

    def _start(self, worlds: np.ndarray) -> None:
        """New episodes in ``worlds`` (ascending), each with its next training seed."""
        episodes = self.first_episode[worlds] + self.played[worlds] * self.num_worlds + worlds
        if len(episodes) and episodes.max() >= MAX_TRAIN_EPISODES:
            raise RuntimeError(f"a run may start at most {MAX_TRAIN_EPISODES:,} training episodes (crowdnav.agents.training.seeding)")
        self.played[worlds] += 1
        seeds = [train_seed(self.run_seed, int(episode)) for episode in episodes]
        for world, seed in zip(worlds.tolist(), seeds, strict=True):
            self.episode_seeds[world] = seed
        self.engine.reset(worlds, seeds)
        self._active[worlds] = True
        self._began[worlds] = self._steps
        oldest = int(self._began.min()) - (self._steps - len(self._history))
        if oldest > 0:  # no running episode needs the steps before its reset
            del self._history[:oldest]

    def reset(self) -> VecEnvObs:
        """Start a new episode in every world (each with its next training seed)."""
        self._start(np.arange(self.num_worlds))
        self._raw = self.engine.observe()
        self.reset_infos = [{"active": True} for _ in range(self.num_envs)]
        self._reset_seeds()
        self._reset_options()
        return self.inputs.rows(self._raw, self._active)

    # ------------------------------------------------------------------- step

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def _act(self, actions: np.ndarray, active: np.ndarray | None = None) -> RobotsStep:
        """One step of the network's (W, R, 2) ``actions`` in the worlds of ``active`` (None: all), recorded for a resume."""
        self._history.append(actions)
        self._steps += 1
        step = self.engine.step(self.commands.batch(actions, self._raw), active)
        stepped = np.ones(self.num_worlds, dtype=bool) if active is None else active
        self._active = np.where(stepped[:, None], step.stepped, self._active)
        self._raw = self.engine.observe()
        return step

    def step_wait(self) -> VecEnvStepReturn:
        assert self._actions is not None, "step_async before step_wait"
        actions = np.array(self._actions, dtype=np.float32).reshape(self.num_worlds, len(self.robots), 2)
        step = self._act(actions)
        observations = self.inputs.rows(self._raw, self._active)
        infos = self._infos(step)
        dones = np.repeat(step.over, len(self.robots))
        ended = np.flatnonzero(step.over)
        if len(ended):
            for row in np.flatnonzero(dones).tolist():
                infos[row]["terminal_observation"] = observations[row].copy()
                infos[row]["active"] = True  # the new episode's reset info, merged over the last step's
            self._start(ended)
            self._raw = self.engine.observe()
            observations = self.inputs.rows(self._raw, self._active)
        return observations, step.rewards.astype(np.float32).reshape(-1), dones, infos

    def _infos(self, step: RobotsStep) -> list[dict[str, Any]]:
        """Every row's info of ``step``, what the robots-only env's ``infos[name]`` holds under ``fixed_agents`` (one dict per
        row: SB3's layout)."""
        count = len(self.robots)
        acted, outcome = step.stepped.reshape(-1).tolist(), step.outcome.reshape(-1).tolist()
        terms = {term: step.terms[term].reshape(-1).tolist() for term in REWARD_TERMS}
        seeds, truncated = self.episode_seeds, step.truncated.tolist()
        infos: list[dict[str, Any]] = []
        for row in range(self.num_envs):  # the infos are SB3's list of dicts: built per row
            world = row // count
            info: dict[str, Any] = {"active": False}
            if acted[row]:
                info = {"reward_terms": {term: values[row] for term, values in terms.items()}}
                if outcome[row] is not None:
                    info["outcome"], info["is_success"] = outcome[row], outcome[row] == "success"
                    contact = step.collisions.get((world, row % count))
                    if contact is not None:
                        info["collision_kind"], info["collision_partner"] = contact.kind, contact.partner
                info["active"] = True
            info["episode_seed"] = seeds[world]
            if truncated[world]:
                info["TimeLimit.truncated"] = True
            infos.append(info)
        return infos

    # ------------------------------------------------------------------ resume

    def episode_counters(self) -> list[tuple[int, int]]:
        """Each world's ``(first_episode, played)``, what :meth:`restore_worlds` takes back."""
        return [(int(first), int(played)) for first, played in zip(self.first_episode, self.played, strict=True)]

    def episode_actions(self) -> tuple[np.ndarray, np.ndarray]:
        """The network's actions since each world's episode began: ``(actions (W, steps, R, 2) float32, lengths (W,))``."""
        lengths = self._steps - self._began
        actions = np.zeros((self.num_worlds, int(lengths.max(initial=0)), len(self.robots), 2), np.float32)
        if len(self._history):
            history = np.stack(self._history, axis=1)  # (W, kept steps, R, 2)
            for world, length in enumerate(lengths.tolist()):  # a resume's save, once per checkpoint
                if length:
                    actions[world, :length] = history[world, len(self._history) - length :]
        return actions, lengths

    def snapshot(self, world: int) -> RobotsWorldState:
        """World ``world`` now, copied: :meth:`load_worlds` puts it back in a RobotsVecEnv of either engine."""
        length = int(self._steps - self._began[world])
        kept = self._history[len(self._history) - length :] if length else []
        actions = np.array([step[world] for step in kept], dtype=np.float32).reshape(length, len(self.robots), 2)
        return RobotsWorldState(self.engine.snapshot(world), int(self.first_episode[world]), int(self.played[world]),
                                self._active[world].copy(), actions)

    def load_worlds(self, states: Sequence[RobotsWorldState]) -> np.ndarray:
        """A training resume: world ``w`` becomes ``states[w]`` (:meth:`snapshot` s of a run of the same config, either
        engine's), every world at once; returns the rows' observations, those of the snapshots. A state that does not fit
        is a ValueError in one line (its world and the worlds loaded before it are then to be reset)."""
        worlds, robots = self.num_worlds, len(self.robots)
        if len(states) != worlds:
            raise ValueError(f"load_worlds: {len(states)} states for {worlds} worlds")
        for w, state in enumerate(states):
            if not isinstance(state, RobotsWorldState) or state.played < 1 or state.active.shape != (robots,) \
                    or state.active.dtype != bool or state.actions.shape[1:] != (robots, 2) or state.actions.dtype != np.float32:
                raise ValueError(f"world {w}: expected a RobotsWorldState of a world of {robots} robots (RobotsVecEnv.snapshot)")
        for w, state in enumerate(states):
            self.engine.load(w, state.world)
        self.first_episode = np.array([state.first_episode for state in states], dtype=np.int64)
        self.played = np.array([state.played for state in states], dtype=np.int64)
        episodes = self.first_episode + (self.played - 1) * worlds + np.arange(worlds)  # the episode each world plays
        self.episode_seeds = [train_seed(self.run_seed, int(episode)) for episode in episodes]
        self._active = np.stack([state.active for state in states])
        lengths = np.array([len(state.actions) for state in states], dtype=np.int64)
        steps = int(lengths.max(initial=0))
        history = np.zeros((steps, worlds, robots, 2), np.float32)  # each world's actions the last of the steps kept
        for w, state in enumerate(states):
            history[steps - len(state.actions) :, w] = state.actions
        self._history, self._steps, self._began = list(history), steps, steps - lengths
        self._raw = self.engine.observe()
        self._reset_seeds()
        return self.inputs.rows(self._raw, self._active)

    def restart(self, counters: Sequence[tuple[int, int]]) -> np.ndarray:
        """Every world reset to the episode its counters ``(first_episode, played)`` number (as saved: ``played`` counts it);
        returns the rows' observations. A resume's first act: what the stored worlds are checked against."""
        worlds = self.num_worlds
        if len(counters) != worlds:
            raise ValueError(f"restart: one counter pair per world ({worlds})")
        self.first_episode = np.array([int(first) for first, _ in counters], dtype=np.int64)
        self.played = np.array([int(played) - 1 for _, played in counters], dtype=np.int64)
        self._history, self._steps = [], 0
        self._start(np.arange(worlds))
        self._raw = self.engine.observe()
        self._reset_seeds()
        return self.inputs.rows(self._raw, self._active)

    def restore_worlds(self, counters: Sequence[tuple[int, int]], actions: np.ndarray, lengths: np.ndarray) -> np.ndarray:
        """A format-1 resume: world ``w`` back in its episode after its first ``lengths[w]`` steps of ``actions[w]``
        ((worlds, steps, robots, 2), the network's own actions), its counters ``(first_episode, played)`` as saved.

        Every world is reset with its episode's seed and replays its actions (a world whose replay is over waits): the
        simulator's generator, seeded at reset, is an episode's only randomness, so the worlds are as they were, bit for
        bit. Returns the rows' observations.
        """
        worlds = self.num_worlds
        if len(counters) != worlds or len(actions) != worlds or len(lengths) != worlds:
            raise ValueError(f"restore_worlds: one counter pair, action array and length per world ({worlds})")
        self.restart(counters)
        lengths = np.asarray(lengths, dtype=np.int64)
        steps = int(lengths.max(initial=0))
        wait = steps - lengths  # the shorter replays start later, so that every world's steps are the last ones recorded
        everyone = np.arange(worlds)
        for t in range(steps):
            playing = t >= wait
            row = np.asarray(actions[everyone, np.where(playing, t - wait, 0)], dtype=np.float32)
            self._act(np.where(playing[:, None, None], row, np.float32(0.0)), playing)
        self._began[:] = self._steps - lengths
        self._reset_seeds()
        return self.inputs.rows(self._raw, self._active)

    def close(self) -> None:
        self.engine.close()

    # SB3 asks for render_mode only; the worlds take their settings from the run's config.

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        raise ValueError(f"set_attr({attr_name!r}): refused, the robots' worlds take their settings from the run's config")

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any) -> list[Any]:
        raise ValueError(f"env_method({method_name!r}): refused, the robots' worlds are one engine (call RobotsVecEnv's own methods)")

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [None] * self.num_envs

