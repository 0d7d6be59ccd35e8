"""The crowd simulator: one robot and a crowd of social-force (or ORCA) humans among static obstacles.

State lives in numpy arrays indexed by agent, robot first: ``positions[0]`` is the robot,
``positions[1:]`` the active humans. Points and velocities are complex numbers
(``x + 1j*y``, metres and m/s, world frame). A step costs a fixed number of array operations
whatever the crowd size: there is no Python loop over humans, pairs or edges. Up to
``grid_from`` humans every pair is measured; larger crowds measure only pairs within the
human-human force's reach, found with a grid of cells (:mod:`crowdnav.crowd_grid`, the same model
within a stated tolerance).

Each walking group's humans take their velocity commands from the group's crowd model (the
social force, ORCA, ...: :mod:`crowdnav.crowd`, held as :attr:`Simulator.crowd`); everything
after the command is the same.

Step order: humans' commands (social force or ORCA, or given actions) and robot kinematics ->
integrate -> measure the new geometry once (pairwise distances, nearest obstacle points) ->
keep humans out of walls and of each other -> robot collision, world-exit and goal checks ->
humans at their goals follow the scenario's ``on_goal`` rule.
The measuring and what is read from it (``refresh``, the overlap pushes, the robot's collision
and world-exit checks) live in :mod:`crowdnav.sim_geometry` (:class:`crowdnav.sim_geometry.SimGeometry`,
a mixin of this class); this module draws episodes and steps them.

The robot cannot escape the task: leaving the world (its centre outside the scenario's
``world.min`` / ``world.max`` rectangle) is either impossible (``world.boundary_walls``: the
walls are obstacles, touching them is a collision) or ends the episode with the outcome
``out_of_bounds`` (open space).

The episode's state is one declared :class:`crowdnav.sim_state.SimState` the simulator owns
(:attr:`Simulator.state`); its fields read as the simulator's attributes (``sim.positions``,
``sim.human_goals``, ...: :class:`crowdnav.sim_state.StateFields`). Only the simulator's
methods change it (:meth:`Simulator.step`, :meth:`Simulator.stop_humans`, the goal rules it
runs); staging a scene by hand (tests, scripted set-ups) writes those arrays and then calls
:meth:`Simulator.refresh`.

A scenario with ``robots:`` has several robots: agent 0 stays the first (ego) robot and the
others live in :attr:`Simulator.team` (:mod:`crowdnav.robots`; None for one robot, whose step
is unchanged); :attr:`Simulator.robot_events` holds every robot's events of the last step.

Randomness comes only from the generator seeded by :meth:`Simulator.reset`.
"""

from __future__ import annotations

import copy
import math
from typing import cast

import numpy as np

from crowdnav import social_force as sf
from crowdnav.contacts import goal_distance
from crowdnav.crowd import Crowd
from crowdnav.crowd.views import WorldView
from crowdnav.events import OUTCOMES, Collision, SimulationError, StepEvents  # noqa: F401  (re-exported: their public home)
from crowdnav.groups import apply_goal_rules, first_goals, place_groups, stall_window, together_table
from crowdnav.placement import JITTER_REACH
from crowdnav.robot_view import RobotAccessors, robot_scenario
from crowdnav.robots import PARKED, Team, first_heading, robot_kinematics
from crowdnav.scenario.loader import Overrides
from crowdnav.scenario.schema import HumanGroup
from crowdnav.sim_geometry import SimGeometry
from crowdnav.sim_state import PairConstants, SimState, StateFields, pair_constants
from crowdnav.world import CompiledWorld, WorldSource, load_world

_NO_TABLE = np.zeros((0, 0))
"""The all-pairs tables of a crowd on the neighbour grid, which has none (and never reads them)."""


