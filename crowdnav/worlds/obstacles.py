"""Static obstacles: shapely builds and checks the geometry once, numpy arrays serve the step loop.

Points are complex numbers ``x + 1j*y`` throughout the hot path: one complex array op replaces
two real ones, which matters when a step is a few dozen numpy calls.

Obstacles are polygons (walls, boundary walls, polygonal and rectangular furniture) stored as
edges padded to a common count per polygon, plus exact discs (round furniture).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TypeAlias

import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon, box
from shapely.geometry.base import BaseGeometry
from shapely.validation import explain_validity

from crowdnav.errors import CrowdNavError
from crowdnav.scenario.schema import CircleFurniture, RectangleFurniture, Scenario

Vertex: TypeAlias = tuple[float, float]
"""A point ``(x, y)`` of a scenario's outline, in metres."""

FAR = 1.0e6
"""Coordinate of padding edges: far enough never to be the nearest edge."""


class GeometryError(CrowdNavError, ValueError):
    """A geometric problem at a dotted scenario path (turned into a ScenarioError by :func:`crowdnav.worlds.compiled.load_world`)."""

    def __init__(self, path: str, message: str):
        self.path, self.message = path, message
        super().__init__(f"{path}: {message}")


@dataclass
class StaticObstacles:
    """All static geometry as arrays for vectorized distance and raycast queries."""

    polygons: list[Polygon]
    """Shapely polygons, for load-time queries, rendering and tests."""
    labels: list[str]
    """Per polygon: its scenario path (``walls.0``, ``furniture.2``, ``world.boundary``) and name if any."""
    edge_start: np.ndarray
    """(P, E) complex: start vertex of each edge; padding edges sit at FAR."""
    edge_vector: np.ndarray
    """(P, E) complex: end minus start."""
    disc_center: np.ndarray
    """(C,) complex: centres of round obstacles."""
    disc_radius: np.ndarray
    """(C,) float: radii of round obstacles."""
    disc_labels: list[str] = field(default_factory=list)
    """Per disc: its scenario path and name."""
    surface: EdgeSet | None = None
    """Polygons then discs (each disc one zero-length edge at its centre) for one nearest-point query."""
    surface_radius: np.ndarray | None = None
    """(P+C,) radius to subtract from the distance to ``surface``: 0 for polygons, the disc radius for discs."""

    @property
    def polygon_count(self) -> int:
        return len(self.polygons)

    @property
    def disc_count(self) -> int:
        return len(self.disc_radius)

    @property
    def union(self) -> BaseGeometry:
        """All static obstacles as one shapely geometry (load-time use only)."""
        shapes = list(self.polygons) + [Point(c.real, c.imag).buffer(r, 64) for c, r in zip(self.disc_center, self.disc_radius, strict=False)]
        return shapely.union_all(shapes) if shapes else shapely.Polygon()


@dataclass
class EdgeSet:
    """Edges of several shapes, padded to the same count per shape (rows), for vectorized queries."""

    start: np.ndarray
    """(S, E) complex edge start points (padding at FAR)."""
    vector: np.ndarray
    """(S, E) complex edge vectors (0 for padding)."""
    projector: np.ndarray
    """(S, E) complex conj(vector) / |vector|^2 (0 for padding and zero-length edges)."""


def nearest_on_edges(points: np.ndarray, edges: EdgeSet) -> tuple[np.ndarray, np.ndarray]:
    """Nearest point of every row of ``edges`` to every point: (offset, distance), each (M, S)."""
    rel = points[:, None, None] - edges.start  # (M, S, E)
    t = (rel * edges.projector).real
    np.maximum(t, 0.0, out=t)
    np.minimum(t, 1.0, out=t)
    offset = t * edges.vector - rel  # from the point to the nearest point of each edge
    dist = np.abs(offset)
    m, p, e = dist.shape
    flat = dist.reshape(m * p, e).argmin(1)
    flat += np.arange(0, m * p * e, e)
    return offset.ravel()[flat].reshape(m, p), dist.ravel()[flat].reshape(m, p)


