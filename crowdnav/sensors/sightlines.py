"""Which people the robot can see: exact lines of sight past walls, furniture and other people, for K worlds at once.

A person is sampled by :data:`SIGHT_OFFSETS`: rays from the robot's centre to three points across
the person's width as the robot sees it (its centre and a point either side). A ray is blocked when
it crosses a static polygon edge, a round piece of furniture or another person's disc before its
end; the fraction of a person's rays that are clear is how much of it is in sight. The tests are the
LIDAR's exact ones (:mod:`crowdnav.sensors.lidar`): segment against segment, segment against disc,
as signed cross products (no division by a determinant that may vanish). Surfaces are seen from
outside: polygon edges whose outer side faces away from the robot are skipped (the first surface a
ray meets always faces it) and a disc containing the robot's centre is transparent.

How it is fast: each blocker is paired only with the rays near the bearings it subtends from the
robot. The rays of all worlds are sorted by (world, bearing bin) (:data:`BINS` bins a turn, each ray
listed twice, a turn apart, so that an interval across the turn is one run), a table lookup finds the
run of rays in the bins of each blocker's bearing interval (a slack of ``BEARING_SLACK`` each side; the
exact test decides), and the work follows the (ray, blocker) pairs that can meet: a few per ray, not
rays x blockers. Edges that no line of sight inside the world can cross (the boundary walls' faces)
are dropped once (:func:`_may_block`). Every test reads one pair's numbers alone, so world k's answer
depends on world k alone, bit for bit, whatever the other worlds are.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from crowdnav.sensors.static_edges import oriented_edges

if TYPE_CHECKING:
    from crowdnav.worlds.compiled import CompiledWorld

SIGHT_OFFSETS = np.array([-0.6, 0.0, 0.6])
"""Where a person's rays end: across its width as seen from the robot, in radii from its centre."""
_ACROSS = 1j * SIGHT_OFFSETS
RAYS = len(SIGHT_OFFSETS)
BEARING_SLACK = 1e-9
"""Radians added to each side of a blocker's bearing interval, against rounding (the exact test decides)."""
TURN = 2.0 * math.pi
BINS = 64
"""Bearing bins per turn (5.6 degrees each): a blocker is paired with the rays of every bin its bearing interval touches."""
_SCALE = BINS / TURN
_SLACKS = np.array([[-BEARING_SLACK * _SCALE], [BEARING_SLACK * _SCALE]])
"""Added to the (low, high) bearings of a blocker, in bin units (``low + -s`` is ``low - s``, exactly)."""
_ONES = np.ones(RAYS, dtype=np.uint8)


