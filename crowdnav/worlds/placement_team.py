"""Several robots (``robots:``): room for every robot together, proved at load time, and the fallback draw that uses it.

The robots after the first are drawn one after the other, each clear of those drawn before it
(:meth:`crowdnav.sim.robots.Team.draw`). A draw first picks a point of the robot's own lattice (as
it always did, so every scenario that reset before draws the same episodes); robots sharing a
region (all starting in one door, overlapping regions) can block every lattice point, since the
robots before sit at jittered positions between them. The draw then falls back to the region's
*fine set*: a dense lattice (about :data:`FINE_POINTS` points, spacing at least
:data:`FINE_SPACING`) with the lattice points themselves, drawn without jitter, under the same
clearances.

:func:`check_team` proves at load time that the fine sets always hold a start and a goal for
every robot, whatever the robots before it drew: each of them can block at most the fine points
within its clearance of any position it can take, so the sum of those worst cases, taken from
the fine set, must leave a point. A scenario that fails is refused in one line naming the
robot's region and the regions that crowd it. Robots whose regions are far apart block nothing,
so the check never refuses them (it refuses no library scenario).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from shapely.geometry import Polygon as ShapelyPolygon
from shapely.geometry.base import BaseGeometry

from crowdnav.scenario.schema import CircleRegion, PointsRegion, Robot, Scenario
from crowdnav.worlds.obstacles import GeometryError
from crowdnav.worlds.placement_checks import component_of, free_components, max_blocked, ring_samples
from crowdnav.worlds.placement_regions import (
    CHUNK,
    GAP,
    JITTER_REACH,
    AnyRegion,
    CandidateSet,
    Placement,
    PlacementError,
    best_lattice,
    grown,
    region_polygon,
)

FINE_POINTS = 1_500
"""About how many points a robot region's fine set holds at most (a larger region gets a coarser one)."""

FINE_SPACING = 0.05
"""Smallest spacing (m) of a fine set's lattice."""


@dataclass
class Fallback:
    """One robot's fine sets (robots after the first only): where its draw goes when its lattice is blocked."""

    start: CandidateSet
    """Fine start positions (no jitter, no rotation)."""
    goal: CandidateSet
    """Fine goal positions (no jitter, no rotation)."""
    goal_distance: float
    """Least distance (m) from the start to a fine goal: ``min_start_goal_distance``, and beyond the goal radius."""
    components: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
    """Free-space component of the lattice starts, the lattice goals, the fine starts and the fine goals (None: one free space)."""
    _start_ok: np.ndarray | None = None

    @property
    def start_ok(self) -> np.ndarray:
        """(K_fine_start,) bool: fine starts with a fine goal :attr:`goal_distance` away in their free space.

        Computed at first use: only robots whose regions others can crowd need it (at load time or at a fallback draw).
        """
        if self._start_ok is None:
            components = self.components[2:] if self.components is not None else (None, None)
            self._start_ok = _goal_counts(self.start.points, 0.0, self.goal.points, self.goal_distance, *components) > 0
        return self._start_ok

    def draw_start(self, rng: np.random.Generator, away_from: np.ndarray, min_distance: np.ndarray) -> tuple[complex, int]:
        """A fine start clear of ``away_from``, and its component (0 without components)."""
        index = self._draw(self.start, rng, self.start_ok, away_from, min_distance)
        return complex(self.start.points[index]), int(self.components[2][index]) if self.components is not None else 0

    def draw_goal(self, rng: np.random.Generator, component: int, away_from: np.ndarray, min_distance: np.ndarray) -> complex:
        """A fine goal in free-space ``component`` clear of ``away_from`` (its start first, at :attr:`goal_distance`)."""
        allowed = self.components[3] == component if self.components is not None else None
        return complex(self.goal.points[self._draw(self.goal, rng, allowed, away_from, min_distance)])

    def lattice_component(self, index: int) -> int:
        """The component of lattice start ``index`` (0 without components)."""
        return int(self.components[0][index]) if self.components is not None else 0

    def lattice_goals(self, component: int) -> np.ndarray | None:
        """The lattice goals in free-space ``component`` (None: all of them)."""
        return self.components[1] == component if self.components is not None else None

    @staticmethod
    def _draw(fine: CandidateSet, rng: np.random.Generator, allowed: np.ndarray | None, away_from: np.ndarray,
              min_distance: np.ndarray) -> int:
        far = (np.abs(fine.points[:, None] - away_from[None, :]) >= min_distance).all(1)
        pool = np.flatnonzero(far if allowed is None else far & allowed)
        if len(pool) == 0:
            raise PlacementError(f"needs 1 free position but only 0 are available among {len(fine.points)} fine points")
        return int(pool[rng.integers(len(pool))])


