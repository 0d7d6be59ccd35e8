"""The scripted robot policies of a ``robots:`` scenario, every world's at once, for any robot of the stack.

The single env drives each other robot with a scripted policy called on that robot's view
(:class:`crowdnav.planning.scripted.SocialForceRobot`, :class:`crowdnav.planning.scripted.StraightToGoal`, on
:meth:`crowdnav.Simulator.robot_view`), in Python's scalar arithmetic; evaluation's scripted baselines drive every robot,
the first one included, that way. Here the same policy runs over a world axis, written with
:mod:`crowdnav.batch.scalar_math` so that each world's action has the single policy's bits: a policy acts for one
:class:`Seat` (robot k of K worlds, what its view shows of it) among a :class:`Fleet` (every robot of those worlds), a
loop over the robots, each its own spec; the sums over the other robots it sees are grouped by which robots are still
in the world (a view lists only those, and the length of a sum decides its rounding). A unicycle's bearing
(``cmath.phase``) is libm's ``atan2`` called per entry: numpy's vectorized ``arctan2`` differs from it in the last bit.

:func:`batched_policy` drives the other robots beside a first robot the caller drives (the vector env's
``other_robots``); :func:`every_robot_actions` drives every robot, the first one's seat read from the batch's crowd-size
stacks (the robots-only engine's scripted baselines). A policy without a batched twin (ORCA, the planners, a callable)
is not stacked: :func:`crowdnav.envs.vector.env.stacks` keeps such worlds as single envs, and evaluation plays it on
:class:`crowdnav.envs.engines.robots.SingleRobots`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from crowdnav.batch.scalar_math import cdiv_real, cmul
from crowdnav.batch.team import TeamStack
from crowdnav.sim import forces as sf

if TYPE_CHECKING:
    from crowdnav.batch.simulator import BatchSimulator

_ATAN2 = np.frompyfunc(math.atan2, 2, 1)
"""``cmath.phase``'s libm ``atan2`` per entry: numpy's own ``arctan2`` is vectorized differently and differs in the last bit."""

RobotPolicy = Callable[[TeamStack, np.ndarray, np.ndarray], np.ndarray]
"""``policy(team, worlds, ego) -> (K, m, 2)`` float64 actions of the other robots of ``worlds`` (``ego``: their (K,)
ego robot positions), 0 for a robot that left, as the single env's ``np.asarray(policy(view), dtype=float)``."""


def batched_policy(name: Any) -> RobotPolicy | None:
    """The batched twin of the ``other_robots`` option ``name`` (None: none, the worlds run as single envs)."""
    return {"social-force": social_force_robots, "straight": straight_robots}.get(name) if isinstance(name, str) else None


def velocity_actions(robot: Any, dt: float, heading: np.ndarray, vr: np.ndarray, vi: np.ndarray) -> np.ndarray:
    """:func:`crowdnav.planning.scripted.velocity_to_action` of one robot spec in every row: (K, 2) float64 of the float32 action."""
    # velocity * cmath.exp(-1j * heading) / max_speed; -1j * h: CPython's product of complex(-0.0, -1.0) and complex(h, 0.0)
    er, ei = -0.0 * heading - -1.0 * 0.0, -0.0 * 0.0 + -1.0 * heading
    lr, li = cmul(vr, vi, np.exp(er) * np.cos(ei), np.exp(er) * np.sin(ei))
    lr, li = cdiv_real(lr, li, robot.max_speed)
    norm = np.hypot(lr, li)
    if robot.kinematics == "holonomic":
        over = norm > 1.0
        dr, di = cdiv_real(lr, li, np.where(over, norm, 1.0))
        out = np.stack([np.where(over, dr, lr), np.where(over, di, li)], axis=1).astype(np.float32)
        return out.astype(float)
    bearing = np.where(norm > 1e-9, _ATAN2(li, lr).astype(float), 0.0)
    turn = bearing / (robot.max_angular_speed * dt)
    forward = norm * np.maximum(0.0, np.cos(bearing))
    return np.clip(np.stack([forward, turn], axis=1).astype(np.float32), -1.0, 1.0).astype(float)