class Sightlines:
    """Lines of sight in one compiled world: its static edges and round furniture, and the people given per call."""

    def __init__(self, world: CompiledWorld):
        edges = oriented_edges(world.obstacles.polygons)
        keep = _may_block(edges.start, edges.vector, world)
        self._edge_start, self._edge_vector = edges.start[keep], edges.vector[keep]
        self._edge_cross = (self._edge_start.conj() * self._edge_vector).imag  # cross(start, vector): from the origin
        self._disc_center = np.asarray(world.obstacles.disc_center, dtype=complex)
        self._disc_radius = np.asarray(world.obstacles.disc_radius, dtype=float)
        self._tables: dict[tuple[bytes, int], Tables] = {}

    def visible_fraction(self, robot: np.ndarray, toward: np.ndarray, distance: np.ndarray, radii: np.ndarray,
                         candidate: np.ndarray) -> np.ndarray:
        """(K, n) float: the fraction of each candidate person's rays that are clear (0 where not a candidate).

        ``robot``: (K,) complex robot centres; ``toward`` / ``distance``: (K, n) each person's centre from the
        robot (complex) and its length; ``radii``: (n,) their radii; ``candidate``: (K, n) bool, the people
        to test (the robot outside their disc). Every person blocks the others' rays, candidate or not.
        """
        k, n = toward.shape
        out = np.zeros((k, n))
        flat = np.flatnonzero(candidate)
        if not len(flat):
            return out
        world, person = np.divmod(flat, n)
        centre = toward.ravel()[flat][:, None]
        rays = (centre + (radii[person] / distance.ravel()[flat])[:, None] * (centre * _ACROSS)).ravel()
        count = len(rays)
        tables = self._tables_of(radii, k)
        scene = self._scene(robot, toward, distance, tables)
        # bearings in bin units from -pi, in one arctan2: the rays, then the blockers' points
        points = np.concatenate([rays, scene.points])
        bearing = (np.arctan2(points.imag, points.real) + math.pi) * _SCALE
        # each ray in its bearing bin and again a turn later, per world: 2 * BINS slots a world
        slot = bearing[:count].astype(np.intp)
        np.minimum(slot, BINS - 1, out=slot)
        slot += (world * (2 * BINS)).repeat(RAYS)
        slots = np.concatenate([slot, slot + BINS])
        if k * 2 * BINS <= 1 << 16:  # 16-bit keys: numpy's stable sort is then a radix sort (the same order, faster)
            slots = slots.astype(np.uint16)
        order = slots.argsort(kind="stable") % count
        starts = np.zeros(k * 2 * BINS + 1, dtype=np.intp)
        np.cumsum(np.bincount(slots, minlength=k * 2 * BINS), out=starts[1:])
        # the (ray, blocker) pairs: blocker b meets the sorted rays at positions [start, stop) (none if it cannot block)
        start, stop = starts[_blocker_slots(bearing[count:], scene, tables)]
        runs = stop - start
        ends = runs.cumsum()
        blocker = np.arange(len(runs)).repeat(runs)
        ray = order[np.arange(int(ends[-1])) + (start + runs - ends)[blocker]]
        edge_pairs = int(ends[scene.edges - 1]) if scene.edges else 0
        # Edge a + s v (s in [0, 1]), ray t z (t in (0, 1)): t = cross(a, v) / cross(z, v), s = cross(a, z) / cross(z, v).
        # With cross(a, v) < 0 (a facing edge) both hold exactly when cross(z, v) < cross(a, v) and cross(z, v) <= cross(a, z) <= 0.
        e, re = blocker[:edge_pairs], ray[:edge_pairs]
        z = rays[re]
        den = (z.conj() * tables.vector[e]).imag
        along = (scene.start[e].conj() * z).imag
        hit_edge = (den < scene.cross[e]) & (den <= along) & (along <= 0.0)
        # Disc: the segment [0, z] passes closer than r to the centre c: the nearest point is tau z, tau = clip(<z, c> / |z|^2, 0, 1).
        d, rd = blocker[edge_pairs:] - scene.edges, ray[edge_pairs:]
        # a ray never blocks on its own person's disc (disc world * discs + person): those pairs are dropped first
        other = np.flatnonzero(d != (world * len(tables.radius) + person).repeat(RAYS)[rd])
        d, rd = d[other], rd[other]
        z, c = rays[rd], scene.center[d]
        tau = ((z.conj() * c).real / (z.real * z.real + z.imag * z.imag)).clip(0.0, 1.0)
        gap = c - tau * z
        hit_disc = gap.real * gap.real + gap.imag * gap.imag < tables.radius2[d]
        blocked = np.zeros(count, dtype=bool)
        blocked[np.concatenate([re[hit_edge], rd[hit_disc]])] = True
        clear = RAYS - blocked.view(np.uint8).reshape(-1, RAYS) @ _ONES  # a matrix product: numpy's row sum is slow
        out.reshape(-1)[flat] = clear * (1.0 / RAYS)
        return out

    def _scene(self, robot: np.ndarray, toward: np.ndarray, distance: np.ndarray, tables: Tables) -> Scene:
        """Every world's every edge, then its every disc (people, then round furniture), relative to its robot.

        Dense (world-major, one row per blocker whether or not it can block): what cannot block (an edge facing away,
        a disc holding the robot's centre) is a blocker with no bins, cheaper than gathering the others."""
        n = toward.shape[1]
        cross = self._edge_cross - (robot.conj()[:, None] * self._edge_vector).imag  # cross(start - robot, vector): < 0 facing
        start = self._edge_start - robot[:, None]
        if len(self._disc_center):
            centers = np.concatenate([toward, self._disc_center - robot[:, None]], axis=1)
            distances = np.concatenate([distance, np.abs(centers[:, n:])], axis=1)
        else:
            centers, distances = toward, distance
        # an edge facing away, a disc holding the robot's centre (transparent)
        idle = np.concatenate([cross >= 0.0, distances <= tables.radius], axis=None)
        # Seen from outside, an edge runs clockwise: from its end to its start; a disc spans its centre's bearing +- arcsin(r / d)
        # <= r / d pi / 2 (r / d < 1; an idle disc: any finite span, it has no bins)
        half = tables.radius / np.maximum(distances, tables.radius) * (BINS / 4.0)
        points = np.concatenate([start + self._edge_vector, start, centers], axis=None)  # edge ends, edge starts, disc centres
        return Scene(edges=start.size, points=points, half=half.ravel(), idle=idle, start=start.ravel(), cross=cross.ravel(),
                     center=centers.ravel())

    def _tables_of(self, radii: np.ndarray, k: int) -> Tables:
        """The per-blocker constants of K worlds of people of ``radii`` (cached: one entry per crowd size and world count)."""
        key = (radii.tobytes(), k)
        tables = self._tables.get(key)
        if tables is None:
            if len(self._tables) > 64:  # bounded
                self._tables.clear()
            radius = np.concatenate([radii, self._disc_radius])
            base = np.arange(k) * (2 * BINS)
            tables = self._tables[key] = Tables(radius=radius, radius2=np.tile(radius * radius, k), vector=np.tile(self._edge_vector, k),
                                                base=np.concatenate([base.repeat(len(self._edge_vector)), base.repeat(len(radius))]))
        return tables


