"""Every robot of a batch's worlds seen from itself: :func:`robot_view`, the batched twin of :class:`crowdnav.sim.robot_view.RobotView`.

A single simulator of a ``robots:`` scenario shows the world from robot k as a :class:`RobotView`: that robot first, then
the humans, then the other robots still in the world (index order), its own heading, goal and obstacle distances. The
sensors read that view as they read a simulator. :func:`robot_view` builds the same arrays for many worlds at once, as a
:class:`crowdnav.batch.state.BatchState` the modalities' ``observe_batch`` reads, for worlds that hold the same robots
(a view lists only those, and its length decides what a sensor sums): the caller groups the worlds by which robots are
there. Every value is the stack's, a copy of its or the team's, or made by the same numpy operations as RobotView's
(:func:`crowdnav.sim.robot_view.robot_offsets`) from the same values.
"""

from __future__ import annotations

import numpy as np

from crowdnav.batch.state import BatchState
from crowdnav.batch.team import TeamStack
from crowdnav.sim.robot_view import robot_offsets


def robot_view(state: BatchState, team: TeamStack, worlds: np.ndarray, robot: int, seen: np.ndarray,
               rows: np.ndarray | None = None) -> BatchState:
    """Robot ``robot`` (0: the first) of ``worlds`` as :class:`crowdnav.sim.robot_view.RobotView` shows it, with the robots
    ``seen`` (indices among every robot, ``robot`` left out, ascending; empty: ``with_robots=False``) after the humans.

    ``state``: rows of the stack (the first robot and the humans), of which ``rows`` are ``worlds`` (None: all of them).
    """
    if robot == 0 and not len(seen):
        return state.rows(rows)  # the stack's own rows: what the first robot sees of the humans alone (the batched env's observation)
    first, moving = (state.positions, state.velocities) if rows is None else (state.positions[rows], state.velocities[rows])
    own: dict[str, np.ndarray] = {}  # the first robot's heading, goal and obstacle tables: the stack's
    if robot == 0:  # the stack's rows, then the robots seen (all of them robots of the team)
        others = seen - 1
        positions, velocities, radii = [first, team.positions[worlds][:, others]], [moving, team.velocities[worlds][:, others]], [state.radii]
    else:
        j = robot - 1
        positions = [team.positions[worlds, j : j + 1], first[:, 1:]]
        velocities = [team.velocities[worlds, j : j + 1], moving[:, 1:]]
        radii = [team.team.radii[j : j + 1], state.radii[1:]]
        offset, distance, p = team.static_offset[worlds, j], team.static_distance[worlds, j], state.polygon_offset.shape[1]
        own = {"robot_heading": team.headings[worlds, j], "robot_goal": team.goals[worlds, j], "polygon_offset": offset[:, :p],
               "polygon_distance": distance[:, :p], "disc_offset": offset[:, p:], "disc_distance": distance[:, p:]}
        if len(seen):  # every robot's, the first robot first
            positions.append(np.concatenate([first[:, :1], team.positions[worlds]], axis=1)[:, seen])
            velocities.append(np.concatenate([moving[:, :1], team.velocities[worlds]], axis=1)[:, seen])
    if len(seen):
        radii.append(team.team.all_radii[seen])
    z = np.concatenate(positions, axis=1)
    robot_offset, robot_distance = robot_offsets(z)
    return state.rows(rows, positions=z, velocities=np.concatenate(velocities, axis=1), radii=np.concatenate(radii),
                      robot_offset=robot_offset, robot_distance=robot_distance, **own)