class Simulator(StateFields, RobotAccessors, SimGeometry):
    """Vectorized crowd simulator for one scenario.

    >>> sim = Simulator("room_furniture")
    >>> sim.reset(seed=0)
    >>> events = sim.step(np.array([1.0, 0.0]))

    ``scenario``: a library name, YAML path, mapping or Scenario (loaded and compiled by
    :func:`crowdnav.world.load_world`), or an already compiled world (then no ``overrides``).
    """

    grid_from: int = 200
    """Crowds of at least this many humans use the neighbour grid (:mod:`crowdnav.crowd_grid`) instead of
    all pairs: the same model within a stated tolerance, at a cost that grows with n instead of n^2."""

    def __init__(self, scenario: WorldSource | CompiledWorld, overrides: Overrides | None = None):
        if isinstance(scenario, CompiledWorld):
            if overrides:
                raise ValueError("overrides apply when a scenario is loaded, not to an already compiled world")
            self.world = scenario
        else:
            self.world = load_world(scenario, overrides)
        self.scenario = scenario = self.world.scenario
        self.obstacles = self.world.obstacles
        self.placement = self.world.placement
        self.dt = scenario.time_step
        self.groups = [group for _, group in scenario.humans.crowd]
        """The crowd's groups in file order (one, named ``crowd``, for a file without ``humans.groups``)."""
        self.together = together_table(self.groups)
        """(G,) bool: the groups that walk together (``walk_together``; :func:`crowdnav.social_force.group_force`); None: none does."""
        self.max_humans = scenario.humans.max_count
        force = scenario.humans.social_force
        self._force = force
        self.relaxation = min(1.0, self.dt / force.relaxation_time)
        """``min(1, dt / relaxation_time)``: the share of the way to its desired velocity a human goes in one step."""
        self._static_count = self.obstacles.polygon_count + self.obstacles.disc_count
        self.stall_window = stall_window(scenario)
        """Steps between stall checks (``humans.stall``; 0: none): :func:`crowdnav.groups.apply_goal_rules`."""
        world = scenario.world
        self.bounds: tuple[float, float, float, float] | None = (
            None if world.boundary_walls else (float(world.min[0]), float(world.min[1]), float(world.max[0]), float(world.max[1])))
        """Open space: ``(x0, y0, x1, y1)`` (m), the rectangle the robot's centre must stay in (None: boundary walls keep it in)."""
        self._rng = np.random.default_rng()
        self._constants: dict[tuple[int, bool], PairConstants] = {}
        self.team = Team(scenario, self.obstacles, self.placement) if scenario.robots is not None else None
        """The robots after the first (:mod:`crowdnav.robots`) of a scenario with ``robots:``; None for one robot."""
        self._robot_scenarios = [robot_scenario(scenario, k) for k in range(len(scenario.robot_specs))]
        self.robot_events: list[StepEvents | None] = []
        """Every robot's events of the last step, the ego robot first (None: it had left); one robot: ``[events]``."""
        self.crowd = Crowd(self.world)
        """The crowd models of the walking groups (:mod:`crowdnav.crowd`); a model that cannot run (ORCA without pyrvo)
        fails here, at load, in one line naming the scenario field that asked for it."""
        self._ready = False

    # ----------------------------------------------------------------- state views

    @property
    def state(self) -> SimState:
        """The episode's state (the simulator's own: read it; it changes through the simulator's methods)."""
        if not self._ready:  # _state is set by the first reset
            raise RuntimeError("call reset() before reading the simulator's state")
        return self._state

    @property
    def robot_position(self) -> complex:
        return complex(self._state.positions[0])

    @property
    def human_positions(self) -> np.ndarray:
        return self._state.positions[1:]

    @property
    def human_velocities(self) -> np.ndarray:
        return self._state.velocities[1:]

    @property
    def robot_goal_distance(self) -> float:
        distance: float = abs(self._state.robot_goal - self._state.positions[0])
        return distance

    @property
    def rng(self) -> np.random.Generator:
        """The episode's generator (seeded by reset); use it for any episode randomness."""
        return self._rng

    # ----------------------------------------------------------------------- reset

    def reset(self, seed: int | None = None) -> None:
        """Start an episode; the same seed gives the same episode bit for bit (seed: a non-negative integer or None)."""
        self.draw_episode(seed)
        self.refresh()

    def draw_episode(self, seed: int | None = None) -> None:
        """:meth:`reset` without measuring the geometry (the batched simulator measures many worlds' at once)."""
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
                raise ValueError(f"seed must be a non-negative integer or None, got {seed!r}")
            self._rng = np.random.default_rng(seed)
        rng, robot, placement = self._rng, self.scenario.robot, self.placement
        counts = [int(rng.integers(group.min_count, group.max_count + 1)) for group in self.groups]
        n = sum(counts)
        start = placement.robot_start.draw(rng, 1, allowed=cast(np.ndarray, placement.start_goal_ok.any(1)))
        reachable = None
        if placement.start_component is not None:  # walls split the free space: a goal on the start's side
            nearest = int(np.argmin(np.abs(placement.robot_start.points - start[0])))
            reachable = placement.goal_component == placement.start_component[nearest]
        goal = placement.robot_goal.draw(
            rng, 1, allowed=reachable, away_from=start, min_distance=robot.min_start_goal_distance + JITTER_REACH
        )[0]
        heading = first_heading(robot, rng, complex(start[0]), complex(goal))
        # the other robots after the ego robot's draws, so a one-robot scenario draws what it always drew
        starts, goals = self.team.draw(rng, complex(start[0]), complex(goal)) if self.team is not None else (start, goal)
        # groups in file order, each away from the robots and the groups before it; then goals, then speeds
        # (one group draws exactly what the crowd drew before groups existed: same seed, same episode)
        spawn = place_groups(self, starts, goals, counts)
        standing = np.repeat([group.standing for group in self.groups], counts).astype(bool)
        human_goals = np.concatenate([np.zeros(0, dtype=complex), *first_goals(self, spawn)])
        preferred_speed = np.concatenate([np.zeros(0), *(_preferred_speeds(rng, group, count)
                                                         for group, count in zip(self.groups, counts, strict=True))])
        max_speed = preferred_speed * self._force.max_speed_factor
        positions = np.concatenate([start, *spawn])
        self._state = SimState(
            positions=positions,
            velocities=np.zeros(n + 1, dtype=complex),
            robot_goal=complex(goal),
            robot_heading=heading,
            step_count=0,
            human_group=np.repeat(np.arange(len(counts)), counts),
            human_goals=human_goals,
            human_preferred_speed=preferred_speed,
            human_max_speed=max_speed,
            # standing members have no speed; a cap of 1 keeps the shared command formula free of 0 / 0
            command_cap=np.where(standing, 1.0, max_speed) if standing.any() else max_speed,
            human_stopped=standing.copy(),
            human_arrived=np.zeros(n, dtype=bool),
            human_respawns=np.zeros(n, dtype=np.int64),
            human_stall_mark=np.abs(human_goals - positions[1:]),  # the first stall window counts from the start
            human_stalls=np.zeros(n, dtype=np.int64),
        )
        self._use_pair_constants(n)
        self._ready = True
        self.crowd.start_episode(WorldView(self), rng)
        if self.crowd.places:  # recorded people where the recording has them, stopped humans for the whole episode
            for index, _, _ in self._place_humans():
                self._state.human_stopped[index] = True

    def pair_constants(self, n: int) -> PairConstants:
        """The repulsion constants of a crowd of ``n`` humans (:func:`crowdnav.sim_state.pair_constants`, cached per ``n``)."""
        key = (n, n >= self.grid_from)
        cached = self._constants.get(key)
        if cached is None:
            cached = self._constants[key] = pair_constants(self.scenario, self.obstacles, n, grid=key[1])
        return cached

    def _use_pair_constants(self, n: int) -> None:
        constants = self.pair_constants(n)
        self.radii = constants.radii
        """(n+1,) body radii (m), robot first."""
        self._grid = constants.grid
        if constants.gain is None or constants.decay is None or constants.contact_all is None:
            self._gain = self._decay = self._contact_all = _NO_TABLE  # a grid crowd: refresh() reads the grid's instead
        else:
            self._gain, self._decay, self._contact_all = constants.gain, constants.decay, constants.contact_all

    def load_state(self, state: SimState) -> None:
        """Make ``state`` (one world's, owned by this simulator from now on) the episode's state and measure its geometry.

        For a state of the episode this simulator drew last (:meth:`draw_episode`): its groups'
        ORCA solver and its generator stay this simulator's.
        """
        self._state = state
        self._use_pair_constants(state.n_humans)
        self._ready = True
        self.refresh()

    def clone(self, state: SimState | None = None) -> Simulator:
        """An independent copy holding a copy of ``state`` (default: this simulator's), the geometry measured.

        It shares the compiled world and the constants (never written) and gets its own copy of the
        generator: stepping one leaves the other as it is (an ORCA solver is shared, but it is set
        from the state at every step). ``state``: one world's, of the episode this simulator drew.
        """
        twin = copy.copy(self)
        twin._rng = copy.deepcopy(self._rng)
        twin.crowd = self.crowd.copy()  # a model's episode state (recorded people reacting) is the twin's own
        if self.team is not None:  # its own robots (the constants stay shared)
            twin.team = copy.copy(self.team)
            twin.team.state = self.team.state.copy()
        twin.load_state((self.state if state is None else state).copy())
        return twin

    # ------------------------------------------------------------------------ step

    def step(self, robot_action: np.ndarray, human_actions: np.ndarray | None = None, other_robot_actions: np.ndarray | None = None) -> StepEvents:
        """Advance one time step; returns the ego robot's events (every robot's: :attr:`robot_events`).

        ``robot_action``: 2 values in [-1, 1] (holonomic: vx, vy in the robot frame; unicycle:
        v, omega), scaled by the max speeds. ``human_actions``: optional (n_humans, 2) velocity
        commands in [-1, 1] times each human's max speed (world frame); by default the humans
        follow the social-force model. ``other_robot_actions``: with ``robots:``, the (R-1, 2)
        actions of the robots after the first, like ``robot_action`` (None: they stand still).
        """
        if not self._ready:
            raise RuntimeError("call reset() before step()")
        state = self._state
        if self.team is not None:  # before anything moves: a bad action leaves the state as it was
            other_robot_actions = self.team.checked_actions(other_robot_actions)
        robot_velocity = self._robot_velocity(robot_action)
        if human_actions is None:
            commands = self.crowd_commands()
        else:
            commands = self._scaled_commands(human_actions)
        if state.human_stopped.any():  # standing groups, arrivals under on_goal: stop, humans a multi-agent env let leave
            commands = np.where(state.human_stopped, 0.0, commands)
        velocities, positions = state.velocities, state.positions
        velocities[0] = robot_velocity
        velocities[1:] = commands
        positions += velocities * self.dt
        if self.team is not None:
            self.team.move(other_robot_actions, self.dt)
        state.step_count += 1
        # one cheap check per step, so a non-finite state stops the episode with its name
        # instead of leaking NaN into rewards while the observations stay finite
        if not np.isfinite(positions).all():
            bad = np.flatnonzero(~np.isfinite(positions))
            who = "the robot" if bad[0] == 0 else f"human {bad[0] - 1}"
            raise SimulationError(f"step {state.step_count}: the position of {who} became non-finite (its velocity: {velocities[bad[0]]}); "
                                  "check the scenario's social_force parameters")
        self.refresh()
        n = len(positions) - 1
        if n and self._humans_touch:  # a human touches someone or something
            self._resolve_human_overlaps()
            self.refresh()
        if n and self.crowd.places:  # after the pushes: placed humans are exactly where their model puts them
            self._place_humans()
            self.refresh()
        truncated = state.step_count >= self.scenario.max_steps
        collision = self.robot_collision()
        left_world = self.robot_left_world()
        goal_reached = goal_distance(state.robot_goal, positions[0]) <= self.scenario.robot.goal_radius
        events = StepEvents(goal_reached=bool(goal_reached), collision=collision, truncated=truncated, left_world=left_world)
        if self.team is None:
            self.robot_events = [events]
        else:  # the ego robot's events gain its robot contacts; a robot that left has none: report a quiet step for it
            self.robot_events = self.team.outcomes(self, events, truncated)
            events = self.robot_events[0] or StepEvents(goal_reached=False, collision=None, truncated=truncated)
        if n and apply_goal_rules(state, self):  # someone respawned: the geometry of the new positions
            self.refresh()
        return events

    def stop_humans(self, index: np.ndarray) -> None:
        """Humans ``index`` (0-based) stop where they are for the rest of the episode (a multi-agent env lets them leave)."""
        state = self.state
        state.human_stopped[index] = True
        state.velocities[1:][index] = 0.0

    def crowd_commands(self) -> np.ndarray:
        """(n_humans,) complex velocity commands (m/s) of the crowd's models in the current state (stopped humans not zeroed)."""
        return self.crowd.commands(WorldView(self))

    def _place_humans(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Put the humans of placing models (:attr:`crowdnav.crowd.Crowd.places`) where they say; returns what they said."""
        placed = self.crowd.place(WorldView(self))
        state = self._state
        for index, positions, velocities in placed:
            state.positions[1:][index] = positions
            state.velocities[1:][index] = velocities
        return placed

    def social_force_commands(self) -> np.ndarray:
        """(n_humans,) complex velocity commands (m/s) of the social-force model in the current state."""
        force, state = self._force, self._state
        to_goal = state.human_goals - state.positions[1:]
        total = sf.goal_force(to_goal, force.goal_weight, force.goal_saturation_distance)
        total += self._repulsion[1:]
        if self.together is not None:  # the walking groups' terms (Moussaïd et al. 2010)
            total += self.group_terms(state.positions[1:], state.velocities[1:], state.human_preferred_speed, state.human_group,
                                      state.human_stopped)
        return sf.velocity_command(total, state.velocities[1:], state.human_preferred_speed, state.command_cap, self.relaxation)

    def group_terms(self, humans: np.ndarray, velocities: np.ndarray, preferred_speed: np.ndarray, group: np.ndarray,
                    stopped: np.ndarray) -> np.ndarray:
        """:func:`crowdnav.social_force.group_force` on the humans (any leading world axes) of a scenario with walking groups."""
        assert self.together is not None
        member = self.together[group] & ~stopped
        return sf.group_force(humans, velocities, preferred_speed, member, group, len(self.together), self.scenario.humans.group_force,
                              self._force.relaxation_time)

    def _robot_velocity(self, action: np.ndarray) -> complex:
        a0, a1 = float(action[0]), float(action[1])
        if not (math.isfinite(a0) and math.isfinite(a1)):
            raise ValueError(f"robot action must be finite, got {list(np.asarray(action).tolist())}")
        a0, a1 = min(1.0, max(-1.0, a0)), min(1.0, max(-1.0, a1))
        if self.team is not None and not self.team.state.active[0]:
            return 0j  # the ego robot left the world: it stays parked
        velocity, self._state.robot_heading = robot_kinematics(self.scenario.robot, self._state.robot_heading, a0, a1, self.dt)
        return velocity

    def _scaled_commands(self, actions: np.ndarray) -> np.ndarray:
        actions = np.asarray(actions, dtype=float)
        if actions.shape != (self.n_humans, 2):
            raise ValueError(f"human_actions must have shape ({self.n_humans}, 2), got {actions.shape}")
        if not np.isfinite(actions).all():
            raise ValueError("human_actions must be finite")
        command = np.clip(actions[:, 0], -1, 1) + 1j * np.clip(actions[:, 1], -1, 1)
        command /= np.maximum(np.abs(command), 1.0)
        scaled: np.ndarray = command * self._state.human_max_speed
        return scaled

    # ----------------------------------------------------------------- several robots

    def retire_robots(self, index: np.ndarray | list[int]) -> None:
        """Robots ``index`` (0: the ego robot) leave the world for the rest of the episode (:data:`crowdnav.robots.PARKED`)."""
        if self.team is None:
            raise ValueError("retire_robots needs a scenario with robots:; the one robot's episode ends with it")
        state = self.team.state
        index = np.asarray(index, dtype=int).reshape(-1)
        if ((index < 0) | (index >= len(state.active))).any():
            raise ValueError(f"robot indices must be in [0, {len(state.active) - 1}], got {index.tolist()}")
        for k in index.tolist():
            if not state.active[k]:
                continue
            state.active[k] = False
            if k == 0:
                state.left_at[0] = self._state.positions[0]
                self._state.positions[0], self._state.velocities[0] = PARKED, 0.0
            else:
                state.left_at[k] = state.positions[k - 1]
                state.positions[k - 1], state.velocities[k - 1] = PARKED, 0.0
        self.refresh()


def _preferred_speeds(rng: np.random.Generator, group: HumanGroup, count: int) -> np.ndarray:
    """``count`` preferred speeds (m/s) of ``group``'s members: drawn from its range, 0 for a standing group."""
    if group.standing:
        return np.zeros(count)
    assert group.preferred_speed is not None  # a walking group always has its range (Humans.crowd fills it in)
    return rng.uniform(*group.preferred_speed, size=count)