@dataclass(frozen=True)
class Seat:
    """Robot ``index`` (0: the first) of K worlds as its scripted policy reads its view
    (:class:`crowdnav.sim.robot_view.RobotView`): row i its world's values, each the single view's own."""

    index: int
    spec: Any
    """Its robot spec (kinematics, speeds, radius: the view's ``scenario.robot``)."""
    position: np.ndarray
    """(K,) complex: its centre."""
    goal: np.ndarray
    """(K,) complex: its goal."""
    heading: np.ndarray
    """(K,): its heading."""
    social: np.ndarray
    """(K,) complex: the humans' social force on it (``robot_social_force``)."""
    static_offset: np.ndarray
    """(K, S) complex: to each static obstacle's nearest point, the polygons' then the discs' (the view's tables, joined)."""
    static_distance: np.ndarray
    """(K, S): their lengths."""


@dataclass(frozen=True)
class Fleet:
    """Every robot of the same K worlds as the others see them, and what the scripted policies share."""

    positions: np.ndarray
    """(K, R) complex: every robot's centre, the first robot's first."""
    active: np.ndarray
    """(K, R) bool: the robots still in the world (a view lists only those)."""
    radii: np.ndarray
    """(R,): their body radii."""
    dt: float
    force: Any
    """The scenario's social-force parameters (``humans.social_force``)."""
    surface_radius: np.ndarray
    """(S,): the static obstacles' surface radii."""

    @cached_property
    def patterns(self) -> tuple[np.ndarray, np.ndarray]:
        """(the distinct rows of ``active``, each world's row among them): the worlds that hold the same robots."""
        patterns, which = np.unique(self.active, axis=0, return_inverse=True)
        return patterns, which.reshape(-1)


def straight_action(seat: Seat, fleet: Fleet) -> np.ndarray:
    """(K, 2): :class:`crowdnav.planning.scripted.StraightToGoal` of ``seat``'s robot in each world."""
    robot, dt = seat.spec, fleet.dt
    to_goal = seat.goal - seat.position
    distance = np.hypot(to_goal.real, to_goal.imag)
    speed = np.minimum(robot.max_speed, distance / dt)
    far = distance > 1e-12
    dr, di = cdiv_real(to_goal.real, to_goal.imag, np.where(far, distance, 1.0))
    vr, vi = cmul(np.where(far, dr, 0.0), np.where(far, di, 0.0), speed, 0.0)
    return velocity_actions(robot, dt, seat.heading, vr, vi)


def social_force_action(seat: Seat, fleet: Fleet) -> np.ndarray:
    """(K, 2): :class:`crowdnav.planning.scripted.SocialForceRobot` of ``seat``'s robot in each world: goal attraction, the humans'
    repulsion (measured), the static obstacles' and the other robots' still in the world, added in the policy's order."""
    robot, params, k = seat.spec, fleet.force, seat.index
    force = sf.goal_force(seat.goal - seat.position, params.goal_weight, params.goal_saturation_distance) + seat.social
    if seat.static_offset.shape[1]:
        gain = sf.repulsion_gain(params.obstacle_strength, robot.radius + fleet.surface_radius, params.obstacle_range)
        force = force + sf.repulsion(seat.static_offset, seat.static_distance, gain[None, :], -1.0 / params.obstacle_range)
    patterns, which = fleet.patterns
    for p, pattern in enumerate(patterns):  # the robots this one sees: those still in the world (a sum's length is its rounding)
        seen = [i for i in range(len(pattern)) if pattern[i] and i != k]
        if not pattern[k] or not seen:
            continue
        rows = np.flatnonzero(which == p)
        offsets = fleet.positions[rows][:, seen] - seat.position[rows, None]
        gain = sf.repulsion_gain(params.robot_strength, robot.radius + fleet.radii[seen], params.robot_range)
        force[rows] = force[rows] + sf.repulsion(offsets, np.abs(offsets), gain[None, :], -1.0 / params.robot_range)
    vr, vi = cmul(force.real, force.imag, robot.max_speed, 0.0)
    speed = np.hypot(vr, vi)
    over = speed > robot.max_speed
    sr, si = cmul(vr, vi, robot.max_speed / np.where(over, speed, 1.0), 0.0)
    return velocity_actions(robot, fleet.dt, seat.heading, np.where(over, sr, vr), np.where(over, si, vi))


