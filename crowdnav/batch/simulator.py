"""Many worlds of one scenario stepped as one batch: the simulator of the native vector env.

World ``i`` of a batch evolves exactly, bit for bit, like a :class:`crowdnav.Simulator` given the
same seed and actions: every quantity is computed with the same numpy operations on the same
values, in the same order, with a leading world axis (see :mod:`crowdnav.batch.scalar_math` for
the robot's scalar math). Worlds whose crowds differ in size are kept in one stack per size (a
*bucket*): padding a crowd would change the length of the force sums, and numpy's pairwise
summation rounds differently for another length, so a padded world would drift from the single
simulator in the last bits (:class:`crowdnav.batch.bucket.Bucket`). A step loops over the crowd sizes present (a scenario's count range),
never over worlds, humans, pairs or edges.

A bucket's episode state is one :class:`crowdnav.batch.stacked_state.StackedState` (SimState's fields with a leading world axis),
its geometry the same arrays a :class:`crowdnav.Simulator` measures, stacked. Resets, and the
goal rules of worlds where a human reached its goal or stalled, draw from each world's own generator: they
run per world (the arrival and stall checks themselves run on all worlds at once). A reset draws on the world's own
:class:`crowdnav.Simulator` (its *slot*) and its state is copied into the stack; the goal rules (:func:`crowdnav.sim.groups.apply_goal_rules`) change
the world's row of the stack in place, drawing from the slot's generator. Crowds large enough for the neighbour grid
(``Simulator.grid_from`` humans) are not stacked (the vector env holds them as single envs). A ``robots:`` scenario's other
robots are every world's :class:`crowdnav.batch.team.TeamStack` (indexed by world): they move after the robot and the
humans, measure their geometry and push the humans in every refresh, and end, as the single simulator's :class:`Team`
does (its operations with a world axis). The humans' commands come from the crowd models
(:mod:`crowdnav.crowd`) through :meth:`crowdnav.crowd.Crowd.commands_batch`, each world with its
slot's own model instances (ORCA: the slot's solver, one world per pyrvo call).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from crowdnav.batch.bucket import Bucket
from crowdnav.batch.scalar_math import robot_velocity
from crowdnav.batch.state import BatchState
from crowdnav.batch.team import TeamStack
from crowdnav.crowd.base import CrowdView
from crowdnav.crowd.views import worlds_view
from crowdnav.sim.contacts import deepest_contact, goal_distance, outside, resolve_overlaps, touching
from crowdnav.sim.episode_state import EpisodeState, capture, restore
from crowdnav.sim.events import Collision, check_finite
from crowdnav.sim.geometry import measure
from crowdnav.sim.groups import apply_goal_rules, goal_checks
from crowdnav.sim.robots import PARKED
from crowdnav.sim.simulator import Simulator, place_humans
from crowdnav.sim.state import SimState
from crowdnav.worlds.compiled import CompiledWorld
from crowdnav.worlds.obstacles import EdgeSet

CHUNK_ELEMENTS = 65_536
"""Worlds are stepped in chunks of about this many agent-column entries ((n+1) x (n+1+obstacles) per world):
larger temporaries leave the CPU caches. Measured (benchmarks/bench_vector.py, 64 worlds): 50 humans ran at
4,700 env-steps/s in one chunk and 7,400 in chunks of 19; 10 humans (one chunk either way) did not change."""


@dataclass
class StepResult:
    """What happened in every world during one batch step (arrays over all worlds of the batch)."""

    goal_reached: np.ndarray
    left_world: np.ndarray
    truncated: np.ndarray
    collisions: dict[int, Collision] = field(default_factory=dict)
    """World index -> the robot's deepest contact, for the worlds where the robot collided."""

    @property
    def collided(self) -> np.ndarray:
        out = np.zeros(len(self.goal_reached), dtype=bool)
        if self.collisions:
            out[list(self.collisions)] = True
        return out

    @property
    def terminated(self) -> np.ndarray:
        ended: np.ndarray = self.goal_reached | self.left_world | self.collided
        return ended