def _blocker_slots(bearing: np.ndarray, scene: Scene, tables: Tables) -> np.ndarray:
    """(2, blockers) int: each blocker's first slot (world * 2 BINS + bin) and one past its last, from the bearings (bin
    units) of its points; equal (no bins) for one that cannot block."""
    m = scene.edges
    bounds = np.empty((2, len(scene.idle)))  # the low and high bearing of every blocker
    bounds[:, :m] = bearing[: 2 * m].reshape(2, m)
    np.subtract(bearing[2 * m :], scene.half, out=bounds[0, m:])
    np.add(bearing[2 * m :], scene.half, out=bounds[1, m:])
    np.add(bounds[1, :m], BINS, out=bounds[1, :m], where=bounds[1, :m] < bounds[0, :m])  # an edge across the turn
    slots: np.ndarray = np.floor(bounds + _SLACKS).astype(np.intp)
    first, end = slots
    end += 1
    np.minimum(end, first + BINS, out=end)  # at most a turn (each ray once)
    slots += BINS * (first < 0) + tables.base  # an interval from below -pi: its run a turn later; then the world's slots
    np.copyto(end, first, where=scene.idle)
    return slots


class Scene(NamedTuple):
    """Every world's every blocker relative to its robot (world-major): ``edges`` polygon edges, then discs."""

    edges: int
    points: np.ndarray
    """(2 edges + discs,) complex: the edges' ends, their starts, the discs' centres (from the robot)."""
    half: np.ndarray
    """(discs,) a disc's bearing half-width bound, in bins."""
    idle: np.ndarray
    """(edges + discs,) bool: it cannot block (an edge facing away from the robot, a disc holding the robot's centre)."""
    start: np.ndarray
    """(edges,) complex: the edges' starts (from the robot)."""
    cross: np.ndarray
    """(edges,) cross(start, vector), < 0 facing."""
    center: np.ndarray
    """(discs,) complex: the discs' centres (from the robot)."""


class Tables(NamedTuple):
    """The constants of K worlds' blockers for one crowd: per disc, and per blocker of every world (world-major)."""

    radius: np.ndarray
    """(n + round furniture,) the disc radii: the people, then the round furniture."""
    radius2: np.ndarray
    """(K discs,) squared radius."""
    vector: np.ndarray
    """(K edges,) complex: the edge's vector."""
    base: np.ndarray
    """(K edges + K discs,) the blocker's world's first slot."""


def _may_block(start: np.ndarray, vector: np.ndarray, world: CompiledWorld) -> np.ndarray:
    """(E,) bool: the edges a line of sight between two points of the world can cross.

    With boundary walls the robot and the people stay in the world's box, so an edge whose line leaves
    the whole box on one side (the walls' faces, the outside of a polygon floor along the box) or that
    lies outside the box never blocks, and is dropped once here. An open world keeps every edge (the
    robot may step out of the box on its last step).
    """
    keep = np.ones(len(start), dtype=bool)
    box = world.scenario.world
    if not box.boundary_walls or not len(start):
        return keep
    (x0, y0), (x1, y1) = box.min, box.max
    corners = np.array([complex(x0, y0), complex(x1, y0), complex(x1, y1), complex(x0, y1)])
    side = ((corners[None, :] - start[:, None]).conj() * vector[:, None]).imag  # cross(corner - start, vector), per corner
    tolerance = 1e-9 * max(x1 - x0, y1 - y0) * np.abs(vector)[:, None]
    cuts = (side > tolerance).any(1) & (side < -tolerance).any(1)
    end = start + vector
    inside = (np.maximum(start.real, end.real) > x0) & (np.minimum(start.real, end.real) < x1) \
        & (np.maximum(start.imag, end.imag) > y0) & (np.minimum(start.imag, end.imag) < y1)
    may: np.ndarray = cuts & inside
    return may
