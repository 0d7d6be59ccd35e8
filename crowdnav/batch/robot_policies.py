"""The scripted policies that drive the other robots of a ``robots:`` scenario, every world's at once.

The single env drives each other robot with a scripted policy called on that robot's view
(:class:`crowdnav.policies.SocialForceRobot`, :class:`crowdnav.policies.StraightToGoal`, on
:meth:`crowdnav.Simulator.robot_view`), in Python's scalar arithmetic. :func:`batched_policy` gives the same
policy over a world axis, written with :mod:`crowdnav.batch.scalar_math` so that each world's action has the
single policy's bits: robot j of every world at once (a loop over the robots, each its own spec), the sums
over the other robots it sees grouped by which robots are still in the world (a view lists only those, and
the length of a sum decides its rounding). A unicycle's bearing (``cmath.phase``) is libm's ``atan2`` called
per entry: numpy's vectorized ``arctan2`` differs from it in the last bit. A policy without a batched twin (ORCA, a callable) is not
stacked: :func:`crowdnav.envs.vector.stacks` keeps such worlds as single envs.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from crowdnav.batch.scalar_math import cdiv_real, cmul
from crowdnav.batch.team import TeamStack
from crowdnav.sim import forces as sf

_ATAN2 = np.frompyfunc(math.atan2, 2, 1)
"""``cmath.phase``'s libm ``atan2`` per entry: numpy's own ``arctan2`` is vectorized differently and differs in the last bit."""

RobotPolicy = Callable[[TeamStack, np.ndarray, np.ndarray], np.ndarray]
"""``policy(team, worlds, ego) -> (K, m, 2)`` float64 actions of the other robots of ``worlds`` (``ego``: their (K,)
ego robot positions), 0 for a robot that left, as the single env's ``np.asarray(policy(view), dtype=float)``."""


def batched_policy(name: Any) -> RobotPolicy | None:
    """The batched twin of the ``other_robots`` option ``name`` (None: none, the worlds run as single envs)."""
    return {"social-force": social_force_robots, "straight": straight_robots}.get(name) if isinstance(name, str) else None


def velocity_actions(robot: Any, dt: float, heading: np.ndarray, vr: np.ndarray, vi: np.ndarray) -> np.ndarray:
    """:func:`crowdnav.policies.velocity_to_action` of one robot spec in every row: (K, 2) float64 of the float32 action."""
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


def _all_positions(team: TeamStack, worlds: np.ndarray, ego: np.ndarray) -> np.ndarray:
    """(K, R) every robot's position, the ego robot first."""
    return np.concatenate([ego[:, None], team.positions[worlds]], axis=1)


def straight_robots(team: TeamStack, worlds: np.ndarray, ego: np.ndarray) -> np.ndarray:
    """:class:`crowdnav.policies.StraightToGoal` for every other robot of ``worlds``."""
    out = np.zeros((len(worlds), len(team.specs), 2))
    dt = team.team_dt
    for j, robot in enumerate(team.specs):
        to_goal = team.goals[worlds, j] - team.positions[worlds, j]
        distance = np.hypot(to_goal.real, to_goal.imag)
        speed = np.minimum(robot.max_speed, distance / dt)
        far = distance > 1e-12
        dr, di = cdiv_real(to_goal.real, to_goal.imag, np.where(far, distance, 1.0))
        vr, vi = cmul(np.where(far, dr, 0.0), np.where(far, di, 0.0), speed, 0.0)
        out[:, j] = velocity_actions(robot, dt, team.headings[worlds, j], vr, vi)
    return _parked_still(team, worlds, out)


def social_force_robots(team: TeamStack, worlds: np.ndarray, ego: np.ndarray) -> np.ndarray:
    """:class:`crowdnav.policies.SocialForceRobot` for every other robot of ``worlds``: goal attraction, the humans' repulsion
    (measured), the static obstacles' and the other robots' still in the world."""
    params, dt = team.force, team.team_dt
    out = np.zeros((len(worlds), len(team.specs), 2))
    everyone = _all_positions(team, worlds, ego)
    active = team.active[worlds]
    patterns, which = np.unique(active, axis=0, return_inverse=True)
    which = which.reshape(-1)
    for j, robot in enumerate(team.specs):
        position = team.positions[worlds, j]
        to_goal = team.goals[worlds, j] - position
        force = sf.goal_force(to_goal, params.goal_weight, params.goal_saturation_distance) + team.social[worlds, j]
        if team.static_count:
            gain = sf.repulsion_gain(params.obstacle_strength, robot.radius + team.surface_radius, params.obstacle_range)
            force = force + sf.repulsion(team.static_offset[worlds, j], team.static_distance[worlds, j], gain[None, :],
                                         -1.0 / params.obstacle_range)
        for p, pattern in enumerate(patterns):  # the robots this one sees: those still in the world (a sum's length is its rounding)
            rows = np.flatnonzero(which == p)
            seen = [k for k in range(len(pattern)) if pattern[k] and k != j + 1]
            if not pattern[j + 1] or not seen:
                continue
            offsets = everyone[rows][:, seen] - position[rows, None]
            gain = sf.repulsion_gain(params.robot_strength, robot.radius + team.team.all_radii[seen], params.robot_range)
            force[rows] = force[rows] + sf.repulsion(offsets, np.abs(offsets), gain[None, :], -1.0 / params.robot_range)
        vr, vi = cmul(force.real, force.imag, robot.max_speed, 0.0)
        speed = np.hypot(vr, vi)
        over = speed > robot.max_speed
        sr, si = cmul(vr, vi, robot.max_speed / np.where(over, speed, 1.0), 0.0)
        out[:, j] = velocity_actions(robot, dt, team.headings[worlds, j], np.where(over, sr, vr), np.where(over, si, vi))
    return _parked_still(team, worlds, out)


def _parked_still(team: TeamStack, worlds: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """``actions`` with 0 for the robots that left (the single env does not call their policy)."""
    actions[~team.active[worlds, 1:]] = 0.0
    return actions