def fine_candidates(region: AnyRegion, lattice: CandidateSet, radius: float, occupied: BaseGeometry) -> CandidateSet:
    """The fine set of ``region`` for a robot of ``radius``: a dense lattice free of obstacles, ``lattice``'s points included.

    Points regions keep their points; a circle perimeter is sampled densely at one rotation.
    """
    if isinstance(region, PointsRegion):
        return CandidateSet(lattice.points.copy(), 0.0)
    if lattice.ring_center is not None:
        assert isinstance(region, CircleRegion)
        count = int(min(FINE_POINTS, max(64, math.ceil(2 * math.pi * region.radius / FINE_SPACING))))
        return CandidateSet(lattice.ring_center + region.radius * np.exp(2j * math.pi * np.arange(count) / count), 0.0)
    shape = region_polygon(region, "")
    clearance = radius + GAP + JITTER_REACH  # the lattice's clearance: its obstacle buffer is cached
    free = shape if occupied.is_empty else shape.difference(grown(occupied, clearance))
    spacing = FINE_SPACING
    if not free.is_empty:
        spacing = max(FINE_SPACING, math.sqrt(free.area / (FINE_POINTS * math.sqrt(3) / 2)))
    points = best_lattice(free, spacing) if not free.is_empty else np.zeros(0, dtype=complex)
    return CandidateSet(np.concatenate([lattice.points, points]), 0.0)


def team_fallback(robot: Robot, placement: Placement, world_box: ShapelyPolygon, occupied: BaseGeometry) -> Fallback:
    """One robot's :class:`Fallback` from its lattice sets (``placement``) and regions."""
    start = fine_candidates(robot.start, placement.robot_start, robot.radius, occupied)
    goal = fine_candidates(robot.goal, placement.robot_goal, robot.radius, occupied)
    components = None
    if placement.robot_start.ring_center is None and placement.robot_goal.ring_center is None:
        parts = free_components(world_box, occupied, robot.radius)
        if len(parts) > 1:
            components = (component_of(placement.robot_start.points, parts), component_of(placement.robot_goal.points, parts),
                          component_of(start.points, parts), component_of(goal.points, parts))
    distance = max(robot.min_start_goal_distance, robot.goal_radius + 0.01)  # never an episode that starts in its goal
    return Fallback(start, goal, distance, components)


def _goal_counts(starts: np.ndarray, margin: float, goals: np.ndarray, min_distance: float,
                 start_component: np.ndarray | None, goal_component: np.ndarray | None) -> np.ndarray:
    """(K_start,) int: for each start (anywhere within ``margin`` of these points), the fine goals at least ``min_distance`` away."""
    needed = min_distance + margin
    counts = np.zeros(len(starts), dtype=np.int64)
    for lo in range(0, len(starts), CHUNK):
        ok = np.abs(starts[lo : lo + CHUNK, None] - goals[None, :]) >= needed
        if start_component is not None and goal_component is not None:
            ok &= start_component[lo : lo + CHUNK, None] == goal_component[None, :]
        counts[lo : lo + CHUNK] = ok.sum(1)
    return counts


