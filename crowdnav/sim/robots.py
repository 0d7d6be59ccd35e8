"""Several robots in one world (a scenario's ``robots:``): the robots after the first, and what they add to a step.

The simulator's :class:`crowdnav.sim.state.SimState` keeps its layout whatever the number of
robots: agent 0 is the *ego* robot (``robots[0]``, the one the Gymnasium env learns), humans
are agents 1..n. The other robots live in a :class:`Team` the simulator holds only for a
scenario with ``robots:`` (``sim.team``; None otherwise), so the one-robot step is the same
code and the same bits as before; the team's work is a few (n+1, m) array operations per step,
m the number of other robots, and a loop over the robots only where each gets its own outcome.

What the team adds to a step: the other robots' kinematics (each robot's own), their repulsion
on the humans (``see_robot``: the robot parameters of the social force, as the ego robot's),
their geometry (to the humans, the ego robot, each other and the static obstacles) and every
robot's outcome, robot-robot contacts included (``Collision("robot", <name>)``).

A robot that finished (success, collision, out of the world) leaves the world when its env
says so (:meth:`crowdnav.Simulator.retire_robots`): it is moved to :data:`PARKED`, a point so
far away that it no longer pushes, blocks or is seen by anyone (every repulsion is exactly 0
there), and its ``active`` flag is cleared; :attr:`TeamState.left_at` keeps where it left.

:class:`crowdnav.sim.robot_view.RobotView` shows the world from one robot (sensors, reward and
scripted policies read it as they read a simulator).
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from crowdnav.sim import forces as sf
from crowdnav.sim.contacts import deepest_contact, goal_distance, outside, touching
from crowdnav.sim.events import Collision, StepEvents
from crowdnav.sim.state import SELF_DISTANCE, SimState
from crowdnav.worlds.obstacles import nearest_on_edges
from crowdnav.worlds.placement import GAP, JITTER_REACH, PlacementError

PARKED = complex(1.0e7, 1.0e7)
"""Where a robot that left the world is kept (m): every exponential repulsion and contact test of it is exactly 0 / False."""


def robot_kinematics(robot: Any, heading: float, a0: float, a1: float, dt: float) -> tuple[complex, float]:
    """A robot's velocity over the step (m/s, world frame) and its new heading, from a clipped, finite action ``(a0, a1)``.

    Holonomic: ``(vx, vy)`` in the robot frame, the norm capped at 1; unicycle: ``(v, omega)``, the exact arc.
    """
    if robot.kinematics == "holonomic":
        command = complex(a0, a1)
        norm = abs(command)
        if norm > 1.0:  # the max speed bounds the norm, not each axis
            command /= norm
        return command * robot.max_speed * cmath.exp(1j * heading), heading
    speed, turn = a0 * robot.max_speed, a1 * robot.max_angular_speed
    new_heading = heading + turn * dt
    if abs(turn) > 1e-9:  # exact arc of the unicycle over the step
        displacement = (speed / turn) * -1j * (cmath.exp(1j * new_heading) - cmath.exp(1j * heading))
    else:
        displacement = speed * dt * cmath.exp(1j * heading)
    return displacement / dt, math.remainder(new_heading, 2 * math.pi)


def clipped_action(action: np.ndarray) -> tuple[float, float]:
    """A robot's 2-value ``action`` as Python floats clipped to [-1, 1] (refused, in one line, unless finite)."""
    a0, a1 = float(action[0]), float(action[1])
    if not (math.isfinite(a0) and math.isfinite(a1)):
        raise ValueError(f"robot action must be finite, got {list(np.asarray(action).tolist())}")
    return min(1.0, max(-1.0, a0)), min(1.0, max(-1.0, a1))


def first_heading(robot: Any, rng: np.random.Generator, start: complex, goal: complex) -> float:
    """A robot's heading at reset (``start_heading``: random, toward_goal or degrees)."""
    if robot.start_heading == "random":
        return float(rng.uniform(-math.pi, math.pi))
    if robot.start_heading == "toward_goal":
        return cmath.phase(goal - start)
    return math.radians(float(robot.start_heading))


