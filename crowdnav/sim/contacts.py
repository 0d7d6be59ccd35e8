"""What a step checks after moving everyone, written once for both simulators: kernels on K worlds.

Humans that overlap are pushed apart and out of obstacles; then the robot's contacts, whether
it left the world and whether it reached its goal give a step's outcome inputs. Each kernel
takes arrays with a leading world axis (K,): :class:`crowdnav.batch.simulator.BatchSimulator`
calls them with a chunk of worlds, :class:`crowdnav.Simulator` with its one world (a view with
K = 1 where the kernel loops over worlds that still overlap, which only steps with overlaps
pay; the robot's checks take no world axis at all, so the single path pays no numpy overhead).
Every world's numbers come from the same operations on the same values whatever K, so both
simulators agree bit for bit (tests/core/test_vector_env.py).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from crowdnav.sim.events import Collision
from crowdnav.sim.state import OBSTACLE_PASSES
from crowdnav.worlds.obstacles import nearest_on_edges


def push_humans_apart(positions: np.ndarray, pair_offset: np.ndarray, pair_distance: np.ndarray, pair_gap: np.ndarray) -> None:
    """Push overlapping humans apart, half the overlap each, in place.

    ``positions``: (K, n+1) complex, robot first; ``pair_offset`` / ``pair_distance`` / ``pair_gap``:
    (K, n, n), from human i to human j (gap: surface distance, negative where they overlap).
    """
    positions[:, 1:] += ((pair_offset / pair_distance) * (np.minimum(pair_gap, 0.0) / 2)).sum(-1)


def push_out_of_obstacles(positions: np.ndarray, surface: Any, contact: np.ndarray, passes: int = OBSTACLE_PASSES) -> None:
    """Push humans out of walls and furniture, in place, up to ``passes`` times.

    ``positions``: (K, n+1) complex, robot first (the robot is not moved); ``surface``: the
    obstacles' edges (:attr:`crowdnav.worlds.obstacles.StaticObstacles.surface`); ``contact``: (n, S)
    surface contact distance of each human to each obstacle. A pass measures the humans of the
    worlds still overlapping and moves each inside human out along its nearest points; a world
    whose humans are clear stops there (a second pass settles corners between two obstacles).
    """
    rows, n = np.arange(len(positions)), positions.shape[1] - 1
    for _ in range(passes):
        humans = positions[rows, 1:]
        offset, distance = nearest_on_edges(humans.reshape(-1), surface)
        offset, distance = offset.reshape(len(rows), n, -1), distance.reshape(len(rows), n, -1)
        gap = distance - contact
        overlapping = gap.reshape(len(rows), -1).min(1) < 0.0
        if not overlapping.any():
            return
        rows, humans, offset, distance, gap = rows[overlapping], humans[overlapping], offset[overlapping], distance[overlapping], gap[overlapping]
        direction = offset / np.maximum(distance, 1e-12)
        humans += (direction * np.minimum(gap, 0.0)).sum(-1)
        positions[rows, 1:] = humans


def resolve_overlaps(positions: np.ndarray, pair_offset: np.ndarray, pair_distance: np.ndarray, gap: np.ndarray, contact_all: np.ndarray,
                     surface: Any) -> None:
    """Humans apart (:func:`push_humans_apart`), then out of walls and furniture (:func:`push_out_of_obstacles`), in place.

    ``positions``: (K, n+1) complex, robot first; ``pair_offset`` / ``pair_distance`` (K, n+1, n+1) and
    ``gap`` (K, n+1, n+1+S) as measured (:class:`crowdnav.sim.geometry.Measured`); ``contact_all``:
    (n+1, n+1+S) the crowd size's contact distances; ``surface``: the obstacles' edges (None: no obstacles).
    Obstacles go last, from the positions after the pair push: a neighbour's push can move a human into furniture.
    """
    n = positions.shape[-1] - 1
    push_humans_apart(positions, pair_offset[:, 1:, 1:], pair_distance[:, 1:, 1:], gap[:, 1:, 1 : n + 1])
    if surface is not None:
        push_out_of_obstacles(positions, surface, contact_all[1:, n + 1 :])


def touching(robot_gap: np.ndarray) -> np.ndarray:
    """(...,) bool: whether the robot touches anything (touching counts); ``robot_gap``: (..., n+1+S) its surface gaps.

    Columns: the robot itself (a huge gap), every human, every obstacle (polygons, then discs).
    """
    touches: np.ndarray = np.minimum.reduce(robot_gap, axis=-1) <= 0.0  # ndarray.min without its Python wrapper
    return touches


def deepest_contact(robot_gap: np.ndarray, n: int, obstacle_labels: Sequence[str]) -> Collision:
    """The robot's deepest contact in one world whose robot is :func:`touching`: ``robot_gap`` (n+1+S,)."""
    k = int(robot_gap.argmin())
    if k <= n:
        return Collision("human", f"human_{k - 1}", float(robot_gap[k]))
    return Collision("static", obstacle_labels[k - n - 1], float(robot_gap[k]))


def outside(x: Any, y: Any, bounds: tuple[float, float, float, float]) -> Any:
    """Whether the point (x, y) is outside ``bounds`` = (x0, y0, x1, y1): Python floats give a bool, arrays a bool array."""
    x0, y0, x1, y1 = bounds
    return (x < x0) | (x > x1) | (y < y0) | (y > y1)


def goal_distance(goal: Any, position: Any) -> Any:
    """``|goal - position|`` (m): of one world's complex scalars (``abs``) or of arrays (``np.hypot``: the same libm hypot)."""
    gap = goal - position
    if isinstance(gap, complex):
        return abs(gap)
    return np.hypot(gap.real, gap.imag)
