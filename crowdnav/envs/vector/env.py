"""The native vector environment: B worlds of one scenario stepped as one batch.

``gymnasium.make_vec("crowdnav/<Scenario>-v0", num_envs=B, vectorization_mode="vector_entry_point")``
returns a :class:`CrowdNavVectorEnv`; ``vectorization_mode="sync"`` still gives Gymnasium's
``SyncVectorEnv`` of B single envs. Both behave the same, world for world and bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, TypeGuard

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from crowdnav.batch.memory import keep_freed_memory as _keep_freed_memory
from crowdnav.batch.robot_policies import batched_policy as team_policy
from crowdnav.envs.core import ScenarioSource, checked_residual, load_env_world, option_overrides
from crowdnav.envs.engines.per_world import TeamWorlds
from crowdnav.envs.engines.protocol import WorldEngine
from crowdnav.envs.engines.stacked import StackedWorlds
from crowdnav.envs.engines.stacked_team import StackedTeamWorlds, first_robot_modalities
from crowdnav.envs.engines.world_state import VectorWorldState, check_state, world_key
from crowdnav.envs.vector.actions import checked_actions, checked_replay, executed
from crowdnav.envs.vector.infos import end_infos, every_infos, reward_term_infos, same_step_infos
from crowdnav.planning.shield import validate_shield
from crowdnav.sensors import Modality
from crowdnav.sim.simulator import Simulator
from crowdnav.worlds.compiled import CompiledWorld

MAX_WORLDS = 4_096
"""Most worlds in one vector env (the training config's num_envs bound)."""
MAX_AGENTS = 2_000_000
"""Most agents (robots and humans at the crowd's largest) over all worlds: each costs about 1 kB of state."""
EngineFactory = Callable[[CompiledWorld, int, dict[str, Modality]], WorldEngine]
"""``engine(world, num_envs, modalities)``: the worlds of a backend of one's own (:class:`CrowdNavVectorEnv`'s ``engine``)."""


class CrowdNavVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`crowdnav.envs.CrowdNavEnv` in one batch (a Gymnasium ``VectorEnv``).

    **Spec.** World ``i`` is exactly the single env: the same observation keys, spaces, reward
    terms, outcomes and infos; reset with seed ``s`` it plays, bit for bit, the episodes the single
    env plays after ``reset(seed=s + i)`` (a list of seeds gives each world its own; later
    episodes continue each world's generator, as ``reset()`` without a seed does). Options are
    the single env's (``scenario``, ``modalities``, ``sensors``, ``reward_weights``, ``overrides``)
    plus ``num_envs`` and ``autoreset_mode``. Rendering is the single env's job (render_mode None).

    **Spaces.** ``single_observation_space`` / ``single_action_space`` are the single env's;
    ``observation_space`` is a Dict of arrays with a leading axis of ``num_envs``, ``action_space``
    a ``(num_envs, 2)`` Box. Rewards are float64 (num_envs,), flags bool (num_envs,).

    **Infos** follow Gymnasium's vector convention (a key's values in an array, ``_key`` marking
    the worlds that have it): ``reward_terms`` (a dict of per-term arrays) for every world that
    stepped; ``outcome``, ``is_success`` for every world that stepped (``"truncated"`` / False for
    a world still running, as :class:`crowdnav.envs.single.CrowdNavEnv`); ``human_stalls``
    (int64) for every world that stepped; ``collision_kind`` and ``collision_partner`` after collisions.

    **Autoreset** (``autoreset_mode``, Gymnasium's :class:`AutoresetMode`):

    * ``NEXT_STEP`` (default, like ``SyncVectorEnv``): the step after a world's episode ended resets
      it (its action is ignored, reward 0, flags False, no infos) and returns the first observation;
    * ``SAME_STEP``: an ended world is reset in the same step; the observation returned is the new
      episode's first, the last one is in ``infos["final_obs"][i]`` and its info in
      ``infos["final_info"][i]`` (for SB3-style training loops);
    * ``DISABLED``: an ended world stays as it ended (its actions are ignored, its flags repeat,
      reward 0) until ``reset(options={"reset_mask": mask})`` resets it (for evaluation).

    **Engine.** The worlds are its ``engine`` (:class:`crowdnav.envs.engines.protocol.WorldEngine`), chosen once by
    :func:`stacks`: stacked in one batch (:class:`crowdnav.envs.engines.stacked.StackedWorlds`: a step loops over
    the crowd sizes present, never over worlds, humans, beams or cells; resets and goal-rule draws run per world
    that needs one), or, for one world (``num_envs=1``) and crowds of ``Simulator.grid_from`` humans or more (the
    single simulator's neighbour grid), held as single envs (:class:`crowdnav.envs.engines.per_world.TeamWorlds`): the
    same episodes, at the single env's speed per world. The env itself keeps Gymnasium's conventions only.
    ``engine`` (optional, an :data:`EngineFactory`) builds the worlds instead of that choice: a new backend, played
    through the protocol like the others (docs/architecture.md, "Adding a backend").

    **Several robots** (a scenario with ``robots:``): world ``i`` is :class:`crowdnav.envs.CrowdNavEnv`
    with the same ``other_robots`` option (the first robot learns, the others follow their scripted
    policy); its infos gain ``other_robots`` (a dict of per-robot arrays, as ``SyncVectorEnv`` lays out the
    single env's dict). The worlds are stacked too (:class:`crowdnav.envs.engines.stacked_team.StackedTeamWorlds`:
    the other robots of every world in the batch, their scripted policy batched), where ``other_robots`` names a
    policy with a batched twin (``social-force``, ``straight``) and the crowd walks by the social force; else
    (ORCA, a callable) a group of single envs (:class:`crowdnav.envs.engines.per_world.TeamWorlds`): the same episodes
    either way. The shield is refused there, as by the single env.

    **Episode seeds.** ``episode_seeds(worlds)`` (optional) gives the seeds of the episodes an
    autoreset starts, for ``worlds`` in ascending order (training numbers its episodes this way,
    :class:`crowdnav.agents.training.seeding.EpisodeSeedCounter`); without it an autoreset continues each
    world's generator.

    **World states.** ``snapshot(world)`` gives a world as data that pickles (:mod:`crowdnav.envs.engines.world_state`: its
    simulator's episode and generator, its reward memory, its tracker, Gymnasium's flags of it); ``load(world, state)``
    makes it any world's of an env of the same scenario and options, which then plays on bit for bit;
    ``load_worlds(states)`` loads every world at once (a training resume; stored without pickle by
    :mod:`crowdnav.envs.engines.world_state_codec`).

    **Memory.** With ``keep_freed_memory`` (default) the env raises glibc malloc's trim threshold
    to 64 MB for its process (:mod:`crowdnav.batch.memory`): the batch's temporaries are then reused
    instead of mapped again every step (about 1.5x, docs/simulator.md). Pass False to leave the
    process's allocator alone.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        scenario: ScenarioSource | None = None,
        num_envs: int = 1,
        *,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        modalities: Sequence[str] | None = None,
        sensors: Mapping[str, Any] | None = None,
        reward_weights: Mapping[str, float] | None = None,
        overrides: Mapping[str, Any] | None = None,
        render_mode: str | None = None,
        keep_freed_memory: bool = True,
        episode_seeds: Callable[[np.ndarray], Sequence[int | None]] | None = None,
        shield: bool | Mapping[str, Any] | None = None,
        residual: bool = False,
        other_robots: str | Callable[..., Any] = "social-force",
        engine: EngineFactory | None = None,
    ):
        if render_mode is not None:
            raise ValueError("the vector env does not render; render a single env (gymnasium.make(..., render_mode=...))")
        _check_num_envs(num_envs)  # before the world loads: a wrong count costs nothing
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ValueError(f"autoreset_mode must be one of {[mode.value for mode in AutoresetMode]}, got {autoreset_mode!r}") from None
        world, self.modalities = load_env_world(scenario, option_overrides(modalities, sensors, reward_weights, overrides))
        self.scenario = world.scenario
        self.episode_seeds = episode_seeds
        _check_agents(num_envs, world.scenario.humans.max_count)
        self.shield = validate_shield(dict(shield) if isinstance(shield, Mapping) else shield, world)
        self.engine: WorldEngine
        # worlds that are plain single envs (one robot): when all step, TeamWorlds.step_every steps them
        self._single_worlds: TeamWorlds | None = None
        policy = team_policy(other_robots) if world.scenario.robots is not None else None
        if engine is not None:  # a backend of the caller's
            self.engine = engine(world, num_envs, self.modalities)
            if self.engine.num_worlds != num_envs:
                raise ValueError(f"engine: it built {self.engine.num_worlds} worlds; num_envs is {num_envs}")
            self.modalities = self.engine.modalities
        elif policy is not None and stacks(world, num_envs, other_robots):  # several robots, stacked
            stacked = StackedTeamWorlds(world, num_envs, first_robot_modalities(world), policy)
            self.engine, self.modalities = stacked, stacked.modalities
        elif stacks(world, num_envs, other_robots):
            self.engine = StackedWorlds(world, num_envs, self.modalities)
        else:  # one single env per world, stepped in one call (crowdnav.envs.engines.per_world)
            team = TeamWorlds(world, num_envs, other_robots)
            self.engine, self.modalities = team, team.modalities  # several robots: the first robot's own (robots.0.modalities)
            self._single_worlds = team if team.plain else None
        self.residual = checked_residual(residual, self.modalities)
        if keep_freed_memory:
            _keep_freed_memory()
        self.num_envs = self.engine.num_worlds
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        self.single_observation_space = spaces.Dict({key: modality.space() for key, modality in self.modalities.items()})
        self.single_action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        b = self.num_envs
        self._started = np.zeros(b, dtype=bool)
        self._all_started = False
        self._ended = np.zeros(b, dtype=bool)  # the episode ended at the last step (NEXT_STEP: reset next; DISABLED: wait)
        self._none_ended = True  # not self._ended.any(), kept as a bool: every world steps next (one world: all steps but a reset's)
        self._last_flags = (np.zeros(b, dtype=bool), np.zeros(b, dtype=bool))
        # the modalities' own Boxes (the same objects as the Dict's): a Box's shape is never None
        boxes = {key: self.modalities[key].space() for key in self.single_observation_space.spaces}
        self._observations = {key: np.zeros((b, *box.shape), dtype=box.dtype) for key, box in boxes.items()}

    # ------------------------------------------------------------------ reset

    def reset(
        self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Reset every world (or those of ``options["reset_mask"]``); ``seed``: None, an int s (world i gets s + i) or one per world."""
        b = self.num_envs
        if seed is None:
            seeds: list[int | None] = [None] * b
        elif _is_seed(seed):
            seeds = [int(seed) + i for i in range(b)]
        elif isinstance(seed, (list, tuple, np.ndarray)) and all(s is None or _is_seed(s) for s in seed):
            seeds = [None if s is None else int(s) for s in seed]
            if len(seeds) != b:
                raise ValueError(f"seed: a list of seeds needs one per world ({b}), got {len(seeds)}")
        else:  # as the single env refuses them: floats, negatives, booleans, strings
            raise ValueError(f"seed must be None, an int or a list of one per world, got {str(seed)[:80]} (seeds are non-negative integers)")
        super().reset(seed=seed if isinstance(seed, int) else None)
        mask = np.ones(b, dtype=bool)
        if options and "reset_mask" in options:
            mask = np.asarray(options["reset_mask"])
            if mask.shape != (b,) or mask.dtype != np.bool_ or not mask.any():
                raise ValueError(f"options['reset_mask'] must be a bool array of shape ({b},) with at least one True, got {options['reset_mask']!r}")
        worlds = np.flatnonzero(mask)
        self._reset_worlds(worlds, [seeds[i] for i in worlds])
        self._observe_all()
        return self._copy_observations(), {}

    def _reset_worlds(self, worlds: np.ndarray, seeds: Sequence[int | None]) -> None:
        self.engine.reset(worlds, seeds)
        self._started[worlds] = True
        self._all_started = bool(self._started.all())
        self._ended[worlds] = False
        self._none_ended = not self._ended.any()
        for flags in self._last_flags:
            flags[worlds] = False

    def _autoreset(self, worlds: np.ndarray) -> None:
        seeds = [None] * len(worlds) if self.episode_seeds is None else list(self.episode_seeds(worlds))
        self._reset_worlds(worlds, seeds)

    # ------------------------------------------------------------------- step

    def step(self, actions: Any) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every running world with its row of ``actions`` ((num_envs, 2), each checked finite); autoreset per the mode."""
        if not self._all_started:
            raise RuntimeError("call reset() before step(): some worlds have not been reset")
        actions = checked_actions(actions, self.num_envs)
        infos: dict[str, Any] = {}
        stepping = ~self._ended
        every = self._none_ended  # every world steps (then no mask is applied below: the common case, one world's always)
        if not every:
            if self.autoreset_mode is AutoresetMode.NEXT_STEP:
                self._autoreset(np.flatnonzero(self._ended))
            if not stepping.any():  # every world is waiting (DISABLED) or was just reset
                self._observe_all()
                return self._copy_observations(), np.zeros(self.num_envs), *self._waiting_flags(), infos
        actions, shielded = self._executed(actions) if self.residual or self.shield is not None else (actions, None)
        if shielded is not None:  # every stepping world's flag (the vector infos' mask convention)
            infos["shielded"], infos["_shielded"] = shielded, stepping.copy()
        if every and self._single_worlds is not None:  # one world: every step but a reset's
            stepped = self._single_worlds.step_every(actions)  # the same arrays, each made once from the worlds' scalars
            rewards, terminated, truncated = stepped.rewards, stepped.terminated, stepped.truncated
            every_infos(infos, stepped, stepping)
            none_ended: bool | None = not stepped.ended  # (every world stepped, so in every mode self._ended becomes theirs)
        else:
            result = self.engine.step(actions, None if every else stepping)
            terminated = result.terminated if every else result.terminated & stepping
            truncated = result.truncated & ~terminated if every else result.truncated & stepping & ~terminated
            outcome, rewards, terms = self.engine.judged(result, stepping, every)
            reward_term_infos(infos, terms, stepping, every)
            end_infos(infos, self.engine, result, outcome, stepping, self._add_info, every)
            none_ended = None
        ended = terminated | truncated
        self._observe_all()
        disabled = self.autoreset_mode is AutoresetMode.DISABLED
        if disabled:
            waiting = self._ended.copy()
            terminated |= waiting & self._last_flags[0]
            truncated |= waiting & self._last_flags[1]
            self._last_flags = (terminated.copy(), truncated.copy())  # what the waiting worlds repeat
        self._ended = self._ended | ended if disabled else ended
        self._none_ended = not self._ended.any() if none_ended is None else none_ended
        if self.autoreset_mode is AutoresetMode.SAME_STEP and not self._none_ended:  # (self._ended is ended)
            infos = self._same_step_reset(infos, ended)
        return self._copy_observations(), rewards, terminated, truncated, infos

    def _executed(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The actions the robots execute: the plan plus the policy's action (``residual``), through the shield (and which it replaced)."""
        return executed(actions, self._observations["plan"] if self.residual else None, self.shield, self.engine)

    def restore_worlds(self, seeds: Sequence[int | None], actions: Any, lengths: Any) -> dict[str, np.ndarray]:
        """Rebuild every world mid-episode (a training resume): world ``i`` reset with ``seeds[i]``, then stepped with ``actions[i, :lengths[i]]``.

        The simulator's generator, seeded at reset, is an episode's only randomness, so this gives the
        worlds bit for bit as they were after those policy actions (residual and shield applied as in
        ``step``); a world steps only through its own actions (the batch leaves the others as they are).
        Returns the observations, as ``reset`` does. No rewards, infos or autoresets: the episodes are
        replayed, not played.
        """
        b = self.num_envs
        actions, lengths = checked_replay(actions, lengths, b)
        self.reset(seed=list(seeds))
        for step in range(int(lengths.max(initial=0))):
            active = lengths > step
            applied, _ = self._executed(checked_actions(actions[:, step], b))
            self.engine.step(applied, None if active.all() else active)
            if self.residual:  # the next plan is observed after this step
                self._observe_all()
        self.engine.settle()  # what a step's reward code keeps (the goal distance now)
        self._observe_all()
        return self._copy_observations()

    def snapshot(self, world: int) -> VectorWorldState:
        """World ``world`` now, as data that pickles (:class:`crowdnav.envs.engines.world_state.VectorWorldState`, a copy): its engine's
        :class:`crowdnav.envs.engines.world_state.WorldState` and Gymnasium's flags of it (its episode ended and waits for its autoreset
        or a reset mask, the flags a waiting world repeats). :meth:`load` makes it any world's of an env of the same options."""
        world = self._world(world)
        if not self._started[world]:
            raise RuntimeError(f"world {world} has not been reset: nothing to snapshot")
        terminated, truncated = self._last_flags
        return VectorWorldState(self.engine.snapshot(world), bool(self._ended[world]), bool(terminated[world]), bool(truncated[world]))

    def load(self, world: int, state: VectorWorldState) -> None:
        """Make ``state`` (a :meth:`snapshot`) world ``world``'s: with the same actions it plays on, episodes and autoresets included,
        as the captured world would, bit for bit (its later episodes continue its generator, or take ``episode_seeds``' seeds).
        The next step's observation is the captured world's; a ValueError in one line names what differs (scenario, settings, robots)."""
        self._load(self._world(world), state)
        if self._all_started:  # (a world not reset yet has nothing to observe; the load or reset that starts the last observes all)
            self._observe_all()

    def load_worlds(self, states: Sequence[VectorWorldState]) -> dict[str, np.ndarray]:
        """Make ``states[i]`` (:meth:`snapshot` s) world ``i``'s, every world at once (a training resume): as :meth:`load` world
        by world, every state checked before any loads, the worlds observed once. Returns the observations, as ``reset`` does."""
        if len(states) != self.num_envs:
            raise ValueError(f"load_worlds: one state per world ({self.num_envs}), got {len(states)}")
        key = world_key(self.scenario)
        for state in states:
            if not isinstance(state, VectorWorldState):
                raise ValueError(f"expected a VectorWorldState (CrowdNavVectorEnv.snapshot), got {type(state).__name__}")
            check_state(state.world, key)
        for world, state in enumerate(states):
            self._load(world, state)
        self._observe_all()
        return self._copy_observations()

    def _load(self, world: int, state: VectorWorldState) -> None:
        if not isinstance(state, VectorWorldState):
            raise ValueError(f"expected a VectorWorldState (CrowdNavVectorEnv.snapshot), got {type(state).__name__}")
        self.engine.load(world, state.world)
        self._started[world] = True
        self._all_started = bool(self._started.all())
        self._ended[world] = state.ended
        self._none_ended = not self._ended.any()
        self._last_flags[0][world], self._last_flags[1][world] = state.terminated, state.truncated

    def _world(self, world: int) -> int:
        if isinstance(world, bool) or not isinstance(world, (int, np.integer)) or not 0 <= world < self.num_envs:
            raise ValueError(f"world must be an integer in [0, {self.num_envs}), got {world!r}")
        return int(world)

    def _waiting_flags(self) -> tuple[np.ndarray, np.ndarray]:
        """(terminated, truncated) when no world stepped: waiting worlds repeat theirs (DISABLED), others are False."""
        if self.autoreset_mode is AutoresetMode.DISABLED:
            return self._last_flags[0] & self._ended, self._last_flags[1] & self._ended
        return np.zeros(self.num_envs, dtype=bool), np.zeros(self.num_envs, dtype=bool)

    def _same_step_reset(self, infos: dict[str, Any], ended: np.ndarray) -> dict[str, Any]:
        """Reset the ended worlds now; their last observation and info move to ``final_obs`` / ``final_info``
        (as ``SyncVectorEnv`` does: :func:`crowdnav.envs.vector.infos.same_step_infos`)."""
        worlds = np.flatnonzero(ended)
        out = same_step_infos(infos, ended, self._observations)
        self._autoreset(worlds)
        self._ended[worlds] = False
        self._observe_all()
        return out

    # ----------------------------------------------------------- observations

    def _observe_all(self) -> None:
        self.engine.observe(self._observations)

    def _copy_observations(self) -> dict[str, np.ndarray]:
        return {key: values.copy() for key, values in self._observations.items()}

    # ---------------------------------------------------------- world access

    def robot_social_force(self) -> np.ndarray:
        """(num_envs,) complex: the humans' social-force repulsion on each robot (the reward's social term reads its length)."""
        return self.engine.social_force()

    def positions(self, world: int) -> np.ndarray:
        """(n+1,) complex: robot then humans of ``world`` (a copy)."""
        return self.engine.row("positions", world)

    def velocities(self, world: int) -> np.ndarray:
        """(n+1,) complex: velocities over the last step of ``world`` (a copy)."""
        return self.engine.row("velocities", world)

    def human_goals(self, world: int) -> np.ndarray:
        """(n,) complex: the humans' current goals in ``world`` (a copy)."""
        return self.engine.row("human_goals", world)

    def human_respawns(self, world: int) -> np.ndarray:
        """(n,) int: how many times each human of ``world`` respawned this episode (a copy; ``Simulator.human_respawns``)."""
        return self.engine.row("human_respawns", world)

    def robot_goal(self, world: int) -> complex:
        return self.engine.robot_goal(world)

    def simulator(self, world: int) -> Simulator:
        """A snapshot of ``world`` as a :class:`crowdnav.Simulator`, built on each call: a copy of its current state.

        Its state and geometry are the world's at the moment of the call (call again after a step);
        it shares nothing writable with the vector env, so stepping it leaves the world as it is.
        """
        return self.engine.simulator(world)


def stacks(world: CompiledWorld, num_envs: int, other_robots: str | Callable[..., Any] = "social-force") -> bool:
    """Whether the vector env steps ``num_envs`` worlds of ``world`` stacked (:class:`StackedWorlds`; several robots:
    :class:`crowdnav.envs.engines.stacked_team.StackedTeamWorlds`), else as single envs (:class:`TeamWorlds`): more than one
    world, crowds below :attr:`Simulator.grid_from` humans; several robots where the stacked team plays what the single env
    does: the other robots driven by a policy with a batched twin (``other_robots``: :func:`team_policy`) and the crowd's
    social-force model alone (a view of stacked worlds lists one robot to the other models; a ``robots:`` scenario has no
    people tracker)."""
    if num_envs <= 1 or world.scenario.humans.max_count >= Simulator.grid_from:
        return False
    if world.scenario.robots is None:
        return True
    models = {group.model for _, group in world.scenario.humans.crowd if not group.standing and group.model is not None}
    return team_policy(other_robots) is not None and models <= {"social_force"}


def _check_num_envs(num_envs: Any) -> None:
    if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or not 1 <= num_envs <= MAX_WORLDS:
        raise ValueError(f"num_envs must be an integer from 1 to {MAX_WORLDS:,}, got {num_envs!r}")


def _check_agents(num_envs: int, max_humans: int) -> None:
    agents = int(num_envs) * (max_humans + 1)
    if agents > MAX_AGENTS:
        raise ValueError(f"num_envs={num_envs} worlds of up to {max_humans:,} humans make {agents:,} agents; "
                         f"expected at most {MAX_AGENTS:,}: fewer worlds or a smaller crowd")


def _is_seed(value: object) -> TypeGuard[int | np.integer[Any]]:
    """A non-negative integer (numpy's too), not a boolean."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool) and bool(value >= 0)
