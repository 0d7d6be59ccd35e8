"""``humans.routing: geodesic``: oncoming humans side-step to pass each other (pedsim's look-ahead force).

Routed humans all take the room's shortest lane, so two flows meeting at a gap walk straight into
each other, and the social force (a repulsion along the line between two people) has no sideways
choice: seen head-on, it only pushes back. Pedestrians resolve this by stepping aside early,
mostly to the same side (lane formation; Helbing & Molnár 1995, Phys. Rev. E 51: 4282). This is
the look-ahead force of libpedsim (Gloor, ``Tagent::lookaheadForce``): a human that sees oncoming
people in its lane ahead adds a push sideways to its goal force, away from the side where more of
them are, and to its right when they are straight ahead or as many on each side (so two people
meeting head-on both step to their right and pass).

"Oncoming": the other human's goal direction (routed, the way it intends to walk; not its
velocity, which is near zero in exactly the jams this is for) is more than ``OPPOSED`` away from
one's own. "In the lane ahead": less than ``LOOK_AHEAD`` m ahead along one's goal direction and
less than two radii plus ``LANE_MARGIN`` to its side. Members of one group that walks together
never count each other (they share a goal). The counts are integers, so a batch of worlds gives
the single simulator's forces bit for bit.
"""

from __future__ import annotations

import math

import numpy as np

LOOK_AHEAD = 4.0
"""How far ahead (m, along one's goal direction) oncoming people are counted (pedsim: 20 m in open space; a room is smaller)."""
LANE_MARGIN = 0.2
"""Oncoming people closer than two radii plus this (m) to one's line of walking are in one's lane (they would touch)."""
OPPOSED = math.cos(math.radians(120.0))
"""Oncoming: the cosine between the two goal directions is below this (more than 120 degrees apart; pedsim: ~143)."""
RIGHT_BIAS = 0.1
"""Someone ahead less than this (m) to one's right still counts as straight ahead, so both of a head-on pair go right."""
STRENGTH = 0.75
"""The sideways push, as a fraction of the goal force's weight (pedsim: 0.5 of its desired force). In the L-shaped room of
tests/core/routing_l_room.yaml (seeds 0-4) 0.5 leaves seed 1 jammed at 0.22 m/s; 0.75 keeps every seed at 0.42-0.46 m/s
(docs/simulator.md#routing-around-furniture)."""


def passing_force(humans: np.ndarray, to_goal: np.ndarray, walking: np.ndarray, radius: float, weight: float,
                  group: np.ndarray, together: np.ndarray | None) -> np.ndarray:
    """(..., n) complex: the sideways push on each human (dimensionless, added to the goal force; 0 with no one oncoming).

    ``humans``, ``to_goal`` (..., n) complex: positions and the (routed) goal vectors, any leading world
    axes; ``walking`` (..., n) bool: who moves (stopped humans neither count nor step aside);
    ``radius``: the humans' radius (m); ``weight``: the goal force's weight; ``group`` (..., n) int and
    ``together`` (G,) bool or None: the groups and which walk together.
    """
    length = np.abs(to_goal)
    heading = np.where(length > 0, to_goal / np.where(length > 0, length, 1.0), 0.0)  # unit goal direction, 0 at the goal
    # [..., i, j]: where j stands in i's frame (real: ahead of i, imag: to i's left)
    local = (humans[..., None, :] - humans[..., :, None]) * np.conj(heading)[..., :, None]
    oncoming = (heading[..., :, None] * np.conj(heading)[..., None, :]).real < OPPOSED
    ahead = oncoming & (local.real > 0) & (local.real < LOOK_AHEAD) & (np.abs(local.imag) < 2 * radius + LANE_MARGIN)
    ahead &= walking[..., :, None] & walking[..., None, :]
    if together is not None:  # fellow members of a walking group share the goal: they never meet head-on
        ahead &= ~((group[..., :, None] == group[..., None, :]) & together[group][..., :, None])
    left = (ahead & (local.imag > -RIGHT_BIAS)).sum(axis=-1)  # straight ahead counts as left: step right
    right = ahead.sum(axis=-1) - left
    side = np.where(left >= right, -1j, 1j) * ((left + right) > 0)  # -1j turns the heading to its right
    force: np.ndarray = (STRENGTH * weight) * heading * side
    return force
