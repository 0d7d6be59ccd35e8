"""Candidate positions: a scenario's sets (:class:`Placement`), one region's lattice built at load time, the draw at each reset.

A region (rectangle, circle, polygon, points, circle perimeter) becomes a :class:`CandidateSet`:
points of a hexagonal lattice free of static obstacles and far enough apart that two agents
placed on different points (with their random jitter) never overlap. :meth:`CandidateSet.draw`
picks distinct points at reset, so a reset costs the same at any density. The load-time checks
that the sets hold the scenario's crowd are :mod:`crowdnav.worlds.placement_checks`; the scenario's
sets are assembled by :mod:`crowdnav.worlds.placement`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, TypeAlias

import numpy as np
import shapely
from shapely.geometry import Point, box
from shapely.geometry import Polygon as ShapelyPolygon
from shapely.geometry.base import BaseGeometry

from crowdnav.errors import CrowdNavError
from crowdnav.scenario.schema import CircleRegion, PointsRegion, PolygonRegion, RectangleRegion
from crowdnav.worlds.obstacles import GeometryError

AnyRegion: TypeAlias = RectangleRegion | PolygonRegion | PointsRegion | CircleRegion
"""A spawn, start or goal region of the schema (one of its four kinds)."""

GAP = 0.05
"""Minimum free space (m) between two freshly placed agents, and between an agent and an obstacle."""


JITTER = 0.05
"""Half-width (m) of the uniform jitter added to lattice points so episodes do not look gridded."""


JITTER_REACH = math.sqrt(2) * JITTER
"""Farthest (m) a jittered point lands from its lattice point (the jitter square's half-diagonal): the slack
a distance checked on lattice points leaves for each jittered end."""


@dataclass
class CandidateSet:
    """Candidate positions for one kind of placement (robot start, human goal, ...)."""

    points: np.ndarray
    """(K,) complex lattice points, obstacle-free with margin for the jitter."""
    jitter: float
    """Uniform jitter half-width per axis applied when a point is drawn."""
    ring_center: complex | None = None
    """For circle perimeters: draws rotate the whole ring by a random angle about this centre."""

    def __len__(self) -> int:
        return len(self.points)

    def draw(
        self,
        rng: np.random.Generator,
        n: int,
        *,
        allowed: np.ndarray | None = None,
        away_from: np.ndarray | None = None,
        min_distance: float | np.ndarray = 0.0,
        replace: bool = False,
    ) -> np.ndarray:
        """``n`` positions from distinct candidates (unless ``replace``).

        ``allowed`` masks candidates; ``away_from`` (complex array) excludes candidates closer
        than ``min_distance`` (one distance, or one per point) to any of its points (e.g. agents already placed).
        """
        points = self.points
        if self.ring_center is not None:
            points = (points - self.ring_center) * np.exp(1j * rng.uniform(0, 2 * math.pi)) + self.ring_center
        mask = allowed
        if away_from is not None and len(away_from):
            far = (np.abs(points[:, None] - away_from[None, :]) >= min_distance).all(1)
            mask = far if mask is None else mask & far
        pool = np.flatnonzero(mask) if mask is not None else np.arange(len(points))
        if len(pool) == 0 or (not replace and n > len(pool)):
            raise PlacementError(f"needs {n} free positions but only {len(pool)} are available")
        out: np.ndarray = points[rng.choice(pool, size=n, replace=replace)]
        if self.jitter > 0:
            noise = rng.uniform(-self.jitter, self.jitter, size=(2, n))
            out = out + noise[0] + 1j * noise[1]
        return out


class PlacementError(CrowdNavError, RuntimeError):
    """A reset could not place every agent (only possible with dynamic exclusions)."""


@dataclass
class GroupPlacement:
    """Candidate sets of one human group."""

    path: str
    """Where the group is written in the file (``humans`` or ``humans.groups.<i>``), for error messages."""
    spawn: CandidateSet
    """Walking groups: member start positions; standing groups and groups that walk together: centres of the circle."""
    goal: CandidateSet | None
    """Goal candidates; None for the mirror rule, standing groups and empty groups."""
    circle_radius: float = 0.0
    """Radius (m) of the circle of member centres a standing group or a group that walks together starts on (0 for other groups)."""


@dataclass
class Placement:
    """All candidate sets of a scenario."""

    robot_start: CandidateSet
    robot_goal: CandidateSet
    groups: list[GroupPlacement]
    """One per human group, in file order (one for a file without ``humans.groups``)."""
    start_goal_ok: np.ndarray
    """(K_start, K_goal) bool: pairs far enough apart for min_start_goal_distance, jitter included."""
    start_component: np.ndarray | None = None
    """Free-space component of each robot start candidate (None: all starts and goals share one)."""
    goal_component: np.ndarray | None = None
    """Free-space component of each robot goal candidate (None: all starts and goals share one)."""
    other_robots: list[Placement] = field(default_factory=list)
    """Scenarios with ``robots:``: the robot sets (start, goal, pairs, components) of robots 1, 2, ... (their ``groups`` empty)."""
    fallback: Any = None
    """Robots after the first: their :class:`crowdnav.worlds.placement_team.Fallback` (fine sets drawn from when the lattice is blocked)."""


CHUNK = 512  # rows per block of the pairwise distance tables built at load time


MAX_CANDIDATES = 4_000
"""Lattice points per region at most: a larger region gets a proportionally coarser lattice.

Every library region holds fewer than 200 points, so this only bounds the cost of huge worlds
(start x goal pairs, pairwise merges and draws are all quadratic in it): a 100 m world covered
by regions loads in about a second instead of needing 10 GB."""


def region_candidates(region: AnyRegion, path: str, radius: float, world_box: ShapelyPolygon, occupied: BaseGeometry) -> CandidateSet:
    """Lattice of obstacle-free positions for an agent of ``radius`` inside ``region``."""
    spacing = 2 * radius + GAP + 2 * JITTER_REACH
    clearance = radius + GAP + JITTER_REACH
    if isinstance(region, PointsRegion):
        points = np.array([complex(x, y) for x, y in region.points])
        _require_inside(points, path, world_box)
        free = clear_of(points, radius, occupied)
        if not free.any():
            raise GeometryError(path, f"every point is inside or within {radius:g} m of an obstacle; expected at least one free point")
        return CandidateSet(points[free], 0.0)
    if isinstance(region, CircleRegion) and region.perimeter:
        ring = Point(region.center).buffer(region.radius, 128).exterior
        if not ring.within(world_box):
            raise GeometryError(path, _outside_message(world_box))
        if ring.distance(occupied) < clearance if not occupied.is_empty else False:
            raise GeometryError(path, f"the circle passes within {clearance:.2f} m of an obstacle; expected a free circle")
        count = int(math.floor(math.pi / math.asin(min(1.0, spacing / (2 * region.radius))))) if spacing < 2 * region.radius else 1
        angles = 2 * math.pi * np.arange(count) / count
        center = complex(*region.center)
        return CandidateSet(center + region.radius * np.exp(1j * angles), 0.0, ring_center=center)
    shape = region_polygon(region, path)
    if not shape.within(world_box.buffer(1e-9)):
        raise GeometryError(path, _outside_message(world_box))
    free_area = shape if occupied.is_empty else shape.difference(grown(occupied, clearance))
    if free_area.is_empty or free_area.area < 1e-9:
        raise GeometryError(path, "region is entirely covered by obstacles (with the agent's radius); expected some free space")
    points = best_lattice(free_area, _bounded_spacing(free_area, spacing))
    if len(points) == 0:
        rep = free_area.representative_point()
        points = np.array([complex(rep.x, rep.y)])
        return CandidateSet(points, 0.0)
    return CandidateSet(points, JITTER)


_GROWN: list[Any] = [None, {}]  # [the world's obstacle union, {clearance: buffered union}]


def grown(occupied: BaseGeometry, clearance: float) -> BaseGeometry:
    """``occupied.buffer(clearance)``, computed once per world and clearance (buffering thousands
    of obstacles is the slowest step of loading; a world's regions share one or two clearances)."""
    if _GROWN[0] is not occupied:
        _GROWN[0], _GROWN[1] = occupied, {}  # one world at a time: no stale geometry is kept alive
    grown = _GROWN[1]
    if clearance not in grown:
        grown[clearance] = occupied.buffer(clearance)
    return grown[clearance]


def region_polygon(region: AnyRegion, path: str) -> ShapelyPolygon:
    if isinstance(region, RectangleRegion):
        return box(region.min[0], region.min[1], region.max[0], region.max[1])
    if isinstance(region, CircleRegion):
        return Point(region.center).buffer(region.radius, 64)
    assert isinstance(region, PolygonRegion)
    shape = ShapelyPolygon(region.points)
    if not shape.is_valid or shape.area <= 0:
        from shapely.validation import explain_validity

        raise GeometryError(f"{path}.points", f"polygon is not valid ({explain_validity(shape)}); expected a simple polygon with non-zero area")
    return shape


def _bounded_spacing(area: BaseGeometry, spacing: float) -> float:
    """``spacing``, widened so the lattice over ``area`` (and over its bounding box, which the
    lattice scan allocates) stays within :data:`MAX_CANDIDATES` (resp. 25 times that) points."""
    minx, miny, maxx, maxy = area.bounds
    cell = spacing * spacing * math.sqrt(3) / 2  # area per hexagonal lattice point
    points, scanned = area.area / cell, (maxx - minx + spacing) * (maxy - miny + spacing) / cell
    factor = max(1.0, points / MAX_CANDIDATES, scanned / (25 * MAX_CANDIDATES))
    return spacing * math.sqrt(factor)


def best_lattice(area: BaseGeometry, spacing: float) -> np.ndarray:
    """Hexagonal lattice points inside ``area``; the best of a few offsets."""
    minx, miny, maxx, maxy = area.bounds
    row = spacing * math.sqrt(3) / 2
    best = np.zeros(0, dtype=complex)
    for ox, oy in ((0.0, 0.0), (0.5, 0.0), (0.0, 0.5), (0.5, 0.5), (0.25, 0.25)):
        ys = np.arange(miny + oy * row, maxy + 1e-9, row)
        xs = np.arange(minx + ox * spacing, maxx + spacing, spacing)
        grid = xs[None, :] + 1j * ys[:, None] + (np.arange(len(ys)) % 2)[:, None] * (spacing / 2)
        grid = grid.ravel()
        inside = shapely.contains_xy(area, grid.real, grid.imag)
        if inside.sum() > len(best):
            best = grid[inside]
    return best


def merge_candidates(sets: list[CandidateSet], spacing: float) -> CandidateSet:
    """Union of candidate sets; drop points closer than ``spacing`` to an earlier one (overlapping regions)."""
    points = np.concatenate([s.points for s in sets])
    ring = next((s.ring_center for s in sets if s.ring_center is not None), None)
    jitter = min(s.jitter for s in sets)
    if spacing > 0 and len(points) > 1:
        dropped = np.zeros(len(points), dtype=bool)  # close to an earlier point
        later = np.arange(len(points))
        for lo in range(0, len(points), CHUNK):  # row blocks: memory stays at CHUNK x K
            rows = slice(lo, lo + CHUNK)
            close = np.abs(points[rows, None] - points[None, :]) < spacing - 1e-9
            dropped |= (close & (later[None, :] > later[rows, None])).any(0)
        points = points[~dropped]
    return CandidateSet(points, jitter, ring if len(sets) == 1 else None)


def clear_of(points: np.ndarray, clearance: float, occupied: BaseGeometry) -> np.ndarray:
    if occupied.is_empty:
        return np.ones(len(points), dtype=bool)
    free: np.ndarray = shapely.distance(occupied, shapely.points(points.real, points.imag)) >= clearance
    return free


def _require_inside(points: np.ndarray, path: str, world_box: ShapelyPolygon) -> None:
    inside = shapely.contains_xy(world_box, points.real, points.imag)
    if not inside.all():
        raise GeometryError(path, _outside_message(world_box))


def _outside_message(world_box: ShapelyPolygon) -> str:
    minx, miny, maxx, maxy = world_box.bounds
    return f"region extends outside the world; expected it inside x in [{minx:g}, {maxx:g}], y in [{miny:g}, {maxy:g}]"
