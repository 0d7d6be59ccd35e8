"""Every robot of every world driven by the caller, the worlds stacked: :class:`StackedRobots` (a
:class:`crowdnav.envs.engines.protocol.RobotsEngine`).

The worlds are one :class:`crowdnav.batch.simulator.BatchSimulator`, their robots after the first its
:class:`crowdnav.batch.team.TeamStack`; this engine does, as array work over the worlds, what the robots-only PettingZoo
env (:class:`crowdnav.envs.parallel.CrowdNavParallelEnv`, ``humans_as_agents=False, fixed_agents=True,
flat_observations=True``) does around its simulator, so world ``i`` plays that env's episodes bit for bit:

* **actions**: each robot in the world moves by its action (the first robot included: one that left stays parked);
  a robot that left ignores its action;
* **outcomes**: each robot's own (the first robot's from the batch's events, the others' from the team's, their
  contacts named as the single simulator names them), ``truncated`` for those still running at the time limit;
* **rewards**: the single env's kernels (:func:`crowdnav.envs.reward.reward_terms`) over (W, R), each robot's goal
  distance at its last step as its progress memory, the humans' social force on it;
* **leaving**: a robot that ended leaves its world (:meth:`BatchSimulator.retire`) after the step's observation (the
  env's ``retire_robots`` after its observation): here when the next step starts, so the observation shows it;
* **observations**: each robot's modalities (``robots.<k>.modalities``, built with its own spec, as the env's core
  builds them) on its view (:func:`crowdnav.batch.robot_views.robot_view`), the worlds grouped by which robots are in
  them (a view lists only those), flattened in its Dict's key order as ``flat_observations`` flattens;
* **frames**: every robot's and human's place, the humans' force on each robot (:meth:`StackedRobots.frame`, what
  evaluation records per step), read from the stack a crowd size at a time;
* **scripted robots**: a scripted policy with a batched twin (:func:`scripted_name`: straight, social force) acts for
  any robot, the first one included, as called with that robot's view of its world
  (:meth:`StackedRobots.scripted_actions`, :func:`crowdnav.batch.robot_policies.every_robot_actions`);
* **states**: a world's :class:`crowdnav.envs.engines.world_state.WorldState` as the env holds it after its step (the robots
  leaving already out, the last observation with it: :mod:`crowdnav.envs.engines.robots_state`), which loads into either engine.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from functools import cached_property
from typing import Any

import numpy as np
from gymnasium import spaces

from crowdnav.batch.robot_policies import SEAT_POLICIES, every_robot_actions
from crowdnav.batch.robot_views import robot_view
from crowdnav.batch.simulator import BatchSimulator
from crowdnav.batch.state import BatchState
from crowdnav.batch.team import TeamStack
from crowdnav.envs.engines.protocol import RobotsFrame, RobotsStep
from crowdnav.envs.engines.robots_state import retired, robots_rows, robots_state
from crowdnav.envs.engines.world_state import WorldKey, WorldState, make_state, world_key
from crowdnav.envs.reward import REWARD_TERMS, reward_terms
from crowdnav.planning.scripted import SCRIPTED_POLICIES
from crowdnav.sensors import Modality, build_modalities
from crowdnav.sim.contacts import goal_distance
from crowdnav.sim.events import outcomes
from crowdnav.worlds.compiled import CompiledWorld

ENDED = ("collision", "out_of_bounds", "success")
"""The outcomes that end a robot's part of the episode (``truncated`` ends the whole episode instead)."""