OUTSIDE_LABEL = "world.outside"
"""Label of the solid parts of a polygon world's bounding box (drawn as outside, not as walls)."""


MAX_GEOMETRY_VERTICES = 5_000
"""Most vertices over the floor, the walls and the polygonal furniture together (library: under 100)."""
MAX_CLOSE_PAIRS = 10_000
"""Most pairs of those edges closer than :func:`_pair_reach` (library: under 300).

Loading buffers the obstacles by the agents' clearance and unions them; GEOS's cost grows with
the edges whose buffers meet (a fine zigzag floor, crossing walls), not with the vertex count, so
both are bounded before anything is built. Any accepted file then loads in about a second."""
MAX_EDGE_TABLE = 100_000
"""Most entries of the padded (obstacles x edges) table every distance query scans (library: under 200)."""


def check_complexity(scenario: Scenario) -> None:
    """Refuse geometry whose loading would cost more than its few vertices suggest; GeometryError names the field.

    Counts the input's own edges (wall centre lines, floor and furniture outlines: nothing is
    built yet), then pairs of edges from anywhere within reach of each other (a spatial index
    query in blocks that stops at the budget), so the check itself costs milliseconds.
    """
    chains = _input_chains(scenario)
    written = [chain for chain in chains if chain[0].endswith(".points")]  # rectangles and discs: 4 corners each
    vertices = sum(len(points) for _, points, _ in written)
    if vertices > MAX_GEOMETRY_VERTICES:
        per_field: dict[str, int] = {}
        for path, points, _ in written:
            field = "world.points" if path == "world.points" else path.split(".")[0]
            per_field[field] = per_field.get(field, 0) + len(points)
        field = max(per_field, key=per_field.__getitem__)
        raise GeometryError(field, f"the geometry has {vertices:,} vertices over the floor, walls and furniture ({per_field[field]:,} "
                            f"here); expected at most {MAX_GEOMETRY_VERTICES:,}: simplify the outlines")
    if not chains:
        return
    starts, ends, owner = [], [], []
    for k, (_, points, closed) in enumerate(chains):
        xy = np.asarray(points, dtype=float)
        if closed:
            xy = np.concatenate([xy, xy[:1]])
        starts.append(xy[:-1])
        ends.append(xy[1:])
        owner.append(np.full(len(xy) - 1, k))
    segments = shapely.linestrings(np.stack([np.concatenate(starts), np.concatenate(ends)], axis=1))
    owners = np.concatenate(owner)
    tree, reach = shapely.STRtree(segments), _pair_reach(scenario)
    pairs_of = np.zeros(len(chains), dtype=np.int64)
    for lo in range(0, len(segments), 256):  # blocks: stop as soon as the budget is spent
        left, right = tree.query(segments[lo : lo + 256], predicate="dwithin", distance=reach)
        later = right > left + lo
        np.add.at(pairs_of, owners[left[later] + lo], 1)
        if pairs_of.sum() > MAX_CLOSE_PAIRS:
            path = chains[int(pairs_of.argmax())][0]
            raise GeometryError(path, f"more than {MAX_CLOSE_PAIRS:,} pairs of edges lie within {reach:.2f} m of each other (a fine "
                                "zigzag, crossing walls or dense outlines), which loading must resolve; expected coarser or fewer "
                                "outlines: simplify the most detailed ones, starting here")


def check_edge_table(polygons: list[Polygon], labels: list[str]) -> None:
    """The padded (obstacles x edges) table stays within :data:`MAX_EDGE_TABLE` (one polygon with many edges pads all others)."""
    edges = [sum(len(ring.coords) - 1 for ring in (poly.exterior, *poly.interiors)) for poly in polygons]
    if edges and len(edges) * max(edges) > MAX_EDGE_TABLE:
        widest = int(np.argmax(edges))
        label = labels[widest].split(" (")[0]
        path = "world.points" if label == OUTSIDE_LABEL else f"{label}.points" if label.startswith(("walls", "furniture")) else label
        raise GeometryError(path, f"{len(edges):,} obstacles padded to this one's {edges[widest]:,} edges make a table of "
                            f"{len(edges) * max(edges):,} edges that every distance query scans; expected at most {MAX_EDGE_TABLE:,}: "
                            "fewer vertices here or fewer obstacles")


