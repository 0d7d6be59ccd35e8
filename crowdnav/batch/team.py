"""The robots after the first of every world of a batch: :class:`TeamStack`, a ``robots:`` scenario's team stacked.

A single simulator of a ``robots:`` scenario holds its other robots in a :class:`crowdnav.sim.robots.Team` (their
:class:`crowdnav.sim.robots.TeamState` and the per-step work: their moves, their geometry and push on the humans,
every robot's outcome). The batched simulator keeps every world's team here instead: the TeamState's fields with a
leading world axis, indexed by world (not by a bucket's row: a team has the same robots whatever the crowd size), and
the team's per-step work as array operations over the worlds of a chunk, each the same numpy operation on the same
values as the single team's, so world i's robots move, push and end as the single simulator's do, bit for bit. The
loops are over the robots (each its own kinematics, 1 to 7 of them), never over worlds; naming a contact runs per
world only where a robot touches another (:func:`crowdnav.sim.robots.with_robot_contact`, as the single step).
"""

from __future__ import annotations

import numpy as np

from crowdnav.batch.scalar_math import robot_velocity
from crowdnav.scenario.crowd import SocialForce
from crowdnav.sim import forces as sf
from crowdnav.sim.contacts import deepest_contact, goal_distance, outside, touching
from crowdnav.sim.events import Collision, outcomes
from crowdnav.sim.robots import PARKED, Team, TeamState, with_robot_contact
from crowdnav.sim.state import SELF_DISTANCE
from crowdnav.worlds.obstacles import nearest_on_edges


