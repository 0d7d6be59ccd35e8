"""Worlds held as single envs in the native vector env: :class:`TeamWorlds`, a group of per-world simulators stepped in one call.

:class:`crowdnav.envs.vector.env.CrowdNavVectorEnv` holds its worlds here, not in one stacked
:class:`crowdnav.batch.simulator.BatchSimulator`, where stacking does not pay or does not apply:

* a scenario with ``robots:`` whose other robots follow a policy without a batched twin (ORCA, a callable; the
  named scripted ones run stacked, :mod:`crowdnav.envs.engines.stacked_team`) or whose crowd has ORCA humans:
  the robots after the first are in each world's :class:`crowdnav.sim.robots.Team`;
* one world (``num_envs=1``): a batch of one does the single env's array work with a world axis and
  per-step bookkeeping on top (0.36x its env-steps/s, docs/environments.md#one-world-and-crowds-of-200-humans-or-more), so the world is
  the single env itself and ``num_envs`` stays a size: every world count collects through the same vector env;
* crowds of :attr:`crowdnav.Simulator.grid_from` humans or more: the single simulator measures them with
  its neighbour grid (:mod:`crowdnav.sim.crowd_grid`), which the all-pairs batch does not have.

Each world is one :class:`crowdnav.envs.single.CrowdNavEnv` (its own :class:`crowdnav.Simulator`, the
other robots' policies, the first robot's sensors and reward), all stepped by one :meth:`TeamWorlds.step`
call. Each world's step is the single env's own, so world ``i`` plays the single env's episodes bit
for bit by construction; the vector env keeps everything around it (autoreset modes, episode seeds,
reset masks, the infos' layout, the shield, the residual plan, SB3's adapter, a training resume) as it
is for stacked worlds. Inside a world nothing loops over humans (the simulator's step is array work); the
loop is over worlds, except for several robots' first-robot LIDAR scans, made for all the worlds in one
batched raycast between the two halves of each world's step (the same kernel, row k world k's, bit for bit).
docs/environments.md#several-robots measures it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from crowdnav.batch.simulator import StepResult
from crowdnav.envs.engines.protocol import Judged, world_frame
from crowdnav.envs.engines.world_state import WorldState
from crowdnav.envs.reward import REWARD_TERMS
from crowdnav.envs.single import CrowdNavEnv
from crowdnav.planning.shield import Shield
from crowdnav.sensors import Modality
from crowdnav.sensors.lidar import LidarModality
from crowdnav.sensors.tracked import attach
from crowdnav.sim.events import Collision, StepEvents
from crowdnav.sim.robot_view import RobotWorld
from crowdnav.sim.simulator import Simulator
from crowdnav.worlds.compiled import CompiledWorld


class EveryStep(NamedTuple):
    """One step of every world, one robot each (:meth:`TeamWorlds.step_every`): what :meth:`TeamWorlds.step`,
    :meth:`TeamWorlds.judged` and :meth:`TeamWorlds.stalls` give the vector env, as new (num_worlds,) arrays."""

    rewards: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    """Truncated and not terminated (the single env's flag)."""
    outcome: np.ndarray
    """Object: each world's outcome, "truncated" while it runs on."""
    success: np.ndarray
    """The outcome is "success"."""
    terms: dict[str, np.ndarray]
    stalls: np.ndarray
    collisions: dict[int, Collision]
    """World -> the robot's collision, for the worlds whose robot collided."""
    ended: bool
    """Some world's episode ended (terminated or truncated)."""


class TeamWorlds:
    """``num_worlds`` single envs of one world, reset and stepped as a batch (the vector env's engine; see the module docstring).

    ``world``: the compiled scenario with every env option applied (sensors, reward weights, overrides);
    ``other_robots``: the single env's option (a policy name, or a callable / class; a class is made per
    robot of each world). After :meth:`reset` / :meth:`step`, ``observations[i]`` is world i's last
    observation, and for the worlds that stepped ``rewards``, ``terms`` and ``other_robots[i]`` its reward,
    reward terms and ``info["other_robots"]``.
    """

    def __init__(self, world: CompiledWorld, num_worlds: int, other_robots: str | Callable[..., Any] = "social-force"):
        self.num_worlds = int(num_worlds)
        # the compiled scenario already holds every option (load_env_world applied them): each env loads it as it is
        self.envs = [CrowdNavEnv(world.scenario, other_robots=other_robots) for _ in range(self.num_worlds)]
        first = self.envs[0]
        self.modalities: dict[str, Modality] = first.core.modalities
        """The first robot's modalities (``robots.0.modalities`` or ``sensors.modalities``), the vector env's observation keys."""
        self.observations: list[dict[str, np.ndarray]] = [{} for _ in range(self.num_worlds)]
        self.rewards = np.zeros(self.num_worlds)
        self.terms = {term: np.zeros(self.num_worlds) for term in REWARD_TERMS}
        """Each reward term's value in every world at its last step."""
        self.outcomes = np.full(self.num_worlds, None, dtype=object)
        """World i's outcome at its last step ("truncated" while it runs on: the vector infos' convention)."""
        self._other_robots: list[dict[str, str | None]] = [{} for _ in range(self.num_worlds)]
        self.team = world.scenario.robots is not None
        """Several robots per world (``robots:``): the other robots' infos and the batched first-robot LIDAR."""
        self.plain = all(env.core.plain for env in self.envs)
        """Every world's core is :attr:`crowdnav.envs.core.EnvCore.plain` (one robot, no shield, plan or view): :meth:`step_every` steps them."""

    def reset(self, worlds: Sequence[int] | np.ndarray, seeds: Sequence[int | None] | np.ndarray) -> None:
        """Start a new episode in each of ``worlds`` (``seeds[k]`` for ``worlds[k]``; None continues its generator)."""
        for world, seed in zip(worlds, seeds, strict=True):
            self.observations[int(world)], _ = self.envs[int(world)].reset(seed=None if seed is None else int(seed))

    def step(self, actions: np.ndarray, active: np.ndarray | None = None) -> StepResult:
        """Step every world (or those of the bool mask ``active``) with its row of ``actions`` ((num_worlds, 2)).

        Each world's single env steps in two halves (:meth:`CrowdNavEnv.advance`, :meth:`CrowdNavEnv.finish_step`);
        between them the first robots' LIDAR scans of all the worlds are made in one batched raycast.
        """
        b = self.num_worlds
        result = StepResult(goal_reached=np.zeros(b, dtype=bool), left_world=np.zeros(b, dtype=bool), truncated=np.zeros(b, dtype=bool))
        worlds = [int(i) for i in (range(b) if active is None else np.flatnonzero(active))]
        if not self.team:
            for i in worlds:  # per world: the single env's step (CrowdNavEnv.step without its info dict, which the vector env lays out)
                core = self.envs[i].core
                own, self.rewards[i], terms = core.step(actions[i])
                self.observations[i] = core.observe()
                self._record(result, i, own, terms)
            return result
        # per world: the single env's step up to its observation (its simulator steps every agent as arrays)
        stepped = [self.envs[i].advance(actions[i]) for i in worlds]
        views = [self.envs[i].simulator.robot_view(0) for i in worlds]
        readings = self._scans(views)
        for k, i in enumerate(worlds):
            env = self.envs[i]
            given = {key: rows[k] for key, rows in readings.items()}
            self.observations[i], self.rewards[i], _, _, info = env.finish_step(*stepped[k], view=views[k], given=given)
            events = env.simulator.robot_events[0]  # the first robot's: it is in the world until its episode ends
            assert events is not None
            self._record(result, i, events, info["reward_terms"])
            self._other_robots[i] = info["other_robots"]
        return result

    def step_every(self, actions: np.ndarray) -> EveryStep:
        """Step every world (all :attr:`plain`) with its row of ``actions`` (checked, float64): :meth:`step` and what
        the vector env then asks of it, in one pass (one world: every step but an autoreset's).

        Each world's core steps and observes as in :meth:`step` (:meth:`crowdnav.envs.core.EnvCore.step_plain`, its
        action already checked: not again); its scalars make each array once, where :meth:`step` writes them into
        this object's arrays for :meth:`judged` and the vector env's info code to copy and recompute: at one world
        those small numpy calls were most of what the vector env cost over the single env
        (docs/environments.md#one-world-and-crowds-of-200-humans-or-more). Leaves ``rewards``, ``terms`` and
        ``outcomes`` as they were (only :meth:`judged` reads them, after :meth:`step`).
        """
        rewards, terminated, truncated, success, outcome, stalls = [], [], [], [], [], []
        terms: list[dict[str, float]] = []
        collisions = {}
        for i, env in enumerate(self.envs):
            core = env.core
            self.observations[i], events, reward, own = core.step_plain(actions[i], checked=True)
            ended = events.terminated
            rewards.append(reward)
            terminated.append(ended)
            truncated.append(events.truncated and not ended)
            outcome.append(events.outcome or "truncated")
            success.append(outcome[-1] == "success")
            terms.append(own)
            stalls.append(int(np.add.reduce(env.simulator.human_stalls)))  # .sum() without its Python wrapper
            if events.collision is not None:
                collisions[i] = events.collision
        return EveryStep(np.array(rewards, dtype=float), np.array(terminated, dtype=bool), np.array(truncated, dtype=bool),
                         np.array(outcome, dtype=object), np.array(success, dtype=bool),
                         {term: np.array([world[term] for world in terms], dtype=float) for term in REWARD_TERMS},
                         np.array(stalls, dtype=np.int64), collisions, any(terminated) or any(truncated))

    def _record(self, result: StepResult, i: int, events: StepEvents, terms: dict[str, float]) -> None:
        """World ``i``'s step: its events in the batch's ``result``, its outcome and reward terms here."""
        result.goal_reached[i], result.left_world[i], result.truncated[i] = events.goal_reached, events.left_world, events.truncated
        if events.collision is not None:
            result.collisions[i] = events.collision
        self.outcomes[i] = events.outcome or "truncated"
        for term, values in self.terms.items():
            values[i] = terms[term]

    def judged(self, result: StepResult, stepping: np.ndarray, every: bool) -> Judged:
        """What the single envs said of the last step of the ``stepping`` worlds (``every``: all; each world's single env
        judged its own step, with the same kernels): every world's outcome (None where it did not step), every world's
        reward (0 where it did not step) and the stepping worlds' values of each reward term, all new arrays."""
        if every:
            return self.outcomes.copy(), self.rewards.copy(), {term: values.copy() for term, values in self.terms.items()}
        worlds = np.flatnonzero(stepping)
        outcome = np.full(self.num_worlds, None, dtype=object)
        outcome[worlds] = self.outcomes[worlds]
        rewards = np.zeros(self.num_worlds)
        rewards[worlds] = self.rewards[worlds]
        return outcome, rewards, {term: values[worlds] for term, values in self.terms.items()}

    def settle(self) -> None:
        """Nothing to settle: each world's single env kept its reward's memory through the replayed steps."""

    def observe(self, out: Mapping[str, np.ndarray]) -> None:
        for i, observation in enumerate(self.observations):  # each world's single env observed its first robot
            for key, values in out.items():
                values[i] = observation[key]

    def shielded(self, shield: Shield, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The single env's own call per world (one robot each: the shield refuses several)."""
        out, replaced = actions.copy(), np.zeros(self.num_worlds, dtype=bool)
        for i, env in enumerate(self.envs):
            out[i], replaced[i] = shield.single(env.core.people(), actions[i])
        return out, replaced

    def other_robots(self, stepping: np.ndarray) -> dict[int, dict[str, str | None]]:
        """Per stepping world, its other robots' outcomes as its single env's ``info["other_robots"]`` (several robots only)."""
        return {int(i): self._other_robots[int(i)] for i in np.flatnonzero(stepping)} if self.team else {}

    def _scans(self, views: list[RobotWorld]) -> dict[str, np.ndarray]:
        """Each LIDAR modality's readings of ``views`` (the first robots' after a step), row k of ``views[k]``.

        Worlds whose views hold the same discs (the same robots still in the world) share one call of
        the scan kernel, whose row k depends on world k alone, bit for bit (:meth:`LidarModality.inverse_ranges`).
        """
        lidars = [(key, modality) for key, modality in self.modalities.items()
                  if type(modality) is LidarModality and modality.sees_robots]  # a subclass may observe otherwise
        if not lidars or not views:
            return {}
        groups: dict[bytes, list[int]] = {}
        for k, view in enumerate(views):
            groups.setdefault(view.radii.tobytes(), []).append(k)
        readings = {}
        for key, lidar in lidars:
            out = np.empty((len(views), lidar.beams), dtype=np.float32)
            for members in groups.values():
                positions = np.stack([views[k].positions for k in members])
                headings = np.array([views[k].robot_heading for k in members], dtype=float)
                out[members] = lidar.readings(positions, headings, views[members[0]].radii)
            readings[key] = out
        return readings

    def simulators(self) -> list[Simulator]:
        """Each world's simulator (live: read it, do not step it)."""
        return [env.simulator for env in self.envs]

    def social_force(self) -> np.ndarray:
        """(num_worlds,) complex: the humans' social-force repulsion on each world's first robot."""
        return np.array([sim.robot_social_force for sim in self.simulators()], dtype=complex)

    def stalls(self) -> np.ndarray:
        """(num_worlds,) int64: how many times a human stalled this episode, per world."""
        return np.array([int(sim.human_stalls.sum()) for sim in self.simulators()], dtype=np.int64)

    def robot_goal(self, world: int) -> complex:
        return complex(self.envs[world].simulator.robot_goal)

    def frame(self, world: int) -> dict[str, np.ndarray]:
        """World ``world``'s simulator as :func:`crowdnav.envs.engines.protocol.world_frame` gives it (the other robots included)."""
        return world_frame(self.envs[world].simulator)

    def row(self, name: str, world: int) -> np.ndarray:
        """A copy of world ``world``'s simulator array ``name`` (``positions``: the first robot then the humans)."""
        values: np.ndarray = np.array(getattr(self.envs[world].simulator, name), copy=True)
        return values

    def snapshot(self, world: int) -> WorldState:
        """World ``world``'s single env's :meth:`CrowdNavEnv.snapshot`."""
        return self.envs[world].snapshot()

    def load(self, world: int, state: WorldState) -> None:
        """World ``world``'s single env's :meth:`CrowdNavEnv.load` (its observation then the world's)."""
        self.observations[world] = self.envs[world].load(state)

    def simulator(self, world: int) -> Simulator:
        """A snapshot of ``world``'s simulator (:meth:`crowdnav.Simulator.clone`): stepping it leaves the world as it is."""
        core = self.envs[world].core
        snapshot = core.simulator.clone()
        if core.tracker is not None:  # its tracks as they are now (a scripted policy reading the snapshot sees them)
            attach(snapshot, core.tracker.frozen(0))
        return snapshot
