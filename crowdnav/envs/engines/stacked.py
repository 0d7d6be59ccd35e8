"""Worlds stacked in one batch: :class:`StackedWorlds`, the vector env's engine where stacking pays.

One :class:`crowdnav.batch.simulator.BatchSimulator` steps the worlds (array work over a world axis, one stack per
crowd size); this engine adds what a world needs beyond its simulator (:class:`crowdnav.envs.engines.protocol.WorldEngine`):
the reward (the single env's kernels, :func:`crowdnav.envs.reward.reward_terms`, over the stepping worlds, with each
world's goal distance at its last step as the progress term's memory), the observations (each modality's
``observe_batch``, chunk by chunk as the simulator steps them), the shield's batched call, the worlds' rows and a
world's state as data (its simulator's episode, its reward memory, its tracker's row).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import cached_property

import numpy as np

from crowdnav.batch.simulator import BatchSimulator, StepResult
from crowdnav.batch.state import BatchState
from crowdnav.envs.engines.protocol import Judged
from crowdnav.envs.engines.world_state import WorldKey, WorldState, check_state, make_state, world_key
from crowdnav.envs.reward import REWARD_TERMS, reward_terms
from crowdnav.planning.shield import Shield
from crowdnav.sensors import Modality
from crowdnav.sensors.tracked import attach, tracked_state
from crowdnav.sensors.tracker import make_tracker
from crowdnav.sim.contacts import goal_distance
from crowdnav.sim.events import outcomes
from crowdnav.sim.simulator import Simulator
from crowdnav.worlds.compiled import CompiledWorld


class StackedWorlds:
    """``num_worlds`` worlds of ``world`` (the compiled scenario with every env option applied) in one :class:`BatchSimulator`.

    ``modalities``: the observation's modalities by key (the vector env's). Implements
    :class:`crowdnav.envs.engines.protocol.WorldEngine`; ``batch`` is the simulator (read it, step it only through here).
    """

    def __init__(self, world: CompiledWorld, num_worlds: int, modalities: dict[str, Modality]):
        self.batch = BatchSimulator(world, num_worlds)
        self.num_worlds = self.batch.num_worlds
        self.modalities = modalities
        weights = world.scenario.reward
        self._weights = {term: float(getattr(weights, term)) for term in REWARD_TERMS}
        self._previous_distance = np.zeros(self.num_worlds)
        """Each world's robot-goal distance after its last step (the goal-progress term's memory; the single env's Reward keeps it)."""
        self.tracker = make_tracker(world, self.num_worlds)
        """The robots' people tracker, one row per world (``sensors.tracker``; None: ``perfect``)."""
        self._tracked = any(modality.reads_tracker for modality in modalities.values()) and self.tracker is not None
        """Some observed modality reads the tracker's people."""

    def reset(self, worlds: Sequence[int] | np.ndarray, seeds: Sequence[int | None] | np.ndarray) -> None:
        self.batch.reset(worlds, seeds)
        worlds = np.asarray(worlds, dtype=np.int64)
        self._previous_distance[worlds] = self._goal_distance(worlds)
        if self.tracker is not None:  # their first detections come with the next step's (or a reading's catch-up)
            self.tracker.start(worlds, list(seeds))

    def step(self, actions: np.ndarray, active: np.ndarray | None = None) -> StepResult:
        result = self.batch.step(actions, active)
        if self.tracker is not None:  # the stepped worlds' tracks, and the first ones of the worlds reset since (one call)
            self._track(None if active is None else active | self._pending_mask())
        return result

    def _pending_mask(self) -> np.ndarray:
        assert self.tracker is not None
        mask = np.zeros(self.num_worlds, dtype=bool)
        mask[self.tracker.pending] = True
        return mask

    def _track(self, worlds: np.ndarray | None) -> None:
        """The tracker's update of ``worlds`` (a bool mask; None: all), one call per crowd size."""
        assert self.tracker is not None
        for bucket in self.batch.buckets.values():
            rows = np.arange(len(bucket)) if worlds is None else np.flatnonzero(worlds[bucket.world])
            if len(rows):
                state = bucket.state
                self.tracker.update(bucket.world[rows], state.positions[rows], state.velocities[rows, 0], state.robot_heading[rows],
                                    bucket.radii)

    def _catch_up(self) -> None:
        """The first tracks of the worlds reset and not stepped since, before anything reads the tracker."""
        if self.tracker is not None and len(self.tracker.pending):
            self._track(self._pending_mask())

    def judged(self, result: StepResult, stepping: np.ndarray, every: bool) -> Judged:
        outcome = outcomes(result.collided & stepping, result.left_world & stepping, result.goal_reached & stepping, stepping)
        rewards = np.zeros(self.num_worlds)
        worlds = np.flatnonzero(stepping)
        distance = self._goal_distance(worlds)
        previous = self._previous_distance[worlds]
        self._previous_distance[worlds] = distance
        force = self.social_force()[worlds]
        rewards[stepping], terms = reward_terms(self._weights, previous, distance, np.hypot(force.real, force.imag), outcome[worlds])
        return outcome, rewards, terms

    def settle(self) -> None:
        self._previous_distance[:] = self._goal_distance(np.arange(self.num_worlds))

    def _goal_distance(self, worlds: np.ndarray) -> np.ndarray:
        """The robot-goal distance of ``worlds``: :func:`crowdnav.sim.contacts.goal_distance`, the single simulator's kernel."""
        out = np.zeros(self.num_worlds)
        for bucket in self.batch.buckets.values():
            out[bucket.world] = goal_distance(bucket.state.robot_goal, bucket.state.positions[:, 0])
        distances: np.ndarray = out[worlds]
        return distances

    def observe(self, out: Mapping[str, np.ndarray]) -> None:
        self._catch_up()
        for bucket in self.batch.buckets.values():
            rows, size = np.arange(len(bucket)), self.batch.chunk_size(bucket.n)
            for start in range(0, len(rows), size):  # chunks of worlds, as the simulator steps them
                chunk = rows[start : start + size]
                state = self.batch.state(bucket, chunk)
                people = self._people(state, bucket.world[chunk]) if self._tracked else state
                for key, values in out.items():
                    modality = self.modalities[key]
                    values[bucket.world[chunk]] = modality.observe_batch(people if modality.reads_tracker else state)

    def _people(self, state: BatchState, worlds: np.ndarray) -> BatchState:
        """``state`` of ``worlds`` with the people as their tracker reports them (``state`` itself for ``perfect``)."""
        return state if self.tracker is None else tracked_state(state, self.tracker.columns(worlds, state.n_humans))

    def shielded(self, shield: Shield, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self._catch_up()
        out, replaced = actions.copy(), np.zeros(self.num_worlds, dtype=bool)
        for bucket in self.batch.buckets.values():
            rows, size = np.arange(len(bucket)), self.batch.chunk_size(bucket.n)
            for start in range(0, len(rows), size):
                chunk = rows[start : start + size]
                worlds = bucket.world[chunk]
                out[worlds], replaced[worlds] = shield.batch(self._people(self.batch.state(bucket, chunk), worlds), actions[worlds])
        return out, replaced

    def stalls(self) -> np.ndarray:
        stalls = np.zeros(self.num_worlds, dtype=np.int64)
        for bucket in self.batch.buckets.values():  # per crowd size
            stalls[bucket.world] = bucket.state.human_stalls.sum(1)
        return stalls

    def other_robots(self, stepping: np.ndarray) -> dict[int, dict[str, str | None]]:
        return {}  # one robot per world

    def social_force(self) -> np.ndarray:
        out = np.zeros(self.num_worlds, dtype=complex)
        for bucket in self.batch.buckets.values():
            out[bucket.world] = bucket.repulsion[:, 0]
        return out

    def row(self, name: str, world: int) -> np.ndarray:
        bucket, row = self.batch.locate(world)
        values: np.ndarray = getattr(bucket.state, name)[row].copy()
        return values

    def robot_goal(self, world: int) -> complex:
        bucket, row = self.batch.locate(world)
        return complex(bucket.state.robot_goal[row])

    def frame(self, world: int) -> dict[str, np.ndarray]:
        return {"positions": self.row("positions", world), "velocities": self.row("velocities", world),
                "goals": np.concatenate([[self.robot_goal(world)], self.row("human_goals", world)]),
                "respawns": self.row("human_respawns", world)}

    def simulator(self, world: int) -> Simulator:
        snapshot = self.batch.simulator(world)
        self._catch_up()
        if self.tracker is not None:  # its tracks as they are now (a scripted policy reading the snapshot sees them)
            attach(snapshot, self.tracker.frozen(world))
        return snapshot

    def simulators(self) -> list[Simulator]:
        return [self.simulator(world) for world in range(self.num_worlds)]

    def snapshot(self, world: int) -> WorldState:
        return make_state(self.world_key, self.batch.snapshot(world), (float(self._previous_distance[world]),),
                          None if self.tracker is None else self.tracker.row_state(world))

    def load(self, world: int, state: WorldState) -> None:
        state = check_state(state, self.world_key)
        self.batch.load(world, state.episode)
        (self._previous_distance[world],) = state.rewards
        if self.tracker is not None and state.tracker is not None:  # (the same sensors: checked)
            self.tracker.load_row(world, state.tracker)

    @cached_property
    def world_key(self) -> WorldKey:
        """What a world state must match to load here (made on first use)."""
        return world_key(self.batch.scenario)
