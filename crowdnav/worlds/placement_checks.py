"""Load-time checks of a scenario's candidate sets: room for every group, reachable goals, rotating rings.

Each check proves something for every reset at load time (so a reset never loops or fails
later): :func:`check_capacity` bounds what the robots and earlier groups can block of each
group's spawn points; :func:`check_ring_start_goal` covers every rotation of a circle perimeter;
:func:`free_components` and :func:`component_of` tell which candidates share one free space.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import Polygon as ShapelyPolygon
from shapely.geometry.base import BaseGeometry

from crowdnav.scenario.schema import Scenario
from crowdnav.worlds.obstacles import GeometryError
from crowdnav.worlds.placement_regions import CHUNK, GAP, JITTER_REACH, CandidateSet, GroupPlacement, Placement, clear_of


def check_capacity(scenario: Scenario, robot_start: CandidateSet, robot_goal: CandidateSet, groups: list[GroupPlacement],
                    other_robots: list[Placement] | None = None) -> None:
    """Every group finds room at reset whatever the robots' starts and the groups placed before it.

    ``other_robots``: the sets of the robots after the first (``robots:``); each blocks as the first does,
    from its lattice or its fine set (:mod:`crowdnav.worlds.placement_team`).

    Groups are placed in file order. Each agent placed earlier blocks at most ``max_blocked``
    of a group's candidates, so subtracting the worst case of all of them is a sufficient bound
    (for one group it is the robot start's block only).
    """
    robot, humans, slack = scenario.robot, scenario.humans, 2 * JITTER_REACH
    crowd = [group for _, group in humans.crowd]
    for k, (placement, group) in enumerate(zip(groups, crowd, strict=True)):
        if group.max_count == 0:
            continue
        points, ring = placement.spawn.points, placement.circle_radius
        capacity = len(points) - _blocked(placement.spawn, robot_start, robot.radius + ring + humans.radius + GAP + slack)
        if group.standing:
            capacity -= _blocked(placement.spawn, robot_goal, robot.radius + ring + humans.radius + GAP + slack)
        for spec, sets in zip(scenario.robot_specs[1:], other_robots or [], strict=True):
            reach = spec.radius + ring + humans.radius + GAP + slack
            capacity -= _blocked_by_robot(placement.spawn, sets.robot_start, sets.fallback.start if sets.fallback else None, reach)
            if group.standing:
                capacity -= _blocked_by_robot(placement.spawn, sets.robot_goal, sets.fallback.goal if sets.fallback else None, reach)
        for earlier, other in zip(groups[:k], crowd[:k], strict=False):
            if other.max_count == 0:
                continue
            reach = ring + earlier.circle_radius + 2 * humans.radius + GAP + slack
            capacity -= (1 if other.on_circle else other.max_count) * _blocked(placement.spawn, earlier.spawn, reach)
        needed = 1 if group.on_circle else group.max_count
        if capacity < needed:
            path = placement.path
            if group.on_circle:
                what = "standing circle" if group.standing else "walking group's starting circle"
                raise GeometryError(f"{path}.spawn", f"no room is sure to be left for the {what} next to the robot and the "
                                    "groups listed before it; expected larger spawn regions or the group listed earlier")
            field = f"{path}.count"
            raise GeometryError(
                field,
                f"the spawn regions hold at most {max(capacity, 0)} human{'' if capacity == 1 else 's'} of radius {humans.radius:g} m "
                f"next to the robot{'s' if other_robots else ''}{' and the groups listed before' if k else ''} "
                f"(asked for up to {group.max_count}); expected a smaller count, a smaller radius or larger spawn regions",
            )


def free_components(world_box: ShapelyPolygon, occupied: BaseGeometry, radius: float) -> list[BaseGeometry]:
    """The connected parts of the free space for a disc of ``radius`` (its centre's reachable set)."""
    free = world_box if occupied.is_empty else world_box.difference(occupied.buffer(radius))
    parts = list(getattr(free, "geoms", [free]))
    for part in parts:
        shapely.prepare(part)
    return parts


def component_of(points: np.ndarray, components: list[BaseGeometry]) -> np.ndarray:
    """Index of the component holding each point (-1: none, e.g. a point on an obstacle's margin)."""
    index = np.full(len(points), -1)
    for k, part in enumerate(components):
        index[(index < 0) & shapely.intersects_xy(part, points.real, points.imag)] = k
    return index


def check_human_reachability(path: str, radius: float, world_box: ShapelyPolygon, occupied: BaseGeometry,
                             spawn_sets: list[CandidateSet], goal_sets: list[CandidateSet]) -> None:
    """A group's spawn and goal regions must share one free space (its members take any of its goals)."""
    components = free_components(world_box, occupied, radius)
    if len(components) < 2:
        return
    sets = [(f"{path}.spawn.{i}", s) for i, s in enumerate(spawn_sets)] + [(f"{path}.goal.{i}", s) for i, s in enumerate(goal_sets)]
    reached = [set(component_of(s.points, components).tolist()) - {-1} for _, s in sets]
    common = set.intersection(*reached) if reached else set()
    if not common:
        path = next(path for (path, _), parts in zip(sets, reached, strict=True) if parts != reached[0]) if len(sets) > 1 else sets[0][0]
        raise GeometryError(path, f"region is walled off from the group's other regions for a human of radius {radius:g} m "
                            "(members take any goal); expected every spawn and goal region in one connected free space")


_RING_STEP = 0.02
"""Arc length (m) between the samples that stand for every rotation of a ring (a circle perimeter) in load-time checks."""


def ring_samples(candidates: CandidateSet) -> tuple[np.ndarray, float]:
    """Positions a draw from ``candidates`` can give, and how far a real one can be from the nearest of them.

    A ring rotates by any angle at each draw, so it is sampled densely (at most 20,000 samples);
    lattice points are themselves (their jitter is the callers' to add, as their reaches do).
    """
    if candidates.ring_center is None or len(candidates.points) == 0:
        return candidates.points, 0.0
    center = candidates.ring_center
    radius = float(np.abs(candidates.points[0] - center))
    count = int(min(20_000, max(64, math.ceil(2 * math.pi * radius / _RING_STEP))))
    samples = center + radius * np.exp(2j * math.pi * np.arange(count) / count)
    return samples, radius * math.pi / count


def _blocked(spawn: CandidateSet, blockers: CandidateSet, reach: float) -> int:
    """The most ``spawn`` candidates one agent drawn from ``blockers`` can block, whatever the rings' rotations."""
    positions, margin = ring_samples(blockers)
    # a rotating spawn ring meets a disc in one arc, which holds at most one candidate more than at any fixed rotation
    extra = 1 if spawn.ring_center is not None and len(spawn.points) else 0
    return max_blocked(spawn.points, positions, reach + margin) + extra


def _blocked_by_robot(spawn: CandidateSet, lattice: CandidateSet, fine: CandidateSet | None, reach: float) -> int:
    """:func:`_blocked` for a robot drawn from its ``lattice`` or, when that is blocked, from its ``fine`` set (crowdnav.worlds.placement_team)."""
    return max(_blocked(spawn, lattice, reach), _blocked(spawn, fine, reach) if fine is not None else 0)


def check_ring_start_goal(start: CandidateSet, goal: CandidateSet, min_distance: float, path: str = "robot") -> None:
    """Every start a rotating ring can give has a goal at least ``min_distance`` away (as the draw asks), for every rotation."""
    starts, margin = ring_samples(start)
    needed = min_distance + JITTER_REACH + math.sqrt(2) * start.jitter + margin  # the draw's margin, and the start's own jitter
    if goal.ring_center is not None:
        # the farthest of K evenly spaced ring points is within pi/K of the opposite direction
        radius = float(np.abs(goal.points[0] - goal.ring_center))
        rho = np.abs(starts - goal.ring_center)
        farthest = np.sqrt(np.maximum(rho**2 + radius**2 + 2 * rho * radius * math.cos(math.pi / len(goal.points)), 0.0))
    else:
        farthest = np.array([float(np.abs(starts[lo : lo + CHUNK, None] - goal.points[None, :]).max(1).min())
                             for lo in range(0, len(starts), CHUNK)])
    worst = float(farthest.min())
    if worst < needed:
        raise GeometryError(f"{path}.min_start_goal_distance", (
            f"a start drawn from {path}.start can be only {worst:.2f} m from the farthest goal in {path}.goal (a circle perimeter "
            f"turns to any angle); expected {path}.min_start_goal_distance at most {max(worst - needed + min_distance, 0):.2f} m, "
            "or regions further apart"))


def ring_mirror_free(ring: CandidateSet, center: complex, clearance: float, world_box: ShapelyPolygon, occupied: BaseGeometry) -> bool:
    """Whether every rotation of ``ring`` mirrors through ``center`` onto free floor (then it may keep rotating)."""
    samples, margin = ring_samples(ring)
    mirrored = 2 * center - samples
    return bool((clear_of(mirrored, clearance + margin, occupied) & inside_floor(mirrored, world_box, margin)).all())


def inside_floor(points: np.ndarray, world_box: ShapelyPolygon, margin: float) -> np.ndarray:
    """Points at least ``margin`` inside the world's box (a goal jittered by up to ``margin`` stays inside)."""
    inner = world_box.buffer(-margin, join_style="mitre") if margin > 0 else world_box
    inside: np.ndarray = shapely.contains_xy(inner, points.real, points.imag)
    return inside


def max_blocked(spawn: np.ndarray, starts: np.ndarray, reach: float) -> int:
    """The most ``spawn`` candidates one agent on any of ``starts`` (with jitter in ``reach``) can block."""
    if len(spawn) == 0 or len(starts) == 0:
        return 0
    return max(int((np.abs(starts[lo : lo + CHUNK, None] - spawn[None, :]) < reach).sum(1).max()) for lo in range(0, len(starts), CHUNK))


def far_pairs(starts: np.ndarray, goals: np.ndarray, threshold: float) -> tuple[np.ndarray, float]:
    """(K_start, K_goal) bool of pairs at least ``threshold`` apart, and the largest distance, in row blocks."""
    ok = np.empty((len(starts), len(goals)), dtype=bool)
    largest = 0.0
    for lo in range(0, len(starts), CHUNK):
        distance = np.abs(starts[lo : lo + CHUNK, None] - goals[None, :])
        ok[lo : lo + CHUNK] = distance >= threshold
        largest = max(largest, float(distance.max()))
    return ok, largest