def _input_chains(scenario: Scenario) -> list[tuple[str, list[Vertex], bool]]:
    """(field path, vertices, closed) of every outline the obstacles are built from (discs: their bounding square)."""
    chains: list[tuple[str, list[Vertex], bool]] = []
    if scenario.world.points is not None:
        chains.append(("world.points", list(scenario.world.points), True))
    chains.extend((f"walls.{i}.points", list(wall.points), False) for i, wall in enumerate(scenario.walls))
    for i, item in enumerate(scenario.furniture):
        if isinstance(item, CircleFurniture):  # its bounding square: overlapping discs make the union work too
            (x, y), r = item.center, item.radius
            chains.append((f"furniture.{i}.center", [(x - r, y - r), (x + r, y - r), (x + r, y + r), (x - r, y + r)], True))
        elif isinstance(item, RectangleFurniture):
            chains.append((f"furniture.{i}.center", list(_rotated_rectangle(item.center, item.size, item.angle).exterior.coords)[:4], True))
        else:
            chains.append((f"furniture.{i}.points", list(item.points), True))
    return chains


def _pair_reach(scenario: Scenario) -> float:
    """Edges closer than this have buffers that meet: twice the largest agent clearance, plus the thickest wall."""
    radius = max(scenario.robot.radius, scenario.humans.radius)
    thickness = max((wall.thickness for wall in scenario.walls), default=0.0)
    return 2 * (radius + 0.05 + math.sqrt(2) * 0.05) + thickness  # placement's GAP and jitter


def build_obstacles(scenario: Scenario) -> StaticObstacles:
    check_complexity(scenario)
    polygons: list[Polygon] = []
    labels: list[str] = []
    discs: list[tuple[complex, float, str]] = []
    world = scenario.world
    world_box = box(world.min[0], world.min[1], world.max[0], world.max[1])
    if world.boundary_walls:
        t = world.boundary_thickness
        (x0, y0), (x1, y1) = world.min, world.max
        # Boundary walls lie outside the bounds so the whole declared world stays usable.
        for rect in (box(x0 - t, y0 - t, x1 + t, y0), box(x0 - t, y1, x1 + t, y1 + t), box(x0 - t, y0, x0, y1), box(x1, y0, x1 + t, y1)):
            polygons.append(rect)
            labels.append("world.boundary")
    if world.points is not None:  # the floor polygon: the rest of the world's box is solid, like a wall
        floor = Polygon(world.points)
        if not floor.is_valid or floor.area <= 0:
            raise GeometryError("world.points", f"polygon is not valid ({explain_validity(floor)}); expected a simple polygon with non-zero area")
        if not floor.within(world_box.buffer(1e-9)):
            raise GeometryError("world.points", "the floor polygon extends outside [world.min, world.max]; expected it inside")
        for part in _polygon_parts(world_box.difference(floor)):
            polygons.append(part)
            labels.append(OUTSIDE_LABEL)
    for i, wall in enumerate(scenario.walls):
        path = f"walls.{i}"
        line = LineString(wall.points)
        if line.length == 0:
            raise GeometryError(f"{path}.points", "expected a polyline of non-zero length")
        shape = line.buffer(wall.thickness / 2, cap_style="square", join_style="mitre")
        for part in _polygon_parts(shape):
            polygons.append(part)
            labels.append(_label(path, wall.name))
        _check_inside(shape, world_box, f"{path}.points", "wall", tolerance=wall.thickness)
    for i, item in enumerate(scenario.furniture):
        path = f"furniture.{i}"
        if isinstance(item, CircleFurniture):
            _check_inside(Point(item.center).buffer(item.radius), world_box, f"{path}.center", "furniture")
            discs.append((complex(*item.center), float(item.radius), _label(path, item.name)))
            continue
        if isinstance(item, RectangleFurniture):
            shape = _rotated_rectangle(item.center, item.size, item.angle)
        else:
            shape = Polygon(item.points)
            if not shape.is_valid or shape.area <= 0:
                reason = explain_validity(shape)
                raise GeometryError(f"{path}.points", f"polygon is not valid ({reason}); expected a simple polygon with non-zero area")
        _check_inside(shape, world_box, f"{path}.points" if not isinstance(item, RectangleFurniture) else f"{path}.center", "furniture")
        polygons.append(shape)
        labels.append(_label(path, item.name))
    check_edge_table(polygons, labels)
    return _as_arrays(polygons, labels, discs)