class TeamStack:
    """Every world's other robots (``num_worlds`` rows of ``team``'s robots), their geometry and their last step's outcomes.

    ``team``: the first world's :class:`Team` (its constants; every world's are the same). Fields of :class:`TeamState`
    with a leading world axis: ``positions``, ``velocities``, ``goals``, ``headings`` (W, m), ``active``, ``left_at`` (W, R).
    """

    def __init__(self, team: Team, num_worlds: int, bounds: tuple[float, float, float, float] | None, dt: float, force: SocialForce):
        self.team = team
        self.team_dt = dt
        """The scenario's time step (s)."""
        self.force = force
        """The scenario's social-force parameters (``humans.social_force``: what the social-force robots read)."""
        self.specs = team.specs
        self.names = team.names
        m, w = len(team.specs), num_worlds
        self.positions = np.full((w, m), PARKED, dtype=complex)
        self.velocities = np.zeros((w, m), dtype=complex)
        self.goals = np.zeros((w, m), dtype=complex)
        self.headings = np.zeros((w, m))
        self.active = np.ones((w, m + 1), dtype=bool)
        self.left_at = np.full((w, m + 1), complex(np.nan, np.nan))
        self._bounds = bounds
        obstacles = team.obstacles
        self._surface = obstacles.surface if team.static_count else None
        s = self.static_count = team.static_count
        self.surface_radius = obstacles.surface_radius
        """(S,) the static obstacles' surface radii (:attr:`crowdnav.worlds.obstacles.StaticObstacles.surface_radius`)."""
        self.social = np.zeros((w, m), dtype=complex)
        """The humans' social-force repulsion on each other robot (``Team.social``), as last measured."""
        self.static_offset = np.zeros((w, m, s), dtype=complex)
        """(W, m, S): from each other robot to each static obstacle's nearest point (``Team.static_offset``)."""
        self.static_distance = np.zeros((w, m, s))
        self.pair_distance = np.zeros((w, m, m))
        self._agent_distance: dict[int, np.ndarray] = {}
        """Crowd size n -> (W, n+1, m): from each agent (ego robot, humans) to each other robot (``Team.distance``), the rows of
        the worlds of that size."""
        self.ended = np.zeros((w, m), dtype=bool)
        """Which other robots ended at their world's last step (success, collision, out of the world)."""
        self.outcome = np.full((w, m), None, dtype=object)
        """Their outcome at that step (None: running)."""
        self.collisions: dict[tuple[int, int], Collision] = {}
        """(world, j) -> other robot j's deepest contact, for the robots that touched something in the batch's last step
        (:meth:`Team.outcomes` names it the same way; the batch clears it when a step starts)."""
        self._labels = obstacles.labels + obstacles.disc_labels

    # ------------------------------------------------------------------ rows

    def set_world(self, world: int, state: TeamState) -> None:
        """``world``'s robots become (a copy of) ``state`` (a reset's draw or a loaded episode's)."""
        for name in ("positions", "velocities", "goals", "headings", "active", "left_at"):
            getattr(self, name)[world] = getattr(state, name)

    def state_of(self, world: int, leaving: np.ndarray | None = None) -> TeamState:
        """``world``'s robots as a single simulator's :class:`TeamState` (copies); ``leaving`` ((m,) bool): those robots as
        :func:`crowdnav.sim.robots.retire_robots` leaves them (out of the world), the world's own rows unchanged."""
        gone = np.zeros(len(self.specs), dtype=bool) if leaving is None else leaving
        positions = self.positions[world]
        return TeamState(np.where(gone, PARKED, positions), np.where(gone, 0j, self.velocities[world]), self.goals[world].copy(),
                         self.headings[world].copy(), self.active[world] & ~np.concatenate([[False], gone]),
                         np.where(np.concatenate([[False], gone]), np.concatenate([[0j], positions]), self.left_at[world]))

    # ------------------------------------------------------------------ step

    def move(self, worlds: np.ndarray, actions: np.ndarray, dt: float) -> None:
        """:meth:`Team.move` of ``worlds`` with their (K, m, 2) actions: each active robot by its own kinematics, then every position."""
        active = self.active[worlds, 1:]
        headings = self.headings[worlds]
        velocities = np.zeros((len(worlds), len(self.specs)), dtype=complex)
        for j, robot in enumerate(self.specs):  # 1 to 7 robots: each its own kinematics, all worlds at once
            re, im, heading = robot_velocity(robot, dt, actions[:, j], headings[:, j])
            on = active[:, j]
            velocities.real[:, j], velocities.imag[:, j] = np.where(on, re, 0.0), np.where(on, im, 0.0)
            headings[:, j] = np.where(on, heading, headings[:, j])
        self.headings[worlds] = headings
        self.velocities[worlds] = velocities
        self.positions[worlds] += velocities * dt

    def refresh(self, worlds: np.ndarray, z: np.ndarray, repulsion: np.ndarray) -> None:
        """:meth:`Team.refresh` of ``worlds`` at the agents' positions ``z`` (K, n+1): their geometry kept, their push added to
        the humans' ``repulsion`` (K, n+1), in place."""
        team, robots = self.team, self.positions[worlds]
        offset = robots[:, None, :] - z[:, :, None]  # [k, i, j]: from agent i to robot j
        distance = np.abs(offset)
        n = z.shape[1] - 1
        stack = self._agent_distance.get(n)
        if stack is None:
            stack = self._agent_distance[n] = np.zeros((len(self.positions), n + 1, len(self.specs)))
        stack[worlds] = distance
        if n:
            repulsion[:, 1:] += sf.repulsion(offset[:, 1:], distance[:, 1:], team.push_gain, team.push_decay)
            # the single team sums the humans' force on robot j over a transposed (m, n) product: the same layout here
            self.social[worlds] = sf.repulsion(-offset[:, 1:].transpose(0, 2, 1), distance[:, 1:].transpose(0, 2, 1), team.social_gain,
                                               team.social_decay)
        else:
            self.social[worlds] = 0.0
        m = robots.shape[1]
        pair_distance = np.abs(robots[:, None, :] - robots[:, :, None])
        pair_distance.reshape(len(worlds), -1)[:, :: m + 1] = SELF_DISTANCE
        self.pair_distance[worlds] = pair_distance
        if self._surface is not None:
            static_offset, static_distance = nearest_on_edges(robots.reshape(-1), self._surface)
            self.static_offset[worlds] = static_offset.reshape(len(worlds), m, -1)
            self.static_distance[worlds] = static_distance.reshape(len(worlds), m, -1)

    def events(self, worlds: np.ndarray, n: int, collisions: dict[int, Collision]) -> None:
        """:meth:`Team.outcomes` of ``worlds`` (n humans) as last measured: the ego robot's contacts with the other robots join
        ``collisions`` (world -> its deepest contact); each other robot's outcome is kept in :attr:`outcome` / :attr:`ended`."""
        team = self.team
        distance = self._agent_distance[n][worlds]
        active = self.active[worlds]
        gone = ~active[:, 1:]
        r0 = team.all_radii[0]
        to_ego = distance[:, 0] - r0 - team.radii  # (K, m)
        to_robots = np.where(gone, np.inf, to_ego)
        ego_on = active[:, 0]
        for k in np.flatnonzero(ego_on & (np.minimum.reduce(to_robots, axis=1) <= 0.0)):  # per contact event, as the single step
            world = int(worlds[k])
            contact = with_robot_contact(collisions.get(world), to_robots[k], self.names[1:])
            if contact is not None:
                collisions[world] = contact
        to_ego = np.where(ego_on[:, None], to_ego, np.inf)
        to_others = self.pair_distance[worlds] - team.pair_contact
        to_others = np.where(gone[:, None, :], np.inf, to_others)
        humans = distance[:, 1:].transpose(0, 2, 1) - team.human_radius - team.radii[:, None]
        static = self.static_distance[worlds] - team.static_contact
        gaps = np.concatenate([to_ego[:, :, None], to_others, humans, static], axis=2)
        touches = np.minimum.reduce(gaps, axis=-1) <= 0.0
        positions = self.positions[worlds]
        reached = goal_distance(self.goals[worlds], positions) <= team.goal_radii
        left = outside(positions.real, positions.imag, self._bounds) if self._bounds is not None else np.zeros(positions.shape, dtype=bool)
        on = ~gone
        touches, left, reached = touches & on, left & on, reached & on
        m = len(self.specs)
        for k, j in zip(*np.nonzero(touches), strict=True):  # per contact event: the contact named as Team.outcomes names it
            gap = np.concatenate([[SELF_DISTANCE], gaps[k, j, 1 + m :]])  # itself, the humans, the obstacles
            contact = with_robot_contact(deepest_contact(gap, n, self._labels) if touching(gap) else None, gaps[k, j, : 1 + m], self.names)
            if contact is not None:  # (always: it touches something)
                self.collisions[int(worlds[k]), int(j)] = contact
        outcome = outcomes(touches.ravel(), left.ravel(), reached.ravel(), np.zeros(touches.size, dtype=bool)).reshape(touches.shape)
        self.outcome[worlds] = outcome
        self.ended[worlds] = touches | left | reached

    def retire(self, worlds: np.ndarray, robots: np.ndarray) -> None:
        """The other robots ``robots`` ((K, m) bool) of ``worlds`` leave (:func:`crowdnav.sim.robots.retire_robots`); the caller
        measures the new geometry."""
        rows, columns = np.nonzero(robots)
        w = worlds[rows]
        self.active[w, columns + 1] = False
        self.left_at[w, columns + 1] = self.positions[w, columns]
        self.positions[w, columns] = PARKED
        self.velocities[w, columns] = 0.0
