"""The geometry of a large crowd: the robot against everyone, each human against its neighbours.

The simulator's all-pairs geometry costs ``(n + 1)^2`` per step. From
:attr:`crowdnav.sim.simulator.Simulator.grid_from` humans on, it uses this instead: human-human
repulsion and overlaps only for pairs closer than a cut-off (found with a grid of cells,
:func:`crowdnav.sim.neighbours.close_pairs`), and the robot's row and column (the social term, the
robot's collisions, humans who see the robot) over everyone, exactly as before.

**The cut-off and its tolerance.** Human-human repulsion is ``A * exp((2r - d) / B)``; beyond
``d = 2r + B * ln(A / PAIR_FORCE_TOLERANCE)`` each pair's force is below
``PAIR_FORCE_TOLERANCE`` (1e-6, dimensionless, against forces of order 1), and those pairs are
left out: about 4.7 m for the default parameters (A = 2, B = 0.3 m, r = 0.3 m). Everything else
(obstacles, the robot, overlaps) is computed as in the all-pairs model, so one step differs from
it by at most the left-out pairs' forces (tests/core/test_crowd_grid.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from crowdnav.sim import forces as sf
from crowdnav.sim.neighbours import close_pairs

if TYPE_CHECKING:
    from crowdnav.scenario.crowd import SocialForce

PAIR_FORCE_TOLERANCE = 1e-6
"""Largest human-human force (dimensionless) a left-out pair could exert."""


@dataclass
class GridGeometry:
    """One refresh of a large crowd's geometry (see :meth:`CrowdGrid.refresh`)."""

    repulsion: np.ndarray
    """(n+1,) complex: social repulsion on every agent, robot first (as the all-pairs model's)."""
    robot_offset: np.ndarray
    """(n+1,) complex: from the robot to every agent (itself: 0)."""
    robot_distance: np.ndarray
    """(n+1,) centre distances from the robot (itself: a huge number)."""
    robot_gap: np.ndarray
    """(n+1+S,) surface gaps of the robot to every agent, then every obstacle."""
    humans_touch: bool
    """Whether any human touches another human, the robot or an obstacle."""
    first: np.ndarray
    second: np.ndarray
    """Agent indices (>= 1) of the human pairs within the cut-off, ``first < second``."""
    pair_offset: np.ndarray
    """From ``first`` to ``second`` (complex)."""
    pair_distance: np.ndarray


class CrowdGrid:
    """Constants of a crowd of ``n`` humans for the neighbour-grid geometry."""

    def __init__(self, n: int, robot_radius: float, human_radius: float, force: SocialForce, see_robot: bool,
                 static_gain: np.ndarray, static_decay: float, static_contact: np.ndarray, self_distance: float):
        self.n = n
        self.contact = 2 * human_radius
        self.pair_gain = float(sf.repulsion_gain(force.human_strength, self.contact, force.human_range))
        self.pair_decay = -1.0 / force.human_range
        reach = force.human_range * math.log(force.human_strength / PAIR_FORCE_TOLERANCE) if force.human_strength > PAIR_FORCE_TOLERANCE else 0.0
        self.cutoff = self.contact + max(reach, 0.0) + 1e-9  # never below contact: overlaps are pairs too
        robot_contact = robot_radius + human_radius
        # row 0, the humans' force on the robot (the reward's social term): human parameters
        self.row_gain = np.full(n + 1, float(sf.repulsion_gain(force.human_strength, robot_contact, force.human_range)))
        self.row_gain[0] = 0.0
        # column 0, the robot's push on humans: only when they see it
        self.column_gain = np.full(n + 1, float(sf.repulsion_gain(force.robot_strength if see_robot else 0.0, robot_contact,
                                                                   force.robot_range)))
        self.column_gain[0] = 0.0
        self.row_decay, self.column_decay = -1.0 / force.human_range, -1.0 / force.robot_range
        self.row_contact = np.full(n + 1, robot_contact)
        self.row_contact[0] = 2 * robot_radius
        self.static_gain, self.static_decay, self.static_contact = static_gain, static_decay, static_contact
        self.self_distance = self_distance

    def refresh(self, z: np.ndarray, static_offset: np.ndarray | None, static_distance: np.ndarray | None) -> GridGeometry:
        """Geometry at positions ``z`` ((n+1,) complex, robot first); static parts from ``nearest_on_edges``."""
        robot_offset = z - z[0]
        robot_distance = np.abs(robot_offset)
        robot_distance[0] = self.self_distance
        first, second = close_pairs(z[1:], self.cutoff)
        first, second = first + 1, second + 1
        pair_offset = z[second] - z[first]
        pair_distance = np.abs(pair_offset)
        # each pair pushes both ends: on `first` along -offset, on `second` along +offset (gain < 0)
        push = pair_offset * (self.pair_gain * np.exp(np.multiply(pair_distance, self.pair_decay, dtype=np.float32)) / pair_distance)
        repulsion = _scatter(first, second, push, len(z))
        # the robot's row (force on it from every human) and column (its push on humans who see it)
        row = self.row_gain * np.exp(np.multiply(robot_distance, self.row_decay, dtype=np.float32)) / robot_distance
        repulsion[0] += (robot_offset * row).sum()
        column = self.column_gain * np.exp(np.multiply(robot_distance, self.column_decay, dtype=np.float32)) / robot_distance
        repulsion -= robot_offset * column
        robot_gap = robot_distance - self.row_contact
        humans_touch = bool((pair_distance < self.contact).any() or (robot_gap[1:] < 0).any())
        if static_offset is not None and static_distance is not None:  # both or neither
            repulsion += sf.repulsion(static_offset, static_distance, self.static_gain, self.static_decay)
            static_gap = static_distance - self.static_contact
            robot_gap = np.concatenate([robot_gap, static_gap[0]])
            humans_touch = humans_touch or bool((static_gap[1:] < 0).any())
        return GridGeometry(repulsion, robot_offset, robot_distance, robot_gap, humans_touch, first, second, pair_offset, pair_distance)

    def push_apart(self, geometry: GridGeometry) -> np.ndarray:
        """(n+1,) complex displacement that moves overlapping humans apart, half the overlap each (robot: 0)."""
        overlap = geometry.pair_distance < self.contact
        first, second = geometry.first[overlap], geometry.second[overlap]
        step = (geometry.pair_offset[overlap] / geometry.pair_distance[overlap]) * ((geometry.pair_distance[overlap] - self.contact) / 2)
        return _scatter(first, second, step, self.n + 1)


def _scatter(first: np.ndarray, second: np.ndarray, value: np.ndarray, size: int) -> np.ndarray:
    """(size,) complex: ``+value`` summed onto each pair's ``first`` agent, ``-value`` onto its ``second``."""
    real = np.bincount(first, value.real, size) - np.bincount(second, value.real, size)
    imag = np.bincount(first, value.imag, size) - np.bincount(second, value.imag, size)
    return real + 1j * imag