def _as_arrays(polygons: list[Polygon], labels: list[str], discs: list[tuple[complex, float, str]]) -> StaticObstacles:
    rings: list[list[tuple[complex, complex]]] = []
    for poly in polygons:
        edges: list[tuple[complex, complex]] = []
        for ring in [poly.exterior, *poly.interiors]:
            xy = np.asarray(ring.coords)
            z = xy[:, 0] + 1j * xy[:, 1]
            edges.extend(zip(z[:-1], z[1:], strict=False))
        rings.append(edges)
    max_edges = max((len(e) for e in rings), default=1)
    count = len(polygons)
    start = np.full((count, max_edges), FAR + 1j * FAR, dtype=complex)
    end = start.copy()
    for i, edges in enumerate(rings):
        start[i, : len(edges)] = [a for a, _ in edges]
        end[i, : len(edges)] = [b for _, b in edges]
    vector = end - start
    len2 = np.abs(vector) ** 2
    inv_len2 = np.divide(1.0, len2, out=np.zeros_like(len2), where=len2 > 1e-18)
    centers = np.array([c for c, _, _ in discs], dtype=complex)
    disc_start = np.full((len(discs), max_edges), FAR + 1j * FAR, dtype=complex)
    disc_start[:, 0] = centers
    surface = EdgeSet(
        start=np.concatenate([start, disc_start]),
        vector=np.concatenate([vector, np.zeros_like(disc_start)]),
        projector=np.concatenate([vector.conj() * inv_len2, np.zeros_like(disc_start)]),
    )
    return StaticObstacles(
        polygons=polygons,
        labels=labels,
        edge_start=start,
        edge_vector=vector,
        disc_center=centers,
        disc_radius=np.array([r for _, r, _ in discs], dtype=float),
        disc_labels=[label for _, _, label in discs],
        surface=surface,
        surface_radius=np.array([0.0] * count + [r for _, r, _ in discs]),
    )


def _rotated_rectangle(center: Vertex, size: tuple[float, float], angle_deg: float) -> Polygon:
    half_w, half_h = size[0] / 2, size[1] / 2
    corners = np.array([-half_w - 1j * half_h, half_w - 1j * half_h, half_w + 1j * half_h, -half_w + 1j * half_h])
    corners = corners * np.exp(1j * math.radians(angle_deg)) + complex(*center)
    return Polygon(np.column_stack([corners.real, corners.imag]))


def _polygon_parts(shape: BaseGeometry) -> list[Polygon]:
    return list(shape.geoms) if hasattr(shape, "geoms") else [shape]


def _check_inside(shape: BaseGeometry, world_box: Polygon, path: str, what: str, tolerance: float = 0.0) -> None:
    if not shape.within(world_box.buffer(tolerance + 1e-9, join_style="mitre")):
        minx, miny, maxx, maxy = world_box.bounds
        raise GeometryError(path, f"{what} extends outside the world; expected it inside x in [{minx:g}, {maxx:g}], y in [{miny:g}, {maxy:g}]")


def _label(path: str, name: str | None) -> str:
    return f"{path} ({name})" if name else path