@dataclass(eq=False)
class TeamState:
    """The episode state of the robots after the first (m of them; ``active`` and ``left_at`` cover all R robots)."""

    positions: np.ndarray
    """(m,) complex, m: centres (:data:`PARKED` once retired)."""
    velocities: np.ndarray
    """(m,) complex, m/s: velocities over the last step."""
    goals: np.ndarray
    """(m,) complex, m: goal centres."""
    headings: np.ndarray
    """(m,) float64, rad: headings."""
    active: np.ndarray
    """(R,) bool, the ego robot first: still in the world."""
    left_at: np.ndarray
    """(R,) complex, m: where each retired robot was when it left (NaN while active)."""

    def copy(self) -> TeamState:
        return TeamState(*(np.copy(value) for value in vars(self).values()))


class Team:
    """The robots after the first of a scenario with ``robots:``, their constants and their per-step work."""

    def __init__(self, scenario: Any, obstacles: Any, placement: Any):
        self.specs = scenario.robot_specs[1:]
        self.names: list[str] = scenario.robot_names
        """Every robot's agent name, the ego robot first."""
        self.placements = placement.other_robots
        humans, force = scenario.humans, scenario.humans.social_force
        self.radii = np.array([robot.radius for robot in self.specs])
        self.all_radii = np.concatenate([[scenario.robot.radius], self.radii])
        """(R,) body radii (m), the ego robot first."""
        self.max_speeds = np.array([robot.max_speed for robot in self.specs])
        self.goal_radii = np.array([robot.goal_radius for robot in self.specs])
        self.human_radius = humans.radius
        # humans pushed by each robot (the ego robot's column of the pair tables, per robot radius)
        self.push_gain = sf.repulsion_gain(force.robot_strength if humans.see_robot else 0.0, humans.radius + self.radii, force.robot_range)
        self.push_decay = -1.0 / force.robot_range
        # the humans' force on each robot: the reward's social term, with the human parameters (row 0 for the ego robot)
        self.social_gain = sf.repulsion_gain(force.human_strength, humans.radius + self.radii, force.human_range)[:, None]
        self.social_decay = -1.0 / force.human_range
        self.obstacles = obstacles
        self.static_count = obstacles.polygon_count + obstacles.disc_count
        self.static_contact = self.radii[:, None] + obstacles.surface_radius[None, :]
        self._static_labels = obstacles.labels + obstacles.disc_labels
        self.pair_contact = self.radii[:, None] + self.radii[None, :]
        count = len(self.specs)
        self.state = TeamState(np.zeros(count, complex), np.zeros(count, complex), np.zeros(count, complex), np.zeros(count),
                               np.ones(count + 1, bool), np.full(count + 1, complex(np.nan, np.nan)))
        """The episode's robots (drawn by :meth:`draw`; a placeholder before the first reset)."""

    @property
    def count(self) -> int:
        """R: every robot, the ego robot included."""
        return len(self.names)

    # ----------------------------------------------------------------- reset

    def draw(self, rng: np.random.Generator, start: complex, goal: complex) -> tuple[np.ndarray, np.ndarray]:
        """Draw the other robots' starts, goals and headings after the ego robot's; returns every robot's (R,) starts and goals.

        Each start keeps clear of the robots drawn before it, each goal of their goals; both respect
        the robot's own start-goal rules as the ego robot's draw does. A draw takes a point of the
        robot's lattice when one is free (so what always drew the same still does), else a point of
        its fine set, which the load-time check (:func:`crowdnav.worlds.placement_team.check_team`) proves is there.
        """
        starts, goals, headings = [start], [goal], []
        radii = self.all_radii
        for j, (robot, places) in enumerate(zip(self.specs, self.placements, strict=True), start=1):
            clear = radii[j] + radii[:j] + GAP + 2 * JITTER_REACH
            fallback = places.fallback
            component = 0
            try:
                begin = places.robot_start.draw(rng, 1, allowed=places.start_goal_ok.any(1), away_from=np.array(starts), min_distance=clear)[0]
                nearest = int(np.argmin(np.abs(places.robot_start.points - begin)))
                component = fallback.lattice_component(nearest)
                reachable = None if places.start_component is None else places.goal_component == places.start_component[nearest]
            except PlacementError:
                try:  # every lattice start is blocked by the robots before it: the fine set
                    begin, component = fallback.draw_start(rng, np.array(starts), radii[j] + radii[:j] + GAP)  # no jitter: no slack
                except PlacementError:
                    raise PlacementError(f"robots.{j}.start: no start is clear of the robots drawn before it this episode; "
                                         "expected start regions with room for every robot") from None
                reachable = fallback.lattice_goals(component)
            away = np.array([begin, *goals])
            near = np.concatenate([[robot.min_start_goal_distance + JITTER_REACH], clear])
            try:
                end = places.robot_goal.draw(rng, 1, allowed=reachable, away_from=away, min_distance=near)[0]
            except PlacementError:
                try:
                    end = fallback.draw_goal(rng, component, away, np.concatenate([[fallback.goal_distance], radii[j] + radii[:j] + GAP]))
                except PlacementError:
                    raise PlacementError(f"robots.{j}.goal: no goal is clear of the other robots' goals this episode (and "
                                         f"min_start_goal_distance from its start); expected goal regions with room for every robot") from None
            headings.append(first_heading(robot, rng, begin, end))
            starts.append(begin)
            goals.append(end)
        count = len(self.specs)
        self.state = TeamState(
            positions=np.array(starts[1:], dtype=complex), velocities=np.zeros(count, dtype=complex), goals=np.array(goals[1:], dtype=complex),
            headings=np.array(headings, dtype=float), active=np.ones(count + 1, dtype=bool), left_at=np.full(count + 1, complex(np.nan, np.nan)),
        )
        return np.array(starts, dtype=complex), np.array(goals, dtype=complex)

    # ------------------------------------------------------------------ step

    def checked_actions(self, actions: np.ndarray | None) -> np.ndarray | None:
        """The other robots' actions as (m, 2) floats, checked before the step changes anything (clipped to [-1, 1] when used)."""
        if actions is None:
            return None
        actions = np.asarray(actions, dtype=float)
        if actions.shape != (len(self.specs), 2) or not np.isfinite(actions).all():
            raise ValueError(f"other_robot_actions must be {len(self.specs)} finite rows of 2 values (one per robot after the first), "
                             f"got shape {actions.shape}")
        return actions  # clipped per value in move()

    def move(self, actions: np.ndarray | None, dt: float) -> None:
        """Every active other robot's velocity from its action ((m, 2) in [-1, 1]; None: standing still), then its new position."""
        state = self.state
        state.velocities[:] = 0.0
        if actions is not None:
            for j, robot in enumerate(self.specs):  # 1 to 7 robots: each its own kinematics
                if state.active[j + 1]:
                    a0, a1 = min(1.0, max(-1.0, float(actions[j, 0]))), min(1.0, max(-1.0, float(actions[j, 1])))
                    velocity, state.headings[j] = robot_kinematics(robot, float(state.headings[j]), a0, a1, dt)
                    state.velocities[j] = velocity
        state.positions += state.velocities * dt

    def refresh(self, positions: np.ndarray, repulsion: np.ndarray) -> None:
        """Measure the team's geometry at the agents' ``positions`` and add the other robots' push to the humans' ``repulsion``."""
        robots = self.state.positions
        offset = robots[None, :] - positions[:, None]  # row i, column j: from agent i (ego robot, humans) to robot j
        distance = np.abs(offset)
        self.offset, self.distance = offset, distance
        n = len(positions) - 1
        if n:
            # the (m,) and (m, 1) gains broadcast against the (n, m) and (m, n) pairs
            repulsion[1:] += sf.repulsion(offset[1:], distance[1:], self.push_gain, self.push_decay)
            self.social = sf.repulsion(-offset[1:].T, distance[1:].T, self.social_gain, self.social_decay)
        else:
            self.social = np.zeros(len(robots), dtype=complex)
        pair = robots[None, :] - robots[:, None]
        self.pair_offset, self.pair_distance = pair, np.abs(pair)
        self.pair_distance.flat[:: len(robots) + 1] = SELF_DISTANCE
        if self.static_count:
            self.static_offset, self.static_distance = nearest_on_edges(robots, self.obstacles.surface)
        else:
            self.static_offset = np.zeros((len(robots), 0), dtype=complex)
            self.static_distance = np.zeros((len(robots), 0))

    def outcomes(self, sim: Any, ego: StepEvents, truncated: bool) -> list[StepEvents | None]:
        """Every robot's events of the step (None for a robot that already left), the ego robot first.

        ``ego``: the ego robot's events as the one-robot step finds them (humans and obstacles);
        they gain its contacts with the other robots here. The other robots' checks are (m, ...)
        array operations; only a robot that touches something pays for naming its deepest contact.
        """
        state, r0, n = self.state, self.all_radii[0], sim.n_humans
        gone = ~state.active[1:]
        events: list[StepEvents | None] = []
        if state.active[0]:
            to_robots = self.distance[0] - r0 - self.radii
            to_robots[gone] = np.inf
            events.append(replace(ego, collision=with_robot_contact(ego.collision, to_robots, self.names[1:])))
        else:
            events.append(None)
        # row j: robot j's surface gaps to the ego robot, the other robots, the humans, the obstacles
        to_ego = self.distance[0] - r0 - self.radii if state.active[0] else np.full(len(self.radii), np.inf)
        to_others = self.pair_distance - self.pair_contact  # the diagonal (itself): a huge gap
        to_others[:, gone] = np.inf
        gaps = np.concatenate([to_ego[:, None], to_others, self.distance[1:].T - self.human_radius - self.radii[:, None],
                               self.static_distance - self.static_contact], axis=1)
        touches = touching(gaps)
        positions = state.positions
        reached = goal_distance(state.goals, positions) <= self.goal_radii
        left = outside(positions.real, positions.imag, sim.bounds) if sim.bounds is not None else np.zeros(len(positions), bool)
        m = len(self.specs)
        for j in range(m):  # one StepEvents per robot; the contact named only where it touches
            if gone[j]:
                events.append(None)
                continue
            collision = None
            if touches[j]:
                gap = np.concatenate([[SELF_DISTANCE], gaps[j, 1 + m :]])  # as the ego robot's: itself, the humans, the obstacles
                collision = with_robot_contact(deepest_contact(gap, n, self._static_labels) if touching(gap) else None,
                                                gaps[j, : 1 + m], self.names)
            events.append(StepEvents(goal_reached=bool(reached[j]), collision=collision, truncated=truncated, left_world=bool(left[j])))
        return events


