"""Collision-free placement of starts and goals without rejection sampling.

At load time each region becomes a set of candidate positions: a hexagonal lattice whose
points are free of static obstacles and far enough apart that two agents placed on
different points (with their random jitter) can never overlap. A reset then only draws
distinct lattice points, so it costs the same at any density, and a region that cannot
hold the requested crowd is reported when the scenario loads instead of looping forever.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely
from shapely.geometry import Point, box
from shapely.geometry import Polygon as ShapelyPolygon

from crowdnav.errors import CrowdNavError
from crowdnav.obstacles import GeometryError, StaticObstacles
from crowdnav.scenario.schema import CircleRegion, PointsRegion, PolygonRegion, RectangleRegion, Scenario

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
        min_distance: float = 0.0,
        replace: bool = False,
    ) -> np.ndarray:
        """``n`` positions from distinct candidates (unless ``replace``).

        ``allowed`` masks candidates; ``away_from`` (complex array) excludes candidates closer
        than ``min_distance`` to any of its points (e.g. agents already placed).
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
        out = points[rng.choice(pool, size=n, replace=replace)]
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
    """Walking groups: member start positions; standing groups: centres of the circle."""
    goal: CandidateSet | None
    """Goal candidates; None for the mirror rule, standing groups and empty groups."""
    circle_radius: float = 0.0
    """Radius (m) of a standing group's circle of member centres (0 for walking groups)."""


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


def build_placement(scenario: Scenario, obstacles: StaticObstacles) -> Placement:
    humans, world = scenario.humans, scenario.world
    world_box = box(world.min[0], world.min[1], world.max[0], world.max[1])
    occupied = obstacles.union
    robots = [_robot_placement(robot, path, world_box, occupied)
              for robot, path in zip(scenario.robot_specs, scenario.robot_paths, strict=True)]
    groups = [_group_placement(scenario, path, group, world_box, occupied) for path, group in humans.crowd]
    first = robots[0]
    _check_capacity(scenario, first.robot_start, first.robot_goal, groups, robots[1:])
    first.groups, first.other_robots = groups, robots[1:]
    return first


def _robot_placement(robot: Any, path: str, world_box: Any, occupied: Any) -> Placement:
    """One robot's candidate sets (``groups`` left empty), its errors named at ``path`` (``robot`` or ``robots.<i>``)."""
    robot_start = _candidates(robot.start, f"{path}.start", robot.radius, world_box, occupied)
    robot_goal = _candidates(robot.goal, f"{path}.goal", robot.radius, world_box, occupied)
    slack = 2 * JITTER_REACH
    start_goal_ok, largest = _far_pairs(robot_start.points, robot_goal.points, robot.min_start_goal_distance + slack)
    if robot_start.ring_center is not None or robot_goal.ring_center is not None:
        start_goal_ok = np.ones_like(start_goal_ok)  # rotated rings: any start, checked for every rotation below
        _check_ring_start_goal(robot_start, robot_goal, robot.min_start_goal_distance, path)
    if not start_goal_ok.any():
        if largest < 1e-9:
            message = f"{path}.start and {path}.goal only offer the same position; expected a goal away from the start"
        else:
            message = (
                f"no start in {path}.start is {robot.min_start_goal_distance:g} m from a goal in {path}.goal "
                f"(largest distance available: {largest:.2f} m); expected a smaller distance or regions further apart"
            )
        raise GeometryError(f"{path}.min_start_goal_distance", message)
    start_component = goal_component = None
    if robot_start.ring_center is None and robot_goal.ring_center is None:
        # only pairs the robot's disc can travel between: walls and furniture may close the way
        components = _free_components(world_box, occupied, robot.radius)
        start_component, goal_component = _component_of(robot_start.points, components), _component_of(robot_goal.points, components)
        same = start_component[:, None] == goal_component[None, :]
        if start_goal_ok.any() and not (start_goal_ok & same).any():
            raise GeometryError(f"{path}.goal", f"no goal in {path}.goal can be reached from a start in {path}.start: walls or furniture "
                                f"close the way for a robot of radius {robot.radius:g} m; expected start and goal regions in one "
                                "connected free space")
        start_goal_ok &= same
        beyond_goal, _ = _far_pairs(robot_start.points, robot_goal.points, robot.goal_radius + slack)
        if (start_goal_ok & ~beyond_goal).any():  # an episode could start inside its goal
            raise GeometryError(
                f"{path}.goal_radius",
                f"a start in {path}.start can lie within the goal radius ({robot.goal_radius:g} m) of a goal in {path}.goal, so an "
                f"episode could end as a success before the robot moves; expected {path}.min_start_goal_distance above the goal "
                "radius, or a smaller goal radius",
            )
    split = start_component is not None and len(set(start_component.tolist()) | set(goal_component.tolist())) > 1
    components_kept = (start_component, goal_component) if split else (None, None)
    return Placement(robot_start, robot_goal, [], start_goal_ok, *components_kept)


