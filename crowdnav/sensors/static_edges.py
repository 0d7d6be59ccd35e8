"""Static polygon edges with a consistent orientation, built once per world for the sensors.

Every polygon is re-oriented (exterior rings counter-clockwise, holes clockwise) so that the
solid is on the left of every edge. Two sensors rely on that: the LIDAR skips edges whose
outer (right) side faces away from the robot, and the occupancy grid counts signed edge
crossings (a winding number) that are positive exactly inside the union of the polygons.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from shapely.geometry import Polygon
from shapely.geometry.polygon import orient


@dataclass(frozen=True)
class OrientedEdges:
    """All polygon edges as arrays; the solid lies on the left of each edge."""

    start: np.ndarray
    """(E,) complex: first vertex, world frame."""
    vector: np.ndarray
    """(E,) complex: second vertex minus first (never zero)."""
    owner: np.ndarray
    """(E,) int: index of the polygon (in ``StaticObstacles.polygons``) the edge belongs to."""

    @property
    def count(self) -> int:
        return len(self.start)


def oriented_edges(polygons: list[Polygon]) -> OrientedEdges:
    """Edges of ``polygons`` (shapely), exteriors counter-clockwise and holes clockwise."""
    starts, vectors, owners = [], [], []
    for index, polygon in enumerate(polygons):
        polygon = orient(polygon, sign=1.0)  # shapely >= 2.0; orient_polygons needs 2.1
        for ring in (polygon.exterior, *polygon.interiors):
            xy = np.asarray(ring.coords)
            z = xy[:, 0] + 1j * xy[:, 1]
            vector = np.diff(z)
            keep = np.abs(vector) > 0.0  # repeated vertices would make zero-length edges
            starts.append(z[:-1][keep])
            vectors.append(vector[keep])
            owners.append(np.full(int(keep.sum()), index))
    if not starts:
        empty = np.zeros(0, dtype=complex)
        return OrientedEdges(empty, empty.copy(), np.zeros(0, dtype=int))
    return OrientedEdges(np.concatenate(starts), np.concatenate(vectors), np.concatenate(owners))
