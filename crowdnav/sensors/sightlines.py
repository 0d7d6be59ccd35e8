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
depends on world k alone, bit for bit, whatever the other worlds are. The bins only choose which pairs
are tested (every pair that can meet is among them), so they may be computed loosely; the tests are
exact. A ray is paired with its own person's disc too, which it always hits (it ends inside): a ray
is clear with one hit, cheaper than finding those pairs. The arrays of a call are laid out once per
crowd and world count (:class:`_Layout`) and written in place, some eighty numpy operations on arrays
of a few hundred to a few thousand entries, none a broadcast along a short last axis (numpy's slow case).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

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
_SHIFT = np.array([[BINS * 1.5 - BEARING_SLACK * _SCALE], [BINS * 1.5 + BEARING_SLACK * _SCALE]])
"""Added to the (low, high) bearings of a blocker in bins from the turn's middle ([-BINS / 2, BINS / 2] and a disc's half
width): to bins from -pi, less or more the slack, plus a turn so that the float is positive (its truncation its floor)."""
_LAST = BINS / 2 - 2.0**-20
"""A ray's bearing in bins from the turn's middle is clamped below this (+pi falls in the last bin)."""


class Sightlines:
    """Lines of sight in one compiled world: its static edges and round furniture, and the people given per call."""

    def __init__(self, world: CompiledWorld):
        edges = oriented_edges(world.obstacles.polygons)
        keep = _may_block(edges.start, edges.vector, world)
        self._edge_start, self._edge_vector = edges.start[keep], edges.vector[keep]
        self._edge_cross = (self._edge_start.conj() * self._edge_vector).imag  # cross(start, vector): from the origin
        self._disc_center = np.asarray(world.obstacles.disc_center, dtype=complex)
        self._disc_radius = np.asarray(world.obstacles.disc_radius, dtype=float)
        self._layouts: dict[tuple[bytes, int], _Layout] = {}

    def visible_fraction(self, robot: np.ndarray, toward: np.ndarray, distance: np.ndarray, radii: np.ndarray,
                         candidate: np.ndarray) -> np.ndarray:
        """(K, n) float: the fraction of each candidate person's rays that are clear (0 where not a candidate).

        ``robot``: (K,) complex robot centres; ``toward`` / ``distance``: (K, n) each person's centre from the
        robot (complex) and its length; ``radii``: (n,) their radii; ``candidate``: (K, n) bool, the people
        to test, each with the robot outside its disc (``distance > radius``: its rays then end inside it).
        Every person blocks the others' rays, candidate or not.
        """
        k, n = toward.shape
        tested = np.flatnonzero(candidate)
        if not len(tested):
            return np.zeros((k, n))
        key = (radii.tobytes(), k)
        layout = self._layouts.get(key)
        if layout is None:
            if len(self._layouts) > 64:  # bounded
                self._layouts.clear()
            layout = self._layouts[key] = _Layout(self, np.asarray(radii, dtype=float), k)
        return layout.visible(robot, np.ascontiguousarray(toward).reshape(-1), np.ascontiguousarray(distance).reshape(-1),
                              candidate.reshape(-1), tested).reshape(k, n)


class _Layout:
    """The arrays of one call for K worlds of n people of given radii: constants, and buffers each call overwrites.

    Blockers: every world's edges (edge-major: edge e of world k at ``e K + k``), then every world's discs (disc
    d, the people then the round furniture, of world k at ``K edges + d K + k``). Rays: ``(RAYS, people)``, of
    every person (person j of world k at column ``k n + j``; those not tested sort past every blocker's
    slots), or of the candidates alone when they are fewer than half (cheaper than the gathers then).
    """

    def __init__(self, sight: Sightlines, radii: np.ndarray, k: int):
        n, edges = len(radii), len(sight._edge_start)
        disc_radius = np.concatenate([radii, sight._disc_radius])
        people, world = k * n, np.arange(k * n) // n
        self.k, self.n, self.rays = k, n, RAYS * people
        self.edges, self.blockers = k * edges, k * (edges + len(disc_radius))
        slots = k * 2 * BINS
        self.radius = np.tile(radii, k)
        """(K n,) each person's radius."""
        self.world_base = world * (2.0 * BINS) + BINS / 2
        """(K n,) added to a ray's bearing (bins from the turn's middle): its world's first slot, and half a turn."""
        self.unseen = slots + 1.5 * BINS
        """Added instead for a person not tested: its rays' slots lie past every blocker's."""
        self.disc_radius = disc_radius[:, None]
        """(discs, 1) the disc radii: the people, then the round furniture."""
        self.disc_bins = disc_radius[:, None] * (BINS / 4.0)
        """A disc's bearing half-width bound over r / d, in bins: arcsin(r / d) <= r / d pi / 2."""
        self.radius2 = np.repeat(disc_radius * disc_radius, k)
        """Per disc of every world: its squared radius."""
        self.base = (np.arange(self.blockers) % k) * (2 * BINS)
        """(blockers,) the blocker's world's first slot."""
        self.edge_start, self.edge_vector = sight._edge_start[:, None], sight._edge_vector[:, None]
        self.edge_cross, self.furniture = sight._edge_cross[:, None], sight._disc_center[:, None]
        self.edge_table = np.zeros((self.edges, 3), dtype=complex)
        """Per edge of every world: its vector, its start (from the robot) conjugated, cross(start, vector) (real); made in place."""
        self.edge_table[:, 0] = np.repeat(sight._edge_vector, k)
        self.points = np.empty(2 * self.blockers + self.rays, dtype=complex)
        """The blockers' (low, high) bearing points (edge ends and disc centres, edge starts and disc centres), then the rays' ends."""
        self.distances = np.empty((len(disc_radius), k))
        self.active = np.empty(self.blockers, dtype=bool)
        self.keys = np.empty((self.rays, 2), dtype=np.uint16 if slots + 3 * BINS <= 1 << 16 else np.intp)
        """Each ray's slot and the slot a turn later (16 bits if they fit: numpy's stable sort is then a radix sort)."""
        self.slots = np.empty((2, self.blockers), dtype=np.intp)
        self.count = slots + 3 * BINS  # the slots of the rays not tested go up to slots + 3 BINS - 1
        self.starts = np.zeros(self.count + 1, dtype=np.intp)
        """Per slot: the sorted rays before it (a count sort's offsets)."""
        self._counter = np.arange(0)
        # views of the buffers, made once: each call writes through them
        e, b = self.edges, self.blockers
        low, high = self.points[: 2 * b].reshape(2, -1)
        self.starts_at, self.ends_at = high[:e].reshape(-1, k), low[:e].reshape(-1, k)
        self.centres, self.centres_copy = low[e:].reshape(-1, k), high[e:].reshape(-1, k)
        self.cross, self.starts_conj = self.edge_table[:, 2].real.reshape(-1, k), self.edge_table[:, 1].reshape(-1, k)
        self.facing, self.outside = self.active[:e].reshape(-1, k), self.active[e:].reshape(-1, k)
        self.edge_runs, self.disc_runs, self.disc_centres = slice(0, e), slice(e, None), self.points[e:b]

    def counter(self, size: int) -> np.ndarray:
        """0, 1, ..., size - 1 (a view of a kept range)."""
        if len(self._counter) < size:
            self._counter = np.arange(max(size, 2 * len(self._counter)))
        return self._counter[:size]

    def visible(self, robot: np.ndarray, toward: np.ndarray, distance: np.ndarray, candidate: np.ndarray,
                tested: np.ndarray) -> np.ndarray:
        """(K n,) the visible fraction of each person (flat ``toward``, ``distance``, ``candidate``, whose entries are
        ``tested``; 0 where not a candidate)."""
        k, n, b = self.k, self.n, self.blockers
        # the blockers from the robot: (low, high) points, edges (edge-major) then discs (disc-major)
        starts, centres = self.starts_at, self.centres
        np.subtract(self.edge_start, robot, out=starts)
        np.add(starts, self.edge_vector, out=self.ends_at)  # seen from outside an edge runs from its end to its start
        centres[:n] = toward.reshape(k, n).T
        np.subtract(self.furniture, robot, out=centres[n:])
        self.centres_copy[...] = centres
        np.subtract(self.edge_cross, (robot.conj() * self.edge_vector).imag, out=self.cross)  # cross(start - robot, vector): < 0 facing
        np.conjugate(starts, out=self.starts_conj)
        distances = self.distances
        distances[:n] = distance.reshape(k, n).T
        np.abs(centres[n:], out=distances[n:])
        # what can block: an edge facing the robot, a disc not holding the robot's centre
        np.less(self.cross, 0.0, out=self.facing)
        np.greater(distances, self.disc_radius, out=self.outside)
        half = self.disc_bins / np.maximum(distances, self.disc_radius)
        # the rays: centre + r / d centre * 1j offset (r / d for a candidate, d > r; finite for anyone)
        sparse = 2 * len(tested) < len(toward)
        if sparse:
            toward, distance, radius, base = toward[tested], distance[tested], self.radius[tested], self.world_base[tested]
        else:
            radius, base = self.radius, np.where(candidate, self.world_base, self.unseen)
        points = self.points[: 2 * b + RAYS * len(toward)]
        ratio = radius / np.maximum(distance, radius)
        np.add(toward, ratio * (toward * _ACROSS[:, None]), out=points[2 * b :].reshape(RAYS, -1))
        # bearings in bins from the turn's middle, in one arctan2
        bearing = np.arctan2(points.imag, points.real)
        bearing *= _SCALE
        clear = self._clear(bearing, half.reshape(-1), base)
        if sparse:
            out = np.zeros(len(candidate))
            out[tested] = clear * (1.0 / RAYS)
            return out
        fraction: np.ndarray = np.where(candidate, clear * (1.0 / RAYS), 0.0)
        return fraction

    def _clear(self, bearing: np.ndarray, half: np.ndarray, base: np.ndarray) -> np.ndarray:
        """Each person's clear rays (of ``RAYS``): the (ray, blocker) pairs the bins allow and their exact tests."""
        e, b = self.edges, self.blockers
        rays = self.points[2 * b : len(bearing)]
        m = len(rays)
        # each ray in its (world, bin) slot and again a turn later (base: its world's, or past every blocker's)
        ray_bins = bearing[2 * b :].reshape(RAYS, -1)
        np.fmin(ray_bins, _LAST, out=ray_bins)
        ray_bins += base
        keys = self.keys[:m]
        np.copyto(keys[:, 0].reshape(RAYS, -1), ray_bins, casting="unsafe")  # positive: truncated, the floor
        np.add(keys[:, 0], BINS, out=keys[:, 1])
        keys = keys.reshape(-1)
        order = keys.argsort(kind="stable")
        order >>= 1  # the ray
        starts = self.starts
        np.cumsum(np.bincount(keys, minlength=self.count), out=starts[1:])
        # each blocker's slots: [first, first + length), length 0 if it cannot block
        bounds = bearing[: 2 * b].reshape(2, -1)
        np.subtract(bounds[0, e:], half, out=bounds[0, e:])
        np.add(bounds[1, e:], half, out=bounds[1, e:])
        bounds += _SHIFT
        slots = self.slots
        np.copyto(slots, bounds, casting="unsafe")
        first, end = slots
        end -= first
        end &= BINS - 1  # an interval across the turn: high < low
        end += 1
        end *= self.active
        first &= BINS - 1
        first += self.base
        end += first
        start, stop = starts[slots]
        # the pairs: blocker b meets the sorted rays at positions [start, stop); the edges' first
        runs = stop - start
        ends = runs.cumsum()
        start -= ends
        start += runs
        ray = order[np.repeat(start, runs) + self.counter(int(ends[-1]))]
        edge_pairs = int(ends[e - 1]) if e else 0
        z = rays[ray]
        z_conj = z.conj()
        hit = np.empty(len(ray), dtype=bool)
        # Edge a + s v (s in [0, 1]), ray t z (t in (0, 1)): t = cross(a, v) / cross(z, v), s = cross(a, z) / cross(z, v).
        # With cross(a, v) < 0 (a facing edge) both hold exactly when cross(z, v) < cross(a, v) and cross(z, v) <= cross(a, z) <= 0.
        edge = np.repeat(self.edge_table, runs[self.edge_runs], axis=0)
        den = (z_conj[:edge_pairs] * edge[:, 0]).imag
        along = (edge[:, 1] * z[:edge_pairs]).imag
        np.logical_and(den < edge[:, 2].real, den <= along, out=hit[:edge_pairs])
        hit[:edge_pairs] &= along <= 0.0
        # Disc: the segment [0, z] passes closer than r to the centre c: the nearest point is tau z, tau = clip(<z, c> / |z|^2, 0, 1).
        # A ray of a candidate meets its own person's disc, which it always hits (it ends 0.6 r from the centre at most): one hit
        # too many per ray, instead of finding those pairs
        z, runs = z[edge_pairs:], runs[self.disc_runs]
        c, radius2 = np.repeat(self.disc_centres, runs), np.repeat(self.radius2, runs)
        tau = (z_conj[edge_pairs:] * c).real / (z.real * z.real + z.imag * z.imag)
        np.minimum(np.maximum(tau, 0.0, out=tau), 1.0, out=tau)
        gap = c - tau * z
        np.less(gap.real * gap.real + gap.imag * gap.imag, radius2, out=hit[edge_pairs:])
        clear = (np.bincount(ray, weights=hit, minlength=m) < 1.5).view(np.uint8).reshape(RAYS, -1)  # its own disc's hit alone
        counts: np.ndarray = clear[0] + clear[1] + clear[2] if RAYS == 3 else clear.sum(0)
        return counts


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