def _group_placement(scenario: Scenario, path: str, group, world_box, occupied) -> GroupPlacement:
    """Candidate sets of one group: member spawns and goals (walking) or circle centres (standing)."""
    humans, slack = scenario.humans, 2 * JITTER_REACH
    empty = CandidateSet(np.zeros(0, dtype=complex), 0.0)
    if group.max_count == 0:
        return GroupPlacement(path, empty, None)
    if group.standing:
        ring = group.circle_radius_for(humans.radius)
        # the circle is one disc of radius ring + radius for obstacles; its members stay in the world too
        sets = [_candidates(r, f"{path}.spawn.{i}", ring + humans.radius, world_box, occupied) for i, r in enumerate(group.spawn)]
        centres = _merge(sets, spacing=0.0)
        inside = shapely.contains_xy(world_box.buffer(-ring - JITTER_REACH), centres.points.real, centres.points.imag)
        if not inside.any():
            raise GeometryError(f"{path}.spawn", f"no centre leaves the standing circle (radius {ring:.2f} m) inside the world; "
                                "expected a region further from the world's edge")
        return GroupPlacement(path, CandidateSet(centres.points[inside], centres.jitter, centres.ring_center), None, ring)
    spawn_sets = [_candidates(r, f"{path}.spawn.{i}", humans.radius, world_box, occupied) for i, r in enumerate(group.spawn)]
    spawn = _merge(spawn_sets, spacing=2 * humans.radius + GAP + slack)
    goal = None
    if group.goal_rule == "mirror":
        center = complex(*(group.mirror_center or scenario.world_center))
        clearance = humans.radius + GAP + slack / 2
        if spawn.ring_center is not None and not _ring_mirror_free(spawn, center, clearance, world_box, occupied):
            # some rotations of the ring would mirror onto goals outside the floor or in an obstacle:
            # the ring stays still, so that the mirrored points dropped below stay dropped
            spawn = CandidateSet(spawn.points, spawn.jitter)
        mirrored = 2 * center - spawn.points
        free = _free(mirrored, clearance, occupied) & _inside_floor(mirrored, world_box, spawn.jitter)
        if not free.any():
            where = f"{path}.mirror_center" if group.mirror_center is not None else f"{path}.goal_rule"
            raise GeometryError(
                where,
                f"mirroring the spawn points through ({center.real:g}, {center.imag:g}) puts every goal outside the world or in an "
                "obstacle; expected a mirror centre between the spawn regions and free space",
            )
        spawn = CandidateSet(spawn.points[free], spawn.jitter, spawn.ring_center)
    else:
        goal_sets = [_candidates(r, f"{path}.goal.{i}", humans.radius, world_box, occupied) for i, r in enumerate(group.goal)]
        goal = _merge(goal_sets, spacing=0.0)
        _check_human_reachability(path, humans.radius, world_box, occupied, spawn_sets, goal_sets)
    return GroupPlacement(path, spawn, goal)