class StackedRobots:
    """``num_worlds`` worlds of ``world`` (a ``robots:`` scenario, every env option applied) in one batch (module docstring)."""

    def __init__(self, world: CompiledWorld, num_worlds: int):
        self.batch = BatchSimulator(world, num_worlds)
        if self.batch.team is None:
            raise ValueError("StackedRobots plays a scenario with several robots (robots:)")
        self.team: TeamStack = self.batch.team
        self.num_worlds = self.batch.num_worlds
        self.robot_names: list[str] = list(self.team.names)
        scenario, slot = world.scenario, self.batch.slots[0]
        self.sensors: list[tuple[tuple[str, Modality], ...]] = []
        """Each robot's modalities in its Dict's key order (the flat observation's)."""
        for k, robot in enumerate(scenario.robot_specs):
            own = getattr(robot, "modalities", None)
            built = build_modalities(own if own is not None else scenario.sensors.modalities,
                                     dataclasses.replace(world, scenario=slot.robot_scenario(k)), scenario.sensors)
            space = spaces.Dict({key: modality.space() for key, modality in built.items()})
            self.sensors.append(tuple((key, built[key]) for key in space.spaces))
        sizes = {sum(int(spaces.flatdim(modality.space())) for _, modality in own) for own in self.sensors}
        if len(sizes) != 1:
            raise ValueError(f"the robots observe vectors of different lengths {sorted(sizes)}; a batch of robots needs one length")
        self.observation_size = sizes.pop()
        self._weights = {term: float(getattr(scenario.reward, term)) for term in REWARD_TERMS}
        r = len(self.robot_names)
        self._previous = np.zeros((self.num_worlds, r))
        """Each robot's goal distance at its last step or reset (its reward's progress memory)."""
        self._leaving = np.zeros((self.num_worlds, r), dtype=bool)
        """Robots that ended at their world's last step, leaving it before anything else happens there."""
        self._over = np.zeros(self.num_worlds, dtype=bool)
        """Worlds whose episode ended at their last step (not reset since)."""
        self._loaded = np.zeros(self.num_worlds, dtype=bool)
        self._stored = np.zeros((self.num_worlds, r, self.observation_size), np.float32)
        """Worlds loaded from a state, and (``_stored``) the observation it carried, observed until the world steps or resets."""
        self._observed: np.ndarray | None = None
        """:meth:`observe`'s last answer while it is current (a snapshot's observation: the robots leaving still in it)."""

    # ------------------------------------------------------------------ reset

    def reset(self, worlds: Sequence[int] | np.ndarray, seeds: Sequence[int | None]) -> None:
        self.batch.reset(worlds, seeds)
        worlds = np.asarray(worlds, dtype=np.int64)
        self._leaving[worlds] = False
        self._over[worlds] = self._loaded[worlds] = False
        self._observed = None
        self._previous[worlds] = self._goal_distance()[worlds]

    # ------------------------------------------------------------------- step

    def step(self, actions: np.ndarray, active: np.ndarray | None = None) -> RobotsStep:
        team, w = self.team, self.num_worlds
        stepping = np.ones(w, dtype=bool) if active is None else active
        self._observed = None
        self._leave(stepping)
        here = team.active & stepping[:, None]  # the robots that act: in a stepping world, not left
        actions = np.where(here[:, :, None], np.asarray(actions, dtype=np.float64), 0.0)  # a robot that left stands (unchecked)
        _check(actions, here, self.robot_names)
        result = self.batch.step(actions[:, 0], active, actions[:, 1:])
        outcome = np.full((w, len(self.robot_names)), None, dtype=object)
        outcome[:, 0] = outcomes(result.collided, result.left_world, result.goal_reached, result.truncated)
        running = np.full(outcome.shape, None, dtype=object)  # an other robot's outcome when it did not end: the time limit's
        running[result.truncated] = "truncated"
        outcome[:, 1:] = np.where(team.ended, team.outcome, running[:, 1:])
        outcome[~here] = None
        ended = np.logical_or.reduce([outcome == name for name in ENDED])  # (None among the names: no isin on objects)
        going = (here & ~ended).any(1)
        truncated = going & result.truncated & stepping
        over = stepping & (~going | truncated)
        self._leaving |= ended & ~over[:, None]  # (the stepping worlds' were cleared as they left)
        self._over = np.where(stepping, over, self._over)
        self._loaded &= ~stepping  # a loaded world that stepped observes its new state
        collisions = {(world, 0): contact for world, contact in result.collisions.items() if here[world, 0]}
        collisions.update(((world, j + 1), contact) for (world, j), contact in team.collisions.items() if here[world, j + 1])
        rewards, terms = self._rewards(here, outcome)
        return RobotsStep(here, rewards, terms, outcome, collisions, truncated, over)

    def _leave(self, stepping: np.ndarray) -> None:
        """The robots that ended at their world's last step leave the ``stepping`` worlds (the env's ``retire_robots`` after its
        observation); a world that waits keeps them, its observation unchanged."""
        leaving = self._leaving & stepping[:, None]
        if leaving.any():
            self.batch.retire(leaving[:, 1:], leaving[:, 0])
            self._leaving &= ~leaving

    def _rewards(self, here: np.ndarray, outcome: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Each acting robot's reward and terms (the env's Reward on its view), its progress memory moved on."""
        distance, force = self._goal_distance(), self._social_force()
        previous = self._previous
        self._previous = np.where(here, distance, previous)
        reward, terms = reward_terms(self._weights, previous, distance, np.hypot(force.real, force.imag), outcome)
        return np.where(here, reward, 0.0), {term: np.where(here, values, 0.0) for term, values in terms.items()}

    def _goal_distance(self) -> np.ndarray:
        """(W, R): every robot's goal distance now (:func:`crowdnav.sim.contacts.goal_distance`, the view's ``robot_goal_distance``)."""
        positions, goals = self._positions_and_goals()
        distance: np.ndarray = goal_distance(goals, positions)  # elementwise: the same bits as each robot's own
        return distance

    def _positions_and_goals(self) -> tuple[np.ndarray, np.ndarray]:
        """(W, R) complex each: every robot's centre and goal (the first robot's from its crowd size's stack, the team's)."""
        positions = np.zeros((self.num_worlds, len(self.robot_names)), dtype=complex)
        goals = np.zeros_like(positions)
        for bucket in self.batch.buckets.values():
            positions[bucket.world, 0], goals[bucket.world, 0] = bucket.state.positions[:, 0], bucket.state.robot_goal
        positions[:, 1:], goals[:, 1:] = self.team.positions, self.team.goals
        return positions, goals

    def _social_force(self) -> np.ndarray:
        """(W, R) complex: the humans' social force on every robot (the first robot's row of the repulsion, the team's)."""
        out = np.zeros((self.num_worlds, len(self.robot_names)), dtype=complex)
        for bucket in self.batch.buckets.values():
            out[bucket.world, 0] = bucket.repulsion[:, 0]
        out[:, 1:] = self.team.social
        return out

    # ------------------------------------------------------------------ observations

    def observe(self) -> np.ndarray:
        out = np.zeros((self.num_worlds, len(self.robot_names), self.observation_size), dtype=np.float32)
        team = self.team
        for bucket in self.batch.buckets.values():
            rows, size = np.arange(len(bucket)), self.batch.chunk_size(bucket.n)
            for start in range(0, len(rows), size):  # chunks of worlds, as the simulator steps them
                chunk = rows[start : start + size]
                state, worlds = self.batch.state(bucket, chunk), bucket.world[chunk]
                patterns, which = np.unique(team.active[worlds], axis=0, return_inverse=True)
                which = which.reshape(-1)
                for p, pattern in enumerate(patterns):  # worlds holding the same robots: their views list the same discs
                    group = np.flatnonzero(which == p)
                    part = state.rows(group)
                    for k in np.flatnonzero(pattern).tolist():  # each robot in those worlds, by its own sensors
                        out[worlds[group], k] = self._flat(part, worlds[group], k, np.flatnonzero(pattern))
        if self._loaded.any():
            out[self._loaded] = self._stored[self._loaded]
        self._observed = out
        return out

    def _flat(self, state: BatchState, worlds: np.ndarray, robot: int, present: np.ndarray) -> np.ndarray:
        """Robot ``robot``'s flat observations in ``worlds`` (``state``: their rows; ``present``: the robots in them)."""
        seen = present[present != robot]
        views: dict[bool, BatchState] = {}  # with the other robots, without them (a modality that tracks people): made once if read
        parts = []
        for _, modality in self.sensors[robot]:
            wanted = modality.sees_robots
            if wanted not in views:
                views[wanted] = robot_view(state, self.team, worlds, robot, seen if wanted else seen[:0])
            parts.append(np.asarray(modality.observe_batch(views[wanted]), dtype=modality.space().dtype).reshape(len(worlds), -1))
        return np.concatenate(parts, axis=1)

    # ------------------------------------------------------------------ scripted robots

    def scripted_actions(self, policy: Any, robots: np.ndarray) -> np.ndarray:
        """(W, R, 2) float32: scripted ``policy``'s action for each of ``robots`` ((W, R) bool), as ``policy`` returns it called
        with that robot's view of its world (``simulator.robot_view(k)``); 0 elsewhere. ``policy`` needs a batched twin
        (:func:`scripted_name`; ValueError otherwise).

        The robots that ended at the last step of the worlds of ``robots`` leave those worlds first, as the per-world env's
        had left them at that step's end (this engine defers it past the observation): read :meth:`observe` before."""
        name = scripted_name(policy)
        if name is None:
            raise ValueError(f"{type(policy).__name__} has no batched twin to drive stacked robots; play it on SingleRobots")
        out = np.zeros((self.num_worlds, len(self.robot_names), 2), dtype=np.float32)
        acting: np.ndarray = np.any(robots, axis=1)
        self._leave(acting)
        worlds = np.flatnonzero(acting)
        if len(worlds):
            out[worlds] = every_robot_actions(name, self.batch, worlds)  # (float64 of float32: exact)
        out[~robots] = 0.0
        return out

    # ------------------------------------------------------------------ frames

    def frame(self) -> RobotsFrame:
        w = self.num_worlds
        crowd = np.zeros(w, dtype=np.int64)
        for n, bucket in self.batch.buckets.items():
            crowd[bucket.world] = n
        force = self._social_force()
        positions, goals = self._positions_and_goals()
        frame = RobotsFrame(positions, goals, np.hypot(force.real, force.imag),
                            np.full((w, int(crowd.max(initial=0))), complex(np.nan, np.nan)), crowd, np.zeros(w, dtype=np.int64))
        for n, bucket in self.batch.buckets.items():  # each crowd size's worlds at once
            state, worlds = bucket.state, bucket.world
            frame.humans[worlds, :n] = state.positions[:, 1:]
            frame.stalls[worlds] = state.human_stalls.sum(axis=1)
        return frame

    def radii(self, world: int) -> tuple[np.ndarray, np.ndarray]:
        bucket, _ = self.batch.locate(world)
        return self.team.team.all_radii.copy(), bucket.radii[1:].copy()

    # ------------------------------------------------------------------ a world's state

    def snapshot(self, world: int) -> WorldState:
        episode = self.batch.snapshot(world)
        leaving = self._leaving[world]
        if leaving.any():  # out of the world in the state, as the env leaves them at its step's end (here: the next step's start)
            episode = retired(episode, self.team.state_of(world, leaving[1:]), bool(leaving[0]))
        observed = self._observed if self._observed is not None else self.observe()
        base = make_state(self.world_key, episode, tuple(self._previous[world].tolist()), None)
        return robots_state(base, not self._over[world], observed[world], self.robot_names)

    def load(self, world: int, state: WorldState) -> None:
        state, rows = robots_rows(state, self.world_key, self.robot_names, self.observation_size)
        if state.tracker is not None:
            raise ValueError("a world state with a people tracker's tracks cannot load into stacked robots (they play without a tracker)")
        self.batch.load(world, state.episode)
        self._previous[world] = state.rewards
        self._leaving[world] = False
        self._over[world] = state.env is not None and not state.env.running
        self._loaded[world], self._stored[world] = True, rows
        self._observed = None

    @cached_property
    def world_key(self) -> WorldKey:
        """What a world state must match to load here (made on first use)."""
        return world_key(self.batch.scenario)

    def close(self) -> None:
        """Nothing to release (the worlds are arrays)."""


def scripted_name(policy: Any) -> str | None:
    """The :data:`crowdnav.planning.scripted.SCRIPTED_POLICIES` name of ``policy`` (an instance of that very class: a subclass may act
    otherwise) where :class:`StackedRobots` has its batched twin (:data:`crowdnav.batch.robot_policies.SEAT_POLICIES`);
    None for the others (ORCA, the planners, a callable)."""
    return next((name for name, kind in SCRIPTED_POLICIES.items() if type(policy) is kind and name in SEAT_POLICIES), None)


def _check(actions: np.ndarray, here: np.ndarray, names: Sequence[str]) -> None:
    """The env's refusal of an acting robot's non-finite action (ValueError naming the robot), before anything moves."""
    bad = here & ~np.isfinite(actions).all(axis=2)
    if bad.any():
        world, k = (int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"the action of {names[k]} in world {world}: the robot action must be finite (no NaN or inf), "
                         f"got {actions[world, k].tolist()}")