def retire_robots(team: Team, ego: SimState, index: np.ndarray | list[int]) -> None:
    """Robots ``index`` (0: the ego robot, whose centre is in ``ego``, its world's state) leave for the rest of the episode.

    Each is moved to :data:`PARKED` and stops; the caller measures the new geometry.
    """
    retire_in(team.state, ego, index)


def retire_in(state: TeamState, ego: SimState, index: np.ndarray | list[int]) -> None:
    """:func:`retire_robots` on a team's state and its world's state as data (a world state's copies, as a snapshot takes them)."""
    index = np.asarray(index, dtype=int).reshape(-1)
    if ((index < 0) | (index >= len(state.active))).any():
        raise ValueError(f"robot indices must be in [0, {len(state.active) - 1}], got {index.tolist()}")
    for k in index.tolist():
        if not state.active[k]:
            continue
        state.active[k] = False
        if k == 0:
            state.left_at[0] = ego.positions[0]
            ego.positions[0], ego.velocities[0] = PARKED, 0.0
        else:
            state.left_at[k] = state.positions[k - 1]
            state.positions[k - 1], state.velocities[k - 1] = PARKED, 0.0


def with_robot_contact(collision: Collision | None, to_robots: np.ndarray, robot_names: list[str]) -> Collision | None:
    """A robot's contact with humans or obstacles (``collision``), or its deepest robot contact where that is deeper.

    ``to_robots``: its surface gaps to the robots it can touch (``robot_names``, the same order).
    """
    if not len(to_robots):
        return collision
    k = int(to_robots.argmin())
    depth = float(to_robots[k])
    if depth > 0.0 or (collision is not None and collision.surface_distance <= depth):
        return collision
    return Collision("robot", robot_names[k], depth)
