"""Every robot of a batch's worlds seen from itself: :func:`robot_view`, the batched twin of :class:`crowdnav.sim.robot_view.RobotView`.

A single simulator of a ``robots:`` scenario shows the world from robot k as a :class:`RobotView`: that robot first, then
the humans, then the other robots still in the world (index order), its own heading, goal and obstacle distances. The
sensors read that view as they read a simulator. :func:`robot_view` builds the same arrays for many worlds at once, as a
:class:`crowdnav.batch.state.BatchState` the modalities' ``observe_batch`` reads, for worlds that hold the same robots
(a view lists only those, and its length decides what a sensor sums): the caller groups the worlds by which robots are
there. Every value is a copy of the stack's or the same numpy operation as RobotView's on the same values.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from crowdnav.batch.state import BatchState
from crowdnav.batch.team import TeamStack
from crowdnav.sim.state import SELF_DISTANCE


def robot_view(state: BatchState, team: TeamStack, worlds: np.ndarray, robot: int, seen: np.ndarray) -> BatchState:
    """Robot ``robot`` (0: the first) of ``worlds`` (``state``: their rows of the stack, the first robot and the humans) as
    :class:`crowdnav.sim.robot_view.RobotView` shows it, with the robots ``seen`` (indices among every robot, ``robot``
    left out, ascending; empty: ``with_robots=False``) after the humans."""
    if robot == 0 and not len(seen):
        return state  # the stack's own rows: what the first robot sees of the humans alone (the batched env's observation)
    polygons = state.polygon_offset.shape[1]
    if robot == 0:
        me, velocity, radius = state.positions[:, :1], state.velocities[:, :1], state.radii[:1]
        heading, goal = state.robot_heading, state.robot_goal
        obstacle_offset = np.concatenate([state.polygon_offset, state.disc_offset], axis=1)
        obstacle_distance = np.concatenate([state.polygon_distance, state.disc_distance], axis=1)
    else:
        j = robot - 1
        me, velocity, radius = team.positions[worlds, j : j + 1], team.velocities[worlds, j : j + 1], team.team.radii[j : j + 1]
        heading, goal = team.headings[worlds, j], team.goals[worlds, j]
        obstacle_offset, obstacle_distance = team.static_offset[worlds, j], team.static_distance[worlds, j]
    positions, velocities, radii = [me, state.positions[:, 1:]], [velocity, state.velocities[:, 1:]], [radius, state.radii[1:]]
    if len(seen):
        everyone = np.concatenate([state.positions[:, :1], team.positions[worlds]], axis=1)
        moving = np.concatenate([state.velocities[:, :1], team.velocities[worlds]], axis=1)
        positions.append(everyone[:, seen])
        velocities.append(moving[:, seen])
        radii.append(team.team.all_radii[seen])
    z = np.concatenate(positions, axis=1)
    offset = z - z[:, :1]
    distance = np.abs(offset)
    distance[:, 0] = SELF_DISTANCE
    return dataclasses.replace(state, positions=z, velocities=np.concatenate(velocities, axis=1), robot_heading=heading,
                               robot_goal=goal, radii=np.concatenate(radii), robot_offset=offset, robot_distance=distance,
                               polygon_offset=obstacle_offset[:, :polygons], polygon_distance=obstacle_distance[:, :polygons],
                               disc_offset=obstacle_offset[:, polygons:], disc_distance=obstacle_distance[:, polygons:])