def _lattice_positions(lattice: CandidateSet, allowed: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Where a lattice draw can put a robot, and how far from those points (jitter or the ring's rotation)."""
    if lattice.ring_center is not None:
        return ring_samples(lattice)
    points = lattice.points if allowed is None else lattice.points[allowed]
    return points, math.sqrt(2) * lattice.jitter


def _blocked(target: np.ndarray, positions: list[tuple[np.ndarray, float]], clear: float) -> int:
    """The most ``target`` points one robot at any of ``positions`` (each within its margin) keeps a drawn robot from."""
    return max((max_blocked(target, points, clear + margin) for points, margin in positions
                if len(points) and len(target) and _box_gap(target, points) < clear + margin), default=0)


def _box_gap(a: np.ndarray, b: np.ndarray) -> float:
    """Distance between the bounding boxes of two point sets (0 when they overlap): far sets block nothing."""
    dx = max(a.real.min() - b.real.max(), b.real.min() - a.real.max(), 0.0)
    dy = max(a.imag.min() - b.imag.max(), b.imag.min() - a.imag.max(), 0.0)
    return math.hypot(dx, dy)


def check_team(scenario: Scenario, robots: list[Placement]) -> None:
    """Every robot after the first always finds a start and a goal in its fine sets, whatever the robots before it drew."""
    specs, paths = scenario.robot_specs, scenario.robot_paths
    starts: list[list[tuple[np.ndarray, float]]] = []
    goals: list[list[tuple[np.ndarray, float]]] = []
    for j, (spec, places) in enumerate(zip(specs, robots, strict=True)):
        allowed: np.ndarray = np.asarray(places.start_goal_ok.any(1), dtype=bool)
        lattice_starts = _lattice_positions(places.robot_start, allowed)
        starts.append([lattice_starts])
        goals.append([_lattice_positions(places.robot_goal)])
        fallback = places.fallback
        if j == 0 or fallback is None:
            continue
        radii = [specs[i].radius + spec.radius + GAP for i in range(j)]  # the fine draw's clearances (its points have no jitter)
        blocked = [_blocked(fallback.start.points, starts[i], radii[i]) for i in range(j)]
        room = fallback.start.points
        if any(blocked):  # (nothing blocked: its lattice always has room, as for one robot)
            room = room[fallback.start_ok]
            blocked = [_blocked(room, starts[i], radii[i]) for i in range(j)]
            if len(room) - sum(blocked) < 1:
                raise GeometryError(f"{paths[j]}.start", _no_room(paths, j, blocked, "start", spec, len(room)))
        starts[j].append((room, 0.0))
        blocked = [_blocked(fallback.goal.points, goals[i], radii[i]) for i in range(j)]
        goals[j].append((fallback.goal.points, 0.0))
        if not any(blocked):
            continue
        # its goal: the fewest goals any start leaves, less what the goals drawn before can block
        components = fallback.components
        lattice_component = components[0][allowed] if components is not None else None
        if places.robot_start.ring_center is not None:
            lattice_component = None
        fine_start_component = components[2][fallback.start_ok] if components is not None else None
        room = fallback.start.points[fallback.start_ok]
        goal_component = components[3] if components is not None else None
        fewest = min(
            int(_goal_counts(lattice_starts[0], lattice_starts[1], fallback.goal.points, fallback.goal_distance,
                             lattice_component, goal_component).min(initial=len(fallback.goal.points))),
            int(_goal_counts(room, 0.0, fallback.goal.points, fallback.goal_distance, fine_start_component,
                             goal_component).min(initial=len(fallback.goal.points))),
        )
        if fewest - sum(blocked) < 1:
            raise GeometryError(f"{paths[j]}.goal", _no_room(paths, j, blocked, "goal", spec, fewest))


def _no_room(paths: list[str], j: int, blocked: list[int], kind: str, spec: Robot, room: int) -> str:
    crowding = [f"{paths[i]}.{kind}" for i, count in enumerate(blocked) if count > 0]
    named = ", ".join(crowding[:-1]) + f" and {crowding[-1]}" if len(crowding) > 1 else (crowding[0] if crowding else "")
    where = f"the robots drawn before it ({named})"
    extra = " at least min_start_goal_distance from its start" if kind == "goal" else ""
    return (f"no {kind} is sure to be left for this robot (radius {spec.radius:g} m){extra}: {where} can leave none of its {room} "
            f"{kind} position{'' if room == 1 else 's'} free; expected {kind} regions with room for every robot (larger or separate "
            "regions, fewer or smaller robots)")

