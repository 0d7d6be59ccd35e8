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

from crowdnav.sensors.runs import expand_runs
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
_SLACK = BEARING_SLACK * _SCALE


class Sightlines:
    """Lines of sight in one compiled world: its static edges and round furniture, and the people given per call."""

    def __init__(self, world: CompiledWorld):
        edges = oriented_edges(world.obstacles.polygons)
        keep = _may_block(edges.start, edges.vector, world)
        self._edge_start, self._edge_vector = edges.start[keep], edges.vector[keep]
        self._edge_cross = (self._edge_start.conj() * self._edge_vector).imag  # cross(start, vector): from the origin
        self._disc_center = np.asarray(world.obstacles.disc_center, dtype=complex)
        self._disc_radius = np.asarray(world.obstacles.disc_radius, dtype=float)
        self._radii: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def visible_fraction(self, robot: np.ndarray, toward: np.ndarray, distance: np.ndarray, radii: np.ndarray,
                         candidate: np.ndarray) -> np.ndarray:
        """(K, n) float: the fraction of each candidate person's rays that are clear (0 where not a candidate).

        ``robot``: (K,) complex robot centres; ``toward`` / ``distance``: (K, n) each person's centre from the
        robot (complex) and its length; ``radii``: (n,) their radii; ``candidate``: (K, n) bool, the people
        to test (the robot outside their disc). Every person blocks the others' rays, candidate or not.
        """
        out = np.zeros(toward.shape)
        world, person = np.nonzero(candidate)
        if not len(world):
            return out
        centre = toward[world, person][:, None]
        rays = (centre + (radii[person] / distance[world, person])[:, None] * (centre * _ACROSS)).ravel()
        count = len(rays)
        # each ray in its bearing bin and again a turn later, per world: 2 * BINS slots a world
        slot = np.minimum(((np.arctan2(rays.imag, rays.real) + math.pi) * _SCALE).astype(np.intp), BINS - 1)
        slot += world.repeat(RAYS) * (2 * BINS)
        slots = np.concatenate([slot, slot + BINS])
        order = np.argsort(slots, kind="stable")
        starts = np.zeros(len(toward) * 2 * BINS + 1, dtype=np.intp)
        np.cumsum(np.bincount(slots, minlength=len(toward) * 2 * BINS), out=starts[1:])
        blockers = self._blockers(robot, toward, distance, radii)
        position, ends = expand_runs(starts[blockers.first], starts[blockers.end] - starts[blockers.first])
        ray = order[position] % count
        edge_pairs = int(ends[blockers.edges - 1]) if blockers.edges else 0
        blocker = np.arange(len(blockers.first)).repeat(np.diff(ends, prepend=0))
        blocked = np.zeros(count, dtype=bool)
        # Edge a + s v (s in [0, 1]), ray t z (t in (0, 1)): t = cross(a, v) / cross(z, v), s = cross(a, z) / cross(z, v).
        # With cross(a, v) < 0 (a facing edge) both hold exactly when cross(z, v) < cross(a, v) and cross(z, v) <= cross(a, z) <= 0.
        e, re = blocker[:edge_pairs], ray[:edge_pairs]
        z = rays[re]
        den = (z.conj() * blockers.vector[e]).imag
        along = (blockers.start[e].conj() * z).imag
        blocked[re[(den < blockers.cross[e]) & (den <= along) & (along <= 0.0)]] = True
        # Disc: the segment [0, z] passes closer than r to the centre c: the nearest point is tau z, tau = clip(<z, c> / |z|^2, 0, 1).
        d, rd = blocker[edge_pairs:] - blockers.edges, ray[edge_pairs:]
        z, c = rays[rd], blockers.center[d]
        tau = np.clip((z.conj() * c).real / (z.real * z.real + z.imag * z.imag), 0.0, 1.0)
        gap = c - tau * z
        hit = (gap.real * gap.real + gap.imag * gap.imag < blockers.radius2[d]) & (blockers.person[d] != person[rd // RAYS])
        blocked[rd[hit]] = True  # (a ray never blocks on its own person)
        out[world, person] = (~blocked).reshape(-1, RAYS).sum(1) * (1.0 / RAYS)
        return out

    def _blockers(self, robot: np.ndarray, toward: np.ndarray, distance: np.ndarray, radii: np.ndarray) -> Blockers:
        """Every world's facing polygon edges, then its discs (people, then round furniture) that do not hold the robot."""
        k, n = toward.shape
        cross = self._edge_cross - (robot.conj()[:, None] * self._edge_vector).imag  # cross(start - robot, vector): < 0 facing
        edge_world, edge = np.nonzero(cross < 0.0)
        start = self._edge_start[edge] - robot[edge_world]
        vector = self._edge_vector[edge]
        if len(self._disc_center):
            furniture = self._disc_center - robot[:, None]
            centers, distances = np.concatenate([toward, furniture], axis=1), np.concatenate([distance, np.abs(furniture)], axis=1)
        else:
            centers, distances = toward, distance
        radius, person_of = self._disc_tables(radii)
        disc_world, disc = np.nonzero(distances > radius)  # a disc holding the robot's centre is transparent
        center, r = centers[disc_world, disc], radius[disc]
        # Bearings in bin units from -pi, in one arctan2: edge ends, edge starts, disc centres. Seen from outside, an
        # edge runs clockwise: from its end to its start; a disc spans its centre's bearing +- arcsin(r / d) <= r / d pi / 2.
        m = len(edge)
        points = np.concatenate([start + vector, start, center])
        bearing = (np.arctan2(points.imag, points.real) + math.pi) * _SCALE
        half = np.minimum(r / distances[disc_world, disc], 2.0) * (BINS / 4.0)
        low = np.concatenate([bearing[:m], bearing[2 * m :] - half])
        high = np.concatenate([bearing[m : 2 * m], bearing[2 * m :] + half])
        high[:m][high[:m] < low[:m]] += BINS  # an edge across the turn
        first = np.floor(low - _SLACK).astype(np.intp)
        end = np.minimum(np.floor(high + _SLACK).astype(np.intp) + 1, first + BINS)  # at most a turn (each ray once)
        turned = BINS * (first < 0)  # an interval from below -pi: its run a turn later
        first += turned
        end += turned
        base = np.concatenate([edge_world, disc_world]) * (2 * BINS)
        return Blockers(edges=m, first=first + base, end=end + base, start=start, vector=vector, cross=cross[edge_world, edge],
                        center=center, radius2=r * r, person=person_of[disc])

    def _disc_tables(self, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(radius, person index or -1) of every disc: the people (``radii``), then the round furniture."""
        key = radii.tobytes()
        tables = self._radii.get(key)
        if tables is None:
            if len(self._radii) > 64:  # bounded: one entry per crowd size
                self._radii.clear()
            n = len(radii)
            person = np.concatenate([np.arange(n), np.full(len(self._disc_radius), -1)])
            tables = self._radii[key] = (np.concatenate([radii, self._disc_radius]), person)
        return tables


class Blockers(NamedTuple):
    """What can block a ray, over all worlds: ``edges`` facing polygon edges, then discs; per blocker the run of
    (world, bin) slots its bearing interval covers, and its geometry relative to the robot."""

    edges: int
    first: np.ndarray
    """(edges + discs,) its first slot (world * 2 BINS + bin)."""
    end: np.ndarray
    """(edges + discs,) one past its last slot."""
    start: np.ndarray
    """The facing edges' starts (complex, from the robot)."""
    vector: np.ndarray
    cross: np.ndarray
    """The facing edges' cross(start, vector) < 0."""
    center: np.ndarray
    """The discs' centres (complex, from the robot)."""
    radius2: np.ndarray
    person: np.ndarray
    """A disc's person index (-1: furniture): a ray never blocks on its own person."""


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
