"""The crowd simulator: one robot and a crowd of social-force (or ORCA) humans among static obstacles.

State lives in numpy arrays indexed by agent, robot first: ``positions[0]`` is the robot,
``positions[1:]`` the active humans; points and velocities are complex (``x + 1j*y``, m and m/s,
world frame). A step costs a fixed number of array operations whatever the crowd size (no Python
loop over humans, pairs or edges). Up to ``grid_from`` humans every pair is measured; larger
crowds only pairs within the force's reach (:mod:`crowdnav.sim.crowd_grid`, the same model within a
stated tolerance). Each walking group's humans take their commands from the group's crowd model
(:mod:`crowdnav.crowd`, held as :attr:`Simulator.crowd`); everything after the command is the same.

Step order: humans' commands (a crowd model, or given actions) and robot kinematics -> integrate
-> measure the new geometry once -> keep humans out of walls and of each other (after each sub-step: humans
that would move their radius in a step move in sub-steps, :func:`crowdnav.scenario.loader.human_substeps`) -> robot
collision, world-exit and goal checks -> humans at their goals follow the scenario's ``on_goal``
rule. The simulator is made of parts, not base classes: the measuring and what is read from it
(overlap pushes, collision, world exit) are :class:`crowdnav.sim.geometry.Geometry`
(:attr:`Simulator.geometry`), an episode's first draws :func:`crowdnav.sim.episode_draw.draw_state`,
every robot's readings :mod:`crowdnav.sim.robot_view`; this module steps the episode.

The robot cannot escape the task: leaving the world (its centre outside ``world.min`` /
``world.max``) is impossible with ``world.boundary_walls`` (touching them is a collision) and
otherwise ends the episode with the outcome ``out_of_bounds``.

The episode's state is one declared :class:`crowdnav.sim.state.SimState` the simulator owns
(:attr:`Simulator.state`); its fields (read from the declaration, not listed again:
:func:`crowdnav.sim.state.read_state_fields`), the measured geometry's and every robot's read as
the simulator's attributes (``sim.positions``, ``sim.robot_offset``, ``sim.robot_positions``).
Only the simulator's methods change the state (:meth:`Simulator.step`, :meth:`Simulator.stop_humans`,
the goal rules it runs); staging a scene by hand (tests, scripted set-ups) writes those arrays
and then calls :meth:`Simulator.refresh`.
A scenario with ``robots:`` keeps the robots after the first (ego, agent 0) in
:attr:`Simulator.team` (:mod:`crowdnav.sim.robots`; None for one robot); :attr:`Simulator.robot_events`
holds every robot's events of the last step. Randomness comes only from the generator seeded by
:meth:`Simulator.reset`.
"""
from __future__ import annotations

import copy
from typing import TYPE_CHECKING

import numpy as np

from crowdnav.crowd import Crowd
from crowdnav.crowd.base import CrowdView, action_commands
from crowdnav.crowd.passing import passing_force
from crowdnav.crowd.routing import Router, router_for
from crowdnav.crowd.views import world_view
from crowdnav.scenario.loader import Overrides, human_substeps
from crowdnav.scenario.schema import Scenario
from crowdnav.sim import forces as sf
from crowdnav.sim import robot_view as robots_read
from crowdnav.sim.contacts import goal_distance
from crowdnav.sim.episode_draw import draw_state
from crowdnav.sim.events import OUTCOMES, Collision, SimulationError, StepEvents, check_finite  # noqa: F401  (re-exported: their public home)
from crowdnav.sim.geometry import Geometry
from crowdnav.sim.groups import apply_goal_rules, goal_checks, rule_tables, stall_window, together_table
from crowdnav.sim.robot_view import RobotView, RobotWorld, robot_scenario
from crowdnav.sim.robots import Team, clipped_action, retire_robots, robot_kinematics
from crowdnav.sim.state import ConstantsCache, PairConstants, SimState, StateFields, pair_constants, read_state_fields, read_through, read_with
from crowdnav.worlds.compiled import CompiledWorld, WorldSource, load_world