class BatchSimulator:
    """``num_worlds`` copies of one compiled world, reset one by one and stepped together.

    >>> batch = BatchSimulator(load_world("room_furniture"), 4)
    >>> batch.reset(range(4), [0, 1, 2, 3])
    >>> result = batch.step(np.zeros((4, 2)))
    """

    def __init__(self, world: CompiledWorld, num_worlds: int):
        if isinstance(num_worlds, bool) or not isinstance(num_worlds, (int, np.integer)) or num_worlds < 1:
            raise ValueError(f"num_worlds must be a positive integer, got {num_worlds!r}")
        self.num_worlds = int(num_worlds)
        self.slots = [Simulator(world) for _ in range(self.num_worlds)]
        """One single simulator per world: its resets and goal rules (each world's own generator)."""
        first = self.slots[0]
        for slot in self.slots[1:]:  # one bounded cache of pair constants for all the worlds, not one per world
            slot.share_constants(first)
        self.world = world
        self.scenario = world.scenario
        self.dt = first.dt
        if first.max_humans >= first.grid_from:
            raise ValueError(f"the batched simulator handles crowds below {first.grid_from} humans (all pairs); this scenario allows "
                             f"{first.max_humans}: step its worlds with crowdnav.envs.vector.env.CrowdNavVectorEnv (single envs, the neighbour grid)")
        obstacles = world.obstacles
        self._surface: EdgeSet | None = first.geometry.surface
        self._polygons = obstacles.polygon_count
        self._static_count = first.geometry.static_count
        self._labels = obstacles.labels + obstacles.disc_labels
        self._bounds = first.bounds
        self._substeps, self._substep_dt = first.substeps, first.substep_dt
        self._crowd = first.crowd
        """The first world's crowd models, for what all worlds share (which models, which groups)."""
        self._crowds = np.empty(self.num_worlds, dtype=object)
        self._crowds[:] = [slot.crowd for slot in self.slots]
        """Each world's own crowd models (its slot's), indexed by world."""
        self.team = None if first.team is None else TeamStack(first.team, self.num_worlds, first.bounds, first.dt,
                                                                     self.scenario.humans.social_force)
        """A ``robots:`` scenario's other robots, every world's (:mod:`crowdnav.batch.team`); None for one robot."""
        self.buckets: dict[int, Bucket] = {}
        self._where = np.full((self.num_worlds, 2), -1, dtype=np.intp)  # world -> (crowd size, row); -1: never reset

    # ------------------------------------------------------------------ reset

    def reset(self, worlds: Sequence[int] | np.ndarray, seeds: Sequence[int | None] | np.ndarray) -> None:
        """Start a new episode in each of ``worlds`` (``seeds[k]`` for ``worlds[k]``; None continues its generator)."""
        fresh: dict[int, list[int]] = {}
        for world, seed in zip(worlds, seeds, strict=True):  # per reset event: placement draws from each world's generator
            slot = self.slots[world]
            slot.draw_episode(seed)
            if self.team is not None and slot.team is not None:
                self.team.set_world(int(world), slot.team.state)
            n = self._stack(int(world), slot.state)
            fresh.setdefault(n, []).append(int(world))
        for n, fresh_worlds in fresh.items():  # one geometry pass per crowd size for all the new episodes
            self._refresh(self.buckets[n], self._where[fresh_worlds, 1])

    def _stack(self, world: int, state: SimState) -> int:
        """``world``'s row of the stack of its crowd size becomes (a copy of) ``state`` (moved from another size's); returns the size."""
        n = state.n_humans
        size, row = self._where[world]
        if size == n:
            self.buckets[n].replace(row, state)
        else:
            if size >= 0:
                self._drop(world, size, row)
            bucket = self.buckets.get(n)
            if bucket is None:
                bucket = self.buckets[n] = Bucket(n, self.slots[world].pair_constants(n), world, state)
            else:
                bucket.add(world, state)
            self._where[world] = n, len(bucket) - 1
        return n

    def _drop(self, world: int, size: int, row: int) -> None:
        bucket = self.buckets[size]
        bucket.remove(row)
        self._where[bucket.world, 1] = np.arange(len(bucket))
        if not len(bucket):
            del self.buckets[size]

    def locate(self, world: int) -> tuple[Bucket, int]:
        """The bucket holding ``world`` and its row there."""
        size, row = self._where[world]
        if size < 0:
            raise RuntimeError(f"world {world} has not been reset")
        return self.buckets[int(size)], int(row)

    def simulator(self, world: int) -> Simulator:
        """A snapshot of ``world`` now: a :class:`Simulator` holding a copy of its current state, geometry measured.

        Built on each call (the world's slot cloned with its row of the stack): later steps of the
        batch do not change it, and stepping it does not change the batch (its own generator copy).
        """
        bucket, row = self.locate(world)
        return self._synced(world).clone(bucket.state.row(row))

    def snapshot(self, world: int) -> EpisodeState:
        """``world``'s episode now (:func:`crowdnav.sim.episode_state.capture`): its row of the stack, its slot's generator and crowd models."""
        bucket, row = self.locate(world)
        return capture(self._synced(world), bucket.state.row(row))

    def _synced(self, world: int) -> Simulator:
        """``world``'s slot, its other robots (if any) set to the world's now (what a capture, a clone or a goal rule reads)."""
        slot = self.slots[world]
        if self.team is not None and slot.team is not None:
            slot.team.state = self.team.state_of(world)
        return slot

    def load(self, world: int, episode: EpisodeState) -> None:
        """Make ``episode`` (a :meth:`snapshot` of a world of this scenario, or a single simulator's) ``world``'s: its slot takes
        the generator and crowd models' state, its row of the stack the state, measured as a reset's."""
        if not 0 <= world < self.num_worlds:
            raise ValueError(f"world must be in [0, {self.num_worlds}), got {world}")
        slot = self.slots[world]
        restore(slot, episode)
        if self.team is not None and slot.team is not None:
            self.team.set_world(int(world), slot.team.state)
        n = self._stack(int(world), slot.state)
        self._refresh(self.buckets[n], self._where[[world], 1])

    # ------------------------------------------------------------------- step

    def step(self, actions: np.ndarray, active: np.ndarray | None = None, other_actions: np.ndarray | None = None) -> StepResult:
        """Advance the worlds where ``active`` is True (default: all) by one step; ``actions`` (num_worlds, 2), checked finite;
        ``other_actions``: a ``robots:`` scenario's other robots' (num_worlds, m, 2) (None: they stand still).

        Inactive worlds are left exactly as they are.
        """
        b = self.num_worlds
        result = StepResult(np.zeros(b, dtype=bool), np.zeros(b, dtype=bool), np.zeros(b, dtype=bool))
        if self.team is not None:
            self.team.collisions.clear()  # this step's contacts of the other robots only
        for bucket in self.buckets.values():
            rows = np.arange(len(bucket)) if active is None else np.flatnonzero(active[bucket.world])
            size = self.chunk_size(bucket.n)
            for start in range(0, len(rows), size):  # a loop over chunks of worlds, for the caches
                chunk = rows[start : start + size]
                worlds = bucket.world[chunk]
                self._advance(bucket, chunk, actions[worlds], result, None if other_actions is None else other_actions[worlds])
        return result

    def chunk_size(self, n: int) -> int:
        """Worlds of ``n`` humans stepped (and observed) together: :data:`CHUNK_ELEMENTS` over one world's (n+1) x (n+1+obstacles)."""
        return max(1, CHUNK_ELEMENTS // ((n + 1) * (n + 1 + self._static_count)))

    def _advance(self, bucket: Bucket, rows: np.ndarray, actions: np.ndarray, result: StepResult, other_actions: np.ndarray | None) -> None:
        n, dt, state = bucket.n, self.dt, bucket.state
        positions = state.positions[rows]
        velocities = state.velocities[rows]
        robot_re, robot_im, heading = self._robot_velocity(actions, state.robot_heading[rows])
        if self.team is not None:
            here = self.team.active[bucket.world[rows], 0]
            if not here.all():  # a first robot that left stays parked, its heading kept (Simulator._robot_velocity)
                robot_re, robot_im = np.where(here, robot_re, 0.0), np.where(here, robot_im, 0.0)
                heading = np.where(here, heading, state.robot_heading[rows])
        if n:
            view = self._view(bucket, rows, positions, velocities)
            commands = self._crowd.commands_batch(view, self._crowds[bucket.world[rows]])
            stopped = state.human_stopped[rows]
            if stopped.any():  # np.where picks the command itself where not stopped: exact for the others
                commands = np.where(stopped, 0.0, commands)
            velocities[:, 1:] = commands
        velocities.real[:, 0], velocities.imag[:, 0] = robot_re, robot_im  # exactly the scalar's parts
        # as Simulator.step: the robot's whole step, the humans' first sub-step (dt / 1 is dt)
        positions[:, :1] += velocities[:, :1] * dt
        positions[:, 1:] += velocities[:, 1:] * self._substep_dt
        state.robot_heading[rows] = heading
        if self.team is not None:  # the other robots, each by its own kinematics (standing still without actions)
            worlds = bucket.world[rows]
            still = np.zeros((len(rows), len(self.team.specs), 2))
            self.team.move(worlds, still if other_actions is None else other_actions, dt)
        state.step_count[rows] += 1
        check_finite(positions, velocities, state.step_count[rows], bucket.world[rows])
        state.positions[rows], state.velocities[rows] = positions, velocities
        self._refresh(bucket, rows)
        if n:
            for _ in range(1, self._substeps):  # the other sub-steps, each after the last one's contacts (Simulator.step)
                touch = rows[bucket.humans_touch[rows]]
                if len(touch):
                    self._resolve_overlaps(bucket, touch)
                state.positions[rows, 1:] += velocities[:, 1:] * self._substep_dt
                self._refresh(bucket, rows)
            touch = rows[bucket.humans_touch[rows]]
            if len(touch):
                self._resolve_overlaps(bucket, touch)
                self._refresh(bucket, touch)
            if self._crowd.places:  # after the pushes, as Simulator.step: placed humans where their model puts them
                self._place(bucket, rows)
                self._refresh(bucket, rows)
        self._robot_events(bucket, rows, result)
        if n:
            self._goal_rules(bucket, rows)
        result.truncated[bucket.world[rows]] = state.step_count[rows] >= self.scenario.max_steps

    def _place(self, bucket: Bucket, rows: np.ndarray) -> None:
        """:func:`crowdnav.sim.simulator.place_humans` for ``rows``, world by world (each world's own model instances, e.g. its
        recording window), on the views of their rows of the stack."""
        state = bucket.state
        view = self._view(bucket, rows, state.positions[rows], state.velocities[rows])
        for k, row in enumerate(rows):  # per world
            place_humans(self._crowds[bucket.world[row]], view.world(k), state.positions[row], state.velocities[row])

    def _view(self, bucket: Bucket, rows: np.ndarray, positions: np.ndarray, velocities: np.ndarray) -> CrowdView:
        """The crowd models' view of ``rows`` (``positions``, ``velocities``: their (K, n+1) arrays now)."""
        return worlds_view(bucket.state, rows, positions, velocities, bucket.radii, self.scenario.robot.max_speed,
                           lambda: self.social_force_commands(bucket, rows, positions, velocities))

    def social_force_commands(self, bucket: Bucket, rows: np.ndarray, positions: np.ndarray, velocities: np.ndarray) -> np.ndarray:
        """(K, n) :meth:`Simulator.social_force_commands` of ``rows``, every world's at once (``positions`` and ``velocities``:
        the step's (K, n+1) copies of the rows): the single simulator's kernel, :meth:`Simulator.social_force`."""
        state = bucket.state
        return self.slots[0].social_force(positions[:, 1:], velocities[:, 1:], state.human_goals[rows], state.human_group[rows],
                                          state.human_stopped[rows], state.human_preferred_speed[rows], state.command_cap[rows],
                                          bucket.repulsion[rows, 1:])

    def _robot_velocity(self, actions: np.ndarray, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`crowdnav.Simulator._robot_velocity` for every row: (velocity re, im, new heading), in CPython's scalar arithmetic."""
        return robot_velocity(self.scenario.robot, self.dt, actions, heading)

    # --------------------------------------------------------------- geometry

    def _refresh(self, bucket: Bucket, rows: np.ndarray) -> None:
        """:meth:`Simulator.refresh` for ``rows`` of ``bucket``: the same kernel, :func:`crowdnav.sim.geometry.measure`."""
        z = bucket.state.positions[rows]
        measured = measure(z, self._surface, self._polygons, bucket.contact_all, bucket.gain, bucket.decay)
        if self.team is not None:  # the other robots measure theirs and push the humans (Geometry.measure)
            self.team.refresh(bucket.world[rows], z, measured.repulsion)
        bucket.store(rows, measured)

    def _resolve_overlaps(self, bucket: Bucket, rows: np.ndarray) -> None:
        """:meth:`crowdnav.sim.geometry.Geometry.push_humans_apart` for ``rows`` (worlds where a human touches someone or something)."""
        positions = bucket.state.positions[rows]
        resolve_overlaps(positions, bucket.pair_offset[rows], bucket.pair_distance[rows], bucket.gap[rows], bucket.contact_all, self._surface)
        bucket.state.positions[rows] = positions

    def retire(self, robots: np.ndarray, first: np.ndarray | None = None) -> None:
        """The other robots ``robots`` ((num_worlds, m) bool) and the first robots ``first`` ((num_worlds,) bool; None: none) leave
        their worlds (:meth:`crowdnav.Simulator.retire_robots`), measured again.

        The Gymnasium env's first robot never leaves (its world's episode ends with it); a caller that drives every robot
        retires it as the robots-only PettingZoo env does: parked, still, its place kept in ``left_at``."""
        assert self.team is not None
        team = self.team
        for bucket in self.buckets.values():
            ego = np.zeros(len(bucket), dtype=bool) if first is None else first[bucket.world]
            rows = np.flatnonzero(robots[bucket.world].any(1) | ego)
            if len(rows):
                worlds = bucket.world[rows]
                parked = rows[ego[rows]]
                if len(parked):  # retire_robots' branch for robot 0: its centre and velocity live in the world's own state
                    state, home = bucket.state, bucket.world[parked]
                    team.active[home, 0] = False
                    team.left_at[home, 0] = state.positions[parked, 0]
                    state.positions[parked, 0], state.velocities[parked, 0] = PARKED, 0.0
                team.retire(worlds, robots[worlds])
                self._refresh(bucket, rows)

    # ----------------------------------------------------------------- events

    def _robot_events(self, bucket: Bucket, rows: np.ndarray, result: StepResult) -> None:
        n, worlds = bucket.n, bucket.world[rows]
        robot_gap = bucket.gap[rows, 0]
        if robot_gap.shape[1]:
            for k in np.flatnonzero(touching(robot_gap)):  # per collision event
                result.collisions[int(worlds[k])] = deepest_contact(robot_gap[k], n, self._labels)
        robot = bucket.state.positions[rows, 0]
        if self._bounds is not None:
            result.left_world[worlds] = outside(robot.real, robot.imag, self._bounds)
        result.goal_reached[worlds] = goal_distance(bucket.state.robot_goal[rows], robot) <= self.scenario.robot.goal_radius
        if self.team is not None:  # the ego robot's contacts with the other robots, every other robot's outcome (Team.outcomes)
            self.team.events(worlds, n, result.collisions)

    def _goal_rules(self, bucket: Bucket, rows: np.ndarray) -> None:
        """The single simulator's goal checks on every row at once (:func:`crowdnav.sim.groups.goal_checks`), then its goal rules
        (:func:`crowdnav.sim.groups.apply_goal_rules`) in the worlds where they have something to do (someone arrived or stalled)."""
        state = bucket.state
        checks = goal_checks(state, self.slots[0], rows)
        moved = []
        for k in np.flatnonzero(checks.rules):  # per event: the rules draw from the world's generator
            row = rows[k]
            stalled = None if checks.stalled is None else checks.stalled[k]
            # on the world's row of the stack, in place (views), with its slot's groups and generator
            if apply_goal_rules(state.row(row), self._synced(int(bucket.world[row])), checks.arrived[k], stalled):
                moved.append(row)
        if moved:  # respawned humans: the geometry of the new positions, as the single simulator's refresh
            self._refresh(bucket, np.array(moved))

    # ------------------------------------------------------------------ views

    def state(self, bucket: Bucket, rows: np.ndarray | None = None) -> BatchState:
        """What the sensors read, for ``rows`` of ``bucket`` (default: all)."""
        rows = np.arange(len(bucket)) if rows is None else rows
        state = bucket.state
        return BatchState(
            positions=state.positions[rows], velocities=state.velocities[rows], robot_heading=state.robot_heading[rows],
            robot_goal=state.robot_goal[rows], radii=bucket.radii, robot_offset=bucket.pair_offset[rows, 0],
            robot_distance=bucket.pair_distance[rows, 0], polygon_offset=bucket.polygon_offset[rows],
            polygon_distance=bucket.polygon_distance[rows], disc_offset=bucket.disc_offset[rows], disc_distance=bucket.disc_distance[rows],
        )