def _check_capacity(scenario: Scenario, robot_start: CandidateSet, robot_goal: CandidateSet, groups: list[GroupPlacement],
                    other_robots: list[Placement] | None = None) -> None:
    """Every group finds room at reset whatever the robots' starts and the groups placed before it.

    ``other_robots``: the sets of the robots after the first (``robots:``); each blocks as the first does.

    Groups are placed in file order. Each agent placed earlier blocks at most ``_max_blocked``
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
            capacity -= _blocked(placement.spawn, sets.robot_start, reach)
            if group.standing:
                capacity -= _blocked(placement.spawn, sets.robot_goal, reach)
        for earlier, other in zip(groups[:k], crowd[:k], strict=False):
            if other.max_count == 0:
                continue
            reach = ring + earlier.circle_radius + 2 * humans.radius + GAP + slack
            capacity -= (1 if other.standing else other.max_count) * _blocked(placement.spawn, earlier.spawn, reach)
        needed = 1 if group.standing else group.max_count
        if capacity < needed:
            path = placement.path
            if group.standing:
                raise GeometryError(f"{path}.spawn", "no room is sure to be left for the standing circle next to the robot and the "
                                    "groups listed before it; expected larger spawn regions or the group listed earlier")
            field = f"{path}.count"
            raise GeometryError(
                field,
                f"the spawn regions hold at most {max(capacity, 0)} human{'' if capacity == 1 else 's'} of radius {humans.radius:g} m "
                f"next to the robot{'s' if other_robots else ''}{' and the groups listed before' if k else ''} "
                f"(asked for up to {group.max_count}); expected a smaller count, a smaller radius or larger spawn regions",
            )


def _candidates(region, path: str, radius: float, world_box, occupied) -> CandidateSet:
    """Lattice of obstacle-free positions for an agent of ``radius`` inside ``region``."""
    spacing = 2 * radius + GAP + 2 * JITTER_REACH
    clearance = radius + GAP + JITTER_REACH
    if isinstance(region, PointsRegion):
        points = np.array([complex(x, y) for x, y in region.points])
        _require_inside(points, path, world_box)
        free = _free(points, radius, occupied)
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
    shape = _region_polygon(region, path)
    if not shape.within(world_box.buffer(1e-9)):
        raise GeometryError(path, _outside_message(world_box))
    free_area = shape if occupied.is_empty else shape.difference(_grown(occupied, clearance))
    if free_area.is_empty or free_area.area < 1e-9:
        raise GeometryError(path, "region is entirely covered by obstacles (with the agent's radius); expected some free space")
    points = _best_lattice(free_area, _bounded_spacing(free_area, spacing))
    if len(points) == 0:
        rep = free_area.representative_point()
        points = np.array([complex(rep.x, rep.y)])
        return CandidateSet(points, 0.0)
    return CandidateSet(points, JITTER)


_GROWN: list = [None, {}]  # [the world's obstacle union, {clearance: buffered union}]


def _grown(occupied, clearance: float):
    """``occupied.buffer(clearance)``, computed once per world and clearance (buffering thousands
    of obstacles is the slowest step of loading; a world's regions share one or two clearances)."""
    if _GROWN[0] is not occupied:
        _GROWN[0], _GROWN[1] = occupied, {}  # one world at a time: no stale geometry is kept alive
    grown = _GROWN[1]
    if clearance not in grown:
        grown[clearance] = occupied.buffer(clearance)
    return grown[clearance]


def _free_components(world_box, occupied, radius: float) -> list:
    """The connected parts of the free space for a disc of ``radius`` (its centre's reachable set)."""
    free = world_box if occupied.is_empty else world_box.difference(occupied.buffer(radius))
    parts = list(getattr(free, "geoms", [free]))
    for part in parts:
        shapely.prepare(part)
    return parts


def _component_of(points: np.ndarray, components: list) -> np.ndarray:
    """Index of the component holding each point (-1: none, e.g. a point on an obstacle's margin)."""
    index = np.full(len(points), -1)
    for k, part in enumerate(components):
        index[(index < 0) & shapely.intersects_xy(part, points.real, points.imag)] = k
    return index


def _check_human_reachability(path: str, radius: float, world_box, occupied, spawn_sets, goal_sets) -> None:
    """A group's spawn and goal regions must share one free space (its members take any of its goals)."""
    components = _free_components(world_box, occupied, radius)
    if len(components) < 2:
        return
    sets = [(f"{path}.spawn.{i}", s) for i, s in enumerate(spawn_sets)] + [(f"{path}.goal.{i}", s) for i, s in enumerate(goal_sets)]
    reached = [set(_component_of(s.points, components).tolist()) - {-1} for _, s in sets]
    common = set.intersection(*reached) if reached else set()
    if not common:
        path = next(path for (path, _), parts in zip(sets, reached, strict=True) if parts != reached[0]) if len(sets) > 1 else sets[0][0]
        raise GeometryError(path, f"region is walled off from the group's other regions for a human of radius {radius:g} m "
                            "(members take any goal); expected every spawn and goal region in one connected free space")


def _region_polygon(region, path: str) -> ShapelyPolygon:
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


_CHUNK = 512  # rows per block of the pairwise distance tables built at load time

MAX_CANDIDATES = 4_000
"""Lattice points per region at most: a larger region gets a proportionally coarser lattice.

Every library region holds fewer than 200 points, so this only bounds the cost of huge worlds
(start x goal pairs, pairwise merges and draws are all quadratic in it): a 100 m world covered
by regions loads in about a second instead of needing 10 GB."""


def _bounded_spacing(area, spacing: float) -> float:
    """``spacing``, widened so the lattice over ``area`` (and over its bounding box, which the
    lattice scan allocates) stays within :data:`MAX_CANDIDATES` (resp. 25 times that) points."""
    minx, miny, maxx, maxy = area.bounds
    cell = spacing * spacing * math.sqrt(3) / 2  # area per hexagonal lattice point
    points, scanned = area.area / cell, (maxx - minx + spacing) * (maxy - miny + spacing) / cell
    factor = max(1.0, points / MAX_CANDIDATES, scanned / (25 * MAX_CANDIDATES))
    return spacing * math.sqrt(factor)


def _best_lattice(area, spacing: float) -> np.ndarray:
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


def _merge(sets: list[CandidateSet], spacing: float) -> CandidateSet:
    """Union of candidate sets; drop points closer than ``spacing`` to an earlier one (overlapping regions)."""
    points = np.concatenate([s.points for s in sets])
    ring = next((s.ring_center for s in sets if s.ring_center is not None), None)
    jitter = min(s.jitter for s in sets)
    if spacing > 0 and len(points) > 1:
        dropped = np.zeros(len(points), dtype=bool)  # close to an earlier point
        later = np.arange(len(points))
        for lo in range(0, len(points), _CHUNK):  # row blocks: memory stays at _CHUNK x K
            rows = slice(lo, lo + _CHUNK)
            close = np.abs(points[rows, None] - points[None, :]) < spacing - 1e-9
            dropped |= (close & (later[None, :] > later[rows, None])).any(0)
        points = points[~dropped]
    return CandidateSet(points, jitter, ring if len(sets) == 1 else None)


def _free(points: np.ndarray, clearance: float, occupied) -> np.ndarray:
    if occupied.is_empty:
        return np.ones(len(points), dtype=bool)
    return shapely.distance(occupied, shapely.points(points.real, points.imag)) >= clearance


def _require_inside(points: np.ndarray, path: str, world_box) -> None:
    inside = shapely.contains_xy(world_box, points.real, points.imag)
    if not inside.all():
        raise GeometryError(path, _outside_message(world_box))


def _outside_message(world_box) -> str:
    minx, miny, maxx, maxy = world_box.bounds
    return f"region extends outside the world; expected it inside x in [{minx:g}, {maxx:g}], y in [{miny:g}, {maxy:g}]"


_RING_STEP = 0.02
"""Arc length (m) between the samples that stand for every rotation of a ring (a circle perimeter) in load-time checks."""


def _ring_samples(candidates: CandidateSet) -> tuple[np.ndarray, float]:
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
    positions, margin = _ring_samples(blockers)
    # a rotating spawn ring meets a disc in one arc, which holds at most one candidate more than at any fixed rotation
    extra = 1 if spawn.ring_center is not None and len(spawn.points) else 0
    return _max_blocked(spawn.points, positions, reach + margin) + extra


def _check_ring_start_goal(start: CandidateSet, goal: CandidateSet, min_distance: float, path: str = "robot") -> None:
    """Every start a rotating ring can give has a goal at least ``min_distance`` away (as the draw asks), for every rotation."""
    starts, margin = _ring_samples(start)
    needed = min_distance + JITTER_REACH + math.sqrt(2) * start.jitter + margin  # the draw's margin, and the start's own jitter
    if goal.ring_center is not None:
        # the farthest of K evenly spaced ring points is within pi/K of the opposite direction
        radius = float(np.abs(goal.points[0] - goal.ring_center))
        rho = np.abs(starts - goal.ring_center)
        farthest = np.sqrt(np.maximum(rho**2 + radius**2 + 2 * rho * radius * math.cos(math.pi / len(goal.points)), 0.0))
    else:
        farthest = np.array([float(np.abs(starts[lo : lo + _CHUNK, None] - goal.points[None, :]).max(1).min())
                             for lo in range(0, len(starts), _CHUNK)])
    worst = float(farthest.min())
    if worst < needed:
        raise GeometryError(f"{path}.min_start_goal_distance", (
            f"a start drawn from {path}.start can be only {worst:.2f} m from the farthest goal in {path}.goal (a circle perimeter "
            f"turns to any angle); expected {path}.min_start_goal_distance at most {max(worst - needed + min_distance, 0):.2f} m, "
            "or regions further apart"))


def _ring_mirror_free(ring: CandidateSet, center: complex, clearance: float, world_box, occupied) -> bool:
    """Whether every rotation of ``ring`` mirrors through ``center`` onto free floor (then it may keep rotating)."""
    samples, margin = _ring_samples(ring)
    mirrored = 2 * center - samples
    return bool((_free(mirrored, clearance + margin, occupied) & _inside_floor(mirrored, world_box, margin)).all())


def _inside_floor(points: np.ndarray, world_box, margin: float) -> np.ndarray:
    """Points at least ``margin`` inside the world's box (a goal jittered by up to ``margin`` stays inside)."""
    inner = world_box.buffer(-margin, join_style="mitre") if margin > 0 else world_box
    return shapely.contains_xy(inner, points.real, points.imag)


def _max_blocked(spawn: np.ndarray, starts: np.ndarray, reach: float) -> int:
    """The most ``spawn`` candidates one agent on any of ``starts`` (with jitter in ``reach``) can block."""
    if len(spawn) == 0 or len(starts) == 0:
        return 0
    return max(int((np.abs(starts[lo : lo + _CHUNK, None] - spawn[None, :]) < reach).sum(1).max()) for lo in range(0, len(starts), _CHUNK))


def _far_pairs(starts: np.ndarray, goals: np.ndarray, threshold: float) -> tuple[np.ndarray, float]:
    """(K_start, K_goal) bool of pairs at least ``threshold`` apart, and the largest distance, in row blocks."""
    ok = np.empty((len(starts), len(goals)), dtype=bool)
    largest = 0.0
    for lo in range(0, len(starts), _CHUNK):
        distance = np.abs(starts[lo : lo + _CHUNK, None] - goals[None, :])
        ok[lo : lo + _CHUNK] = distance >= threshold
        largest = max(largest, float(distance.max()))
    return ok, largest