if TYPE_CHECKING:  # the state's fields as the simulator's attributes, for the type checker (read_state_fields adds them)
    _StateAttributes = StateFields[complex, float, int]
else:
    _StateAttributes = object


class Simulator(_StateAttributes):
    """Vectorized crowd simulator for one scenario.

    >>> sim = Simulator("room_furniture")
    >>> sim.reset(seed=0)
    >>> events = sim.step(np.array([1.0, 0.0]))

    ``scenario``: a library name, YAML path, mapping or Scenario (loaded and compiled by
    :func:`crowdnav.worlds.compiled.load_world`), or an already compiled world (then no ``overrides``).
    """

    grid_from: int = 200
    """Crowds of at least this many humans use the neighbour grid (:mod:`crowdnav.sim.crowd_grid`) instead of
    all pairs: the same model within a stated tolerance, at a cost that grows with n instead of n^2."""

    # what refresh() measured (crowdnav.sim.geometry.Geometry), read as attributes
    robot_offset: np.ndarray = read_through("geometry.robot_offset", doc="(n+1,) complex (m): from the robot to every agent.")
    robot_distance: np.ndarray = read_through("geometry.robot_distance", doc="(n+1,) (m): centre distances from the robot, its own huge.")
    polygon_offset: np.ndarray = read_through("geometry.polygon_offset", doc="(n+1, P) complex (m): to each polygon's nearest point.")
    polygon_distance: np.ndarray = read_through("geometry.polygon_distance", doc="(n+1, P) (m): their lengths.")
    disc_offset: np.ndarray = read_through("geometry.disc_offset", doc="(n+1, C) complex (m): to each round obstacle's centre.")
    disc_distance: np.ndarray = read_through("geometry.disc_distance", doc="(n+1, C) (m): their lengths (centre distance).")
    # every robot at once (crowdnav.sim.robot_view; one robot: the first and only)
    robot_count: int = read_with(robots_read.robot_count)
    other_robot_discs: slice = read_with(robots_read.other_robot_discs)
    robot_positions: np.ndarray = read_with(robots_read.robot_positions)
    robot_goals: np.ndarray = read_with(robots_read.robot_goals)
    robot_headings: np.ndarray = read_with(robots_read.robot_headings)
    robots_active: np.ndarray = read_with(robots_read.robots_active)

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
        """(G,) bool: the groups that walk together (``walk_together``; :func:`crowdnav.sim.forces.group_force`); None: none does."""
        self.max_humans = scenario.humans.max_count
        force = scenario.humans.social_force
        self._force = force
        self.relaxation = min(1.0, self.dt / force.relaxation_time)
        """``min(1, dt / relaxation_time)``: the share of the way to its desired velocity a human goes in one step."""
        self.substeps = human_substeps(scenario)
        """Sub-steps the humans' motion and contacts take per step (:func:`crowdnav.scenario.loader.human_substeps`; 1 unless a
        step would move a human its radius or more)."""
        self.substep_dt = self.dt / self.substeps
        """Seconds of one sub-step (``dt`` with one sub-step)."""
        self.stall_window = stall_window(scenario)
        """Steps between stall checks (``humans.stall``; 0: none): :func:`crowdnav.sim.groups.goal_checks`."""
        world = scenario.world
        self.bounds: tuple[float, float, float, float] | None = (
            None if world.boundary_walls else (float(world.min[0]), float(world.min[1]), float(world.max[0]), float(world.max[1])))
        """Open space: ``(x0, y0, x1, y1)`` (m), the rectangle the robot's centre must stay in (None: boundary walls keep it in)."""
        self.geometry = Geometry(self.obstacles, self.bounds)
        """What :meth:`refresh` measures from the state (:class:`crowdnav.sim.geometry.Geometry`): not state, never written by others."""
        self._rng = np.random.default_rng()
        self._constants = ConstantsCache()
        """The pair constants of the last few crowd sizes (LRU): bounded whatever sizes ``humans.count`` draws."""
        self.team = Team(scenario, self.obstacles, self.placement) if scenario.robots is not None else None
        """The robots after the first (:mod:`crowdnav.sim.robots`) of a scenario with ``robots:``; None for one robot."""
        self._robot_scenarios: list[Scenario] = [robot_scenario(scenario, k) for k in range(len(scenario.robot_specs))]
        self.robot_events: list[StepEvents | None] = []
        """Every robot's events of the last step, the ego robot first (None: it had left); one robot: ``[events]``."""
        self.crowd = Crowd(self.world)
        """The crowd models of the walking groups (:mod:`crowdnav.crowd`); a model that cannot run (ORCA without pyrvo)
        fails here, at load, in one line naming the scenario field that asked for it."""
        self.router: Router | None = router_for(self.world) if scenario.humans.routing == "geodesic" else None
        """``humans.routing: geodesic``: the compiled world's shared router (:mod:`crowdnav.crowd.routing`); None: straight."""
        self.rules_when_stopped, self.rules_every_step = rule_tables(self.groups, self.crowd.places)
        """Where the goal rules act besides walking arrivals and stalls (:func:`crowdnav.sim.groups.rule_tables`)."""
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
    def n_humans(self) -> int:
        """Active humans this episode."""
        return len(self._state.positions) - 1

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
        rng = self._rng
        self._state = draw_state(self, rng)
        n = self._state.n_humans
        self._use_pair_constants(n)
        self._ready = True
        self.crowd.start_episode(world_view(self), rng)
        if self.crowd.places:  # recorded people where the recording has them, stopped humans for the whole episode
            for index, _, _ in place_humans(self.crowd, world_view(self), self._state.positions, self._state.velocities):
                self._state.human_stopped[index] = True

    def pair_constants(self, n: int) -> PairConstants:
        """The repulsion constants of a crowd of ``n`` humans (:func:`crowdnav.sim.state.pair_constants`, the last few sizes kept)."""
        grid = n >= self.grid_from
        return self._constants.get((n, grid), lambda: pair_constants(self.scenario, self.obstacles, n, grid=grid))

    def share_constants(self, other: Simulator) -> None:
        """Take ``other``'s cache of pair constants (a simulator of the same compiled world): one bounded cache for both."""
        if other.world is not self.world:
            raise ValueError("share_constants: the simulators must share one compiled world")
        self._constants = other._constants

    def _use_pair_constants(self, n: int) -> None:
        constants = self.pair_constants(n)
        self.radii = constants.radii
        """(n+1,) body radii (m), robot first."""
        self.geometry.use(constants)

    def load_state(self, state: SimState) -> None:
        """Make ``state`` (one world's, owned by this simulator from now on) the episode's state and measure its geometry.

        For a state of the episode this simulator drew last (:meth:`draw_episode`): its groups' ORCA solver
        and its generator stay this simulator's (another episode's, with its generator and crowd models:
        :func:`crowdnav.sim.episode_state.restore`).
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
        twin.geometry = self.geometry.copy()  # what the twin measures is its own
        twin.crowd = self.crowd.copy()  # a model's episode state (recorded people reacting) is the twin's own
        if self.team is not None:  # its own robots (the constants stay shared)
            twin.team = copy.copy(self.team)
            twin.team.state = self.team.state.copy()
        twin.load_state((self.state if state is None else state).copy())
        return twin

    # -------------------------------------------------------------------- geometry

    def refresh(self) -> None:
        """Measure the geometry at the current positions (once per step; after editing ``positions`` by hand).

        What it sets (``robot_offset``, ``pair_distance``, ``polygon_offset``, ``disc_distance``,
        the repulsion, ...) is described on :class:`crowdnav.sim.geometry.Geometry` and read by the
        sensors, the reward and the step; ``pair_*`` of crowds of ``grid_from`` or more are built when read.
        """
        self.geometry.measure(self._state.positions, self.team)

    @property
    def pair_offset(self) -> np.ndarray:
        """(n+1, n+1) complex: from agent i to agent j (all pairs; built on demand for large crowds)."""
        return self.geometry.pairs(self._state.positions)[0]

    @property
    def pair_distance(self) -> np.ndarray:
        """(n+1, n+1): centre distances, the diagonal a huge number (built on demand for large crowds)."""
        return self.geometry.pairs(self._state.positions)[1]

    @property
    def robot_social_force(self) -> complex:
        """Social repulsion the humans exert on the robot (dimensionless force, world frame): row 0 of the fused repulsion."""
        return complex(self.geometry.repulsion[0])

    def robot_collision(self) -> Collision | None:
        """The robot's deepest contact in the current state (touching counts), or None."""
        return self.geometry.robot_collision(len(self._state.positions) - 1)

    def robot_left_world(self) -> bool:
        """Whether the robot's centre is outside the world rectangle (always False with boundary walls)."""
        return self.geometry.robot_left_world(complex(self._state.positions[0]))

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
            commands = action_commands(human_actions, self._state.human_max_speed)
        if np.count_nonzero(state.human_stopped):  # standing groups, arrivals under on_goal: stop, humans a multi-agent env let leave
            commands = np.where(state.human_stopped, 0.0, commands)
        velocities, positions = state.velocities, state.positions
        velocities[0] = robot_velocity
        velocities[1:] = commands
        # the robot's whole step, the humans' first sub-step (the others after its contacts, below; dt / 1 is dt)
        positions[:1] += velocities[:1] * self.dt
        positions[1:] += velocities[1:] * self.substep_dt
        if self.team is not None:
            self.team.move(other_robot_actions, self.dt)
        state.step_count += 1
        check_finite(positions, velocities, state.step_count)
        self.refresh()
        n = len(positions) - 1
        for _ in range(1, self.substeps if n else 1):  # fast humans: contacts after every sub-step, so none passes through a wall
            if self.geometry.humans_touch:
                self.geometry.push_humans_apart(positions)
            positions[1:] += velocities[1:] * self.substep_dt
            self.refresh()
        if n and self.geometry.humans_touch:  # a human touches someone or something
            self.geometry.push_humans_apart(positions)
            self.refresh()
        if n and self.crowd.places:  # after the pushes: placed humans are exactly where their model puts them
            place_humans(self.crowd, world_view(self), positions, velocities)
            self.refresh()
        truncated = state.step_count >= self.scenario.max_steps
        collision = self.geometry.robot_collision(n)
        left_world = self.bounds is not None and self.geometry.robot_left_world(complex(positions[0]))
        goal_reached = goal_distance(state.robot_goal, positions[0]) <= self.scenario.robot.goal_radius
        events = StepEvents(goal_reached=bool(goal_reached), collision=collision, truncated=truncated, left_world=left_world)
        if self.team is None:
            self.robot_events = [events]
        else:  # the ego robot's events gain its robot contacts; a robot that left has none: report a quiet step for it
            self.robot_events = self.team.outcomes(self, events, truncated)
            events = self.robot_events[0] or StepEvents(goal_reached=False, collision=None, truncated=truncated)
        if n:
            checks = goal_checks(state, self)
            if checks.rules and apply_goal_rules(state, self, checks.arrived, checks.stalled):  # someone respawned: measure again
                self.refresh()
        return events

    def stop_humans(self, index: np.ndarray) -> None:
        """Humans ``index`` (0-based) stop where they are for the rest of the episode (a multi-agent env lets them leave)."""
        state = self.state
        state.human_stopped[index] = True
        state.velocities[1:][index] = 0.0

    def crowd_commands(self) -> np.ndarray:
        """(n_humans,) complex velocity commands (m/s) of the crowd's models in the current state (stopped humans not zeroed)."""
        return self.crowd.commands(world_view(self))

    def social_force_commands(self) -> np.ndarray:
        """(n_humans,) complex velocity commands (m/s) of the social-force model in the current state."""
        state = self._state
        return self.social_force(state.positions[1:], state.velocities[1:], state.human_goals, state.human_group, state.human_stopped,
                                 state.human_preferred_speed, state.command_cap, self.geometry.repulsion[1:])

    def social_force(self, humans: np.ndarray, velocities: np.ndarray, goals: np.ndarray, group: np.ndarray, stopped: np.ndarray,
                     preferred_speed: np.ndarray, command_cap: np.ndarray, repulsion: np.ndarray) -> np.ndarray:
        """The social-force model's velocity commands (m/s), written once for one world and K: its kernels
        (:mod:`crowdnav.sim.forces`) summed on the humans' (..., n) arrays (any leading world axes) and the measured
        ``repulsion`` on them. One world: :meth:`social_force_commands`; K: the batched simulator, every world's at once."""
        force, router = self._force, self.router
        to_goal = goals - humans if router is None else router.to_goal(humans, goals)  # humans.routing: geodesic
        total = sf.goal_force(to_goal, force.goal_weight, force.goal_saturation_distance)
        if router is not None:  # routed humans side-step oncoming ones (crowdnav.crowd.passing)
            total += passing_force(humans, to_goal, ~stopped, self.scenario.humans.radius, force.goal_weight, group, self.together)
        total += repulsion
        if self.together is not None:  # the walking groups' terms (Moussaïd et al. 2010)
            total += self.group_terms(humans, velocities, preferred_speed, group, stopped)
        commands: np.ndarray = sf.velocity_command(total, velocities, preferred_speed, command_cap, self.relaxation)
        return commands

    def group_terms(self, humans: np.ndarray, velocities: np.ndarray, preferred_speed: np.ndarray, group: np.ndarray,
                    stopped: np.ndarray) -> np.ndarray:
        """:func:`crowdnav.sim.forces.group_force` on the humans (any leading world axes) of a scenario with walking groups."""
        assert self.together is not None
        member = self.together[group] & ~stopped
        return sf.group_force(humans, velocities, preferred_speed, member, group, len(self.together), self.scenario.humans.group_force,
                              self._force.relaxation_time)

    def _robot_velocity(self, action: np.ndarray) -> complex:
        a0, a1 = clipped_action(action)
        if self.team is not None and not self.team.state.active[0]:
            return 0j  # the ego robot left the world: it stays parked
        velocity, self._state.robot_heading = robot_kinematics(self.scenario.robot, self._state.robot_heading, a0, a1, self.dt)
        return velocity

    # ----------------------------------------------------------------- several robots

    def robot_scenario(self, index: int) -> Scenario:
        """The scenario as robot ``index`` sees it: its own spec as ``robot`` (the scenario itself for the ego robot)."""
        return self._robot_scenarios[index]

    def robot_view(self, index: int, with_robots: bool = True) -> RobotWorld:
        """The world from robot ``index`` (:class:`crowdnav.sim.robot_view.RobotView`), what its sensors, reward and scripted policy read.

        ``with_robots=False``: the other robots left out (what a people tracker sees). One robot: the simulator itself.
        """
        return self if self.team is None else RobotView(self, index, with_robots)

    def retire_robots(self, index: np.ndarray | list[int]) -> None:
        """Robots ``index`` (0: the ego robot) leave the world for the rest of the episode (:data:`crowdnav.sim.robots.PARKED`)."""
        if self.team is None:
            raise ValueError("retire_robots needs a scenario with robots:; the one robot's episode ends with it")
        retire_robots(self.team, self.state, index)
        self.refresh()


read_state_fields(Simulator)  # sim.positions is sim.state.positions, and so on for every field of SimState


def place_humans(crowd: Crowd, view: CrowdView, positions: np.ndarray, velocities: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Put one world's humans of placing models (:attr:`crowdnav.crowd.Crowd.places`) where they say; returns what they said.

    ``view``: that world's (one world); ``positions``, ``velocities``: its (n+1,) arrays, written in
    place (the simulator's own, or a view of a batch's row).
    """
    placed = crowd.place(view)
    for index, where, moving in placed:
        positions[1:][index] = where
        velocities[1:][index] = moving
    return placed
