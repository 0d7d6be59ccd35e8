"""Who walks with whom: the links drawn between the members of each group that walks together (``walk_together``).

Each such group's walking members are joined by a thin line in the group's colour, darkened: two
members by one segment, three or more by a closed outline through them in order of their angle
around the group's centre (its convex outline for the small groups people walk in). The renderer
draws the links under the humans' discs, so a viewer sees at a glance which discs belong together,
and a robot that cuts through a group crosses its outline (the ``group_intrusions`` metric).
"""

from __future__ import annotations

from typing import Any

import numpy as np

LINK_WIDTH = 2
"""Line width of a link (pixels)."""
DARKEN = 0.6
"""A link's colour: the group's colour times this (darker than the discs it joins)."""


def group_links(sim: Any, colours: list[tuple[int, int, int]]) -> list[tuple[tuple[int, int, int], np.ndarray, bool]]:
    """``(colour, points, closed)`` per group that walks together and has two walking members or more, file order.

    ``points``: the members' world positions (complex) in outline order; ``closed``: join the last to the first.
    """
    together = getattr(sim, "together", None)
    if together is None:
        return []
    out = []
    walking = ~sim.human_stopped
    for g in np.flatnonzero(together):  # a loop over the scenario's groups (a handful), never over humans
        members = sim.human_positions[(sim.human_group == g) & walking]
        if len(members) < 2:
            continue
        order = np.argsort(np.angle(members - members.mean()))
        colour = tuple(int(c * DARKEN) for c in colours[g])
        out.append(((colour[0], colour[1], colour[2]), members[order], len(members) > 2))
    return out


def draw_group_links(surface: Any, sim: Any, colours: list[tuple[int, int, int]], to_pixels: Any) -> None:
    """Draw :func:`group_links` on a pygame ``surface`` (``to_pixels``: world points to pixel coordinates)."""
    import pygame

    for colour, points, closed in group_links(sim, colours):
        pygame.draw.lines(surface, colour, closed, [tuple(p) for p in to_pixels(points).tolist()], LINK_WIDTH)