SEAT_POLICIES: dict[str, Callable[[Seat, Fleet], np.ndarray]] = {"social-force": social_force_action, "straight": straight_action}
"""The scripted policies (:data:`crowdnav.planning.scripted.SCRIPTED_POLICIES` names) with a batched twin for any robot of a stack."""


def _team_seat(team: TeamStack, worlds: np.ndarray, j: int) -> Seat:
    """Other robot ``j`` (robot ``j + 1``) of ``worlds``."""
    return Seat(j + 1, team.specs[j], team.positions[worlds, j], team.goals[worlds, j], team.headings[worlds, j],
                team.social[worlds, j], team.static_offset[worlds, j], team.static_distance[worlds, j])


def _team_fleet(team: TeamStack, worlds: np.ndarray, ego: np.ndarray) -> Fleet:
    """The robots of ``worlds``, the first one at ``ego``."""
    return Fleet(np.concatenate([ego[:, None], team.positions[worlds]], axis=1), team.active[worlds], team.team.all_radii,
                 team.team_dt, team.force, team.surface_radius)


def straight_robots(team: TeamStack, worlds: np.ndarray, ego: np.ndarray) -> np.ndarray:
    """:class:`crowdnav.planning.scripted.StraightToGoal` for every other robot of ``worlds``."""
    return _other_robots(straight_action, team, worlds, ego)


def social_force_robots(team: TeamStack, worlds: np.ndarray, ego: np.ndarray) -> np.ndarray:
    """:class:`crowdnav.planning.scripted.SocialForceRobot` for every other robot of ``worlds``."""
    return _other_robots(social_force_action, team, worlds, ego)


def _other_robots(policy: Callable[[Seat, Fleet], np.ndarray], team: TeamStack, worlds: np.ndarray, ego: np.ndarray) -> np.ndarray:
    fleet = _team_fleet(team, worlds, ego)
    out = np.zeros((len(worlds), len(team.specs), 2))
    for j in range(len(team.specs)):
        out[:, j] = policy(_team_seat(team, worlds, j), fleet)
    return _parked_still(team, worlds, out)


def every_robot_actions(name: str, batch: BatchSimulator, worlds: np.ndarray) -> np.ndarray:
    """(K, R, 2) float64 of the float32 actions: scripted policy ``name`` (:data:`SEAT_POLICIES`) for every robot of
    ``worlds`` of ``batch`` (a ``robots:`` scenario's), the first robot included, each as the policy called with that
    robot's view of its world (``simulator.robot_view(k)``); 0 for a robot that left."""
    team = batch.team
    assert team is not None  # a robots: scenario's
    w, s = batch.num_worlds, team.static_count
    position, goal, social = np.zeros(w, complex), np.zeros(w, complex), np.zeros(w, complex)
    heading, offset, distance = np.zeros(w), np.zeros((w, s), complex), np.zeros((w, s))
    for bucket in batch.buckets.values():  # the first robot lives in its crowd size's stack: each size's worlds at once
        state, rows = bucket.state, bucket.world
        position[rows], goal[rows], heading[rows] = state.positions[:, 0], state.robot_goal, state.robot_heading
        social[rows] = bucket.repulsion[:, 0]  # the simulator's robot_social_force
        offset[rows] = np.concatenate([bucket.polygon_offset, bucket.disc_offset], axis=1)
        distance[rows] = np.concatenate([bucket.polygon_distance, bucket.disc_distance], axis=1)
    fleet = _team_fleet(team, worlds, position[worlds])
    seats = [Seat(0, batch.scenario.robot, position[worlds], goal[worlds], heading[worlds], social[worlds], offset[worlds],
                  distance[worlds])] + [_team_seat(team, worlds, j) for j in range(len(team.specs))]
    policy = SEAT_POLICIES[name]
    out = np.zeros((len(worlds), len(seats), 2))
    for k, seat in enumerate(seats):
        out[:, k] = policy(seat, fleet)
    out[~fleet.active] = 0.0
    return out


def _parked_still(team: TeamStack, worlds: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """``actions`` with 0 for the robots that left (the single env does not call their policy)."""
    actions[~team.active[worlds, 1:]] = 0.0
    return actions
