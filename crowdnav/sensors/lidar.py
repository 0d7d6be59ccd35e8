"""``lidar``: an exact 2-D raycast scan against human discs, round furniture and polygon edges.

Beam ``k`` of ``B`` points at ``-fov/2 + fov * (k + 0.5) / B`` radians from the heading
(counter-clockwise positive), so a 360-degree scan starts just right of straight behind and
sweeps counter-clockwise; the beams are symmetric about the heading.

Instead of intersecting every beam with every obstacle (a beams x obstacles matrix), each
obstacle is paired only with the run of beams inside the bearings it subtends from the robot
(with one beam of slack each side, and a cheap over-estimate of a disc's angular half-width:
the exact hit test decides). Polygon edges whose outer side faces away from the robot are
skipped: from outside a polygon, the first surface a ray meets always faces it.

Hits are kept as inverse ranges ``1 / t``, so that "nearest hit" is a maximum, a miss can be
any value <= 0 or NaN (ignored by ``fmax``), and no division by a ray-edge determinant that
may be zero is needed.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

from crowdnav.batch.scalar_math import TWO_PI, remainder
from crowdnav.scenario.schema import LidarSensor
from crowdnav.sensors.base import Modality, RadiiConstants, register_modality
from crowdnav.sensors.runs import expand_runs
from crowdnav.sensors.static_edges import oriented_edges

if TYPE_CHECKING:
    from crowdnav.batch.state import BatchState
    from crowdnav.sim.robot_view import RobotWorld
    from crowdnav.worlds.compiled import CompiledWorld

@register_modality
class LidarModality(Modality):
    """Normalized ranges ``range / max_range`` per beam, float32 in [0, 1]; 1 means nothing within range.

    Surfaces are seen from outside: an obstacle that contains the robot's centre (possible only
    after a collision) is transparent, and what lies behind an obstacle is occluded. Scale: the Box
    default, 1 (the readings are already fractions of ``max_range``).
    """

    key = "lidar"
    settings_type = LidarSensor

    def __init__(self, world: CompiledWorld, settings: LidarSensor | None = None):
        super().__init__(world, settings)
        self.beams = int(self.settings.beams)
        self.fov = math.radians(self.settings.fov_deg)
        self.max_range = float(self.settings.max_range)
        self.step = self.fov / self.beams
        """Angle between neighbouring beams (rad)."""
        self.angles = -self.fov / 2 + self.step * (np.arange(self.beams) + 0.5)
        """(B,) beam bearings relative to the heading (rad)."""
        self._directions = np.exp(1j * self.angles)
        self._beams_per_turn = self.beams * 360.0 / self.settings.fov_deg  # exact B when fov is 360
        self._full_circle = self.settings.fov_deg == 360.0
        edges = oriented_edges(world.obstacles.polygons)
        self._edge_count = edges.count
        self._edge_start, self._edge_vector = edges.start, edges.vector
        self._edge_end = edges.start + edges.vector
        self._edge_vector_conj = edges.vector.conj()
        obstacles = world.obstacles
        self._static_disc_count = obstacles.disc_count
        self._static_disc_center = obstacles.disc_center
        self._static_disc_radius = obstacles.disc_radius
        self._no_hit = np.full(self.beams, 1.0 / self.max_range)
        self._primitive_constants = RadiiConstants(self._constants_for)
        """radii -> (P,) per primitive: numerator of the bearing half-width and squared radius (both 0 for edges)."""

    def make_space(self) -> spaces.Box:
        return spaces.Box(low=0.0, high=1.0, shape=(self.beams,), dtype=np.float32)

    def observe(self, sim: RobotWorld) -> np.ndarray:
        return self.readings(sim.positions, sim.robot_heading, sim.radii)

    def observe_batch(self, state: BatchState) -> np.ndarray:
        return self.readings(state.positions, state.robot_heading, state.radii)

    def readings(self, positions: np.ndarray, heading: float | np.ndarray, radii: np.ndarray) -> np.ndarray:
        """The observation ``(*W, B)`` float32 of :meth:`inverse_ranges`' worlds: ``range / max_range`` per beam."""
        inverse = self.inverse_ranges(positions, heading, radii)
        out = np.empty(inverse.shape, dtype=np.float32)
        # (1 / max_range) / inverse <= 1: the inverse ranges start at 1 / max_range
        np.divide(1.0 / self.max_range, inverse, out=out)
        return out

    def ranges(self, sim: RobotWorld) -> np.ndarray:
        """(B,) float64 distances in metres from the robot's centre, ``max_range`` where nothing is hit."""
        return 1.0 / self.inverse_ranges(sim.positions, sim.robot_heading, sim.radii)

    # ------------------------------------------------------------------ raycast

    @np.errstate(divide="ignore", invalid="ignore")  # misses may be inf/NaN by design, see the module doc
    def inverse_ranges(self, positions: np.ndarray, heading: float | np.ndarray, radii: np.ndarray) -> np.ndarray:
        """The scan kernel: ``(*W, B)`` per world and beam, max(1 / max_range, 1 / range of the nearest hit).

        ``positions``: ``(*W, n+1)`` complex, robot first; ``heading``: ``W``-shaped, the robots'
        headings; ``radii``: (n+1,), shared by the worlds. ``W`` is ``(K,)`` for K worlds
        (``observe_batch``) or ``()`` for one (``observe``: no world axis, so one world pays no
        numpy overhead for it); row k depends on world k alone, bit for bit. The (world,
        primitive, beam) pairs of all worlds form one flat list, every world's edges before every
        world's discs, so one scatter maximum fills every scan.
        """
        batched, beams, edges = positions.ndim == 2, self.beams, self._edge_count
        worlds = len(positions) if batched else 1
        primitives = edges + positions.shape[-1] - 1 + self._static_disc_count
        shift, rotation = self._heading_terms(heading, batched)
        half_width_numerator, radius2 = self._primitive_constants(radii)
        # World-frame offsets from the robot, laid out so that one arctan2 gives every bearing
        # interval: [edge ends, disc centres | edge starts, disc centres]. Per-primitive arrays
        # below have length P = edges + discs, discs after edges.
        z = self._primitive_points(positions)
        z -= positions[:, :1] if batched else positions[0]
        bearing = np.arctan2(z.imag, z.real)
        bearing *= 1.0 / self.step
        bearing += shift  # beam units: beam k sits at k; whole turns are added so the values stay positive
        near = z[..., :primitives]  # edges: their end; discs: their centre
        distance = np.abs(near)
        half_width = half_width_numerator / distance
        low = bearing[..., :primitives] - half_width
        high = bearing[..., primitives:] + half_width

        # Per-primitive scale, positive exactly for the primitives the robot can see: edges
        # -1 / cross(start, vector) (the robot on the edge's outer side), discs 1 / (d^2 - r^2)
        # (the robot outside the disc). Scaling the hit formulas by it makes them give 1 / range.
        start_conj = z[..., primitives : primitives + edges].conj()
        scale = np.empty(positions.shape[:-1] + (primitives,))
        np.divide(-1.0, (start_conj * self._edge_vector).imag, out=scale[..., :edges])
        gap2 = distance[..., edges:]
        gap2 *= gap2
        gap2 -= radius2[edges:]
        np.divide(1.0, gap2, out=scale[..., edges:])
        factor = np.empty(positions.shape[:-1] + (primitives,), dtype=complex)  # multiplies a beam direction in every hit formula
        np.multiply(self._edge_vector_conj, scale[..., :edges], out=factor[..., :edges])
        np.multiply(near[..., edges:].conj(), scale[..., edges:], out=factor[..., edges:])
        start_factor = start_conj * scale[..., :edges]
        radius2 = radius2 * (scale * scale)

        def by_kind(values: np.ndarray) -> np.ndarray:  # (K, P) -> every world's edges, then every world's discs
            if not batched:
                return values
            return np.concatenate((values[..., :edges].ravel(), values[..., edges:].ravel()))

        edge_count = worlds * edges
        beam, count, edge_pairs = self._beam_runs(by_kind(low), by_kind(high), by_kind(scale > 0.0), edge_count)
        if not batched:  # numpy's complex multiply gives each element the same bits whatever the layout
            world_beam = beam
            direction = self._directions.take(beam) * rotation
        else:  # (world, beam) of every pair as one index into (K, B) tables: the directions and the scan
            world_beam = by_kind(np.broadcast_to(np.arange(0, worlds * beams, beams)[:, None], (worlds, primitives))).repeat(count)
            world_beam += beam
            direction = (self._directions * rotation).take(world_beam)
        local = by_kind(factor).repeat(count) * direction
        inverse = np.empty(len(beam))
        # Edge a + s * e, ray t * d (robot at the origin): t = cross(a, e) / cross(d, e) and
        # s = cross(a, d) / cross(d, e). With the scale k = -1 / cross(a, e), 1 / t = k * cross(e, d)
        # = Im(k conj(e) d), and 0 <= s <= 1 reads -k cross(e, d) <= k cross(a, d) <= 0.
        hit = local.imag[:edge_pairs]
        along = (start_factor.ravel().repeat(count[:edge_count]) * direction[:edge_pairs]).imag
        np.multiply(hit, along * (along + hit) <= 0.0, out=inverse[:edge_pairs])
        # Disc: with b the centre's distance along the ray and h its distance off it, the near
        # root b - sqrt(r^2 - h^2) equals (d^2 - r^2) / (b + sqrt(r^2 - h^2)); scaled by
        # k = 1 / (d^2 - r^2), its inverse is k b + sqrt(k^2 r^2 - k^2 h^2): NaN on a miss,
        # negative for a disc behind the robot.
        disc_local = local[edge_pairs:]
        root = radius2[..., edges:].ravel().repeat(count[edge_count:]) - disc_local.imag**2
        np.sqrt(root, out=root)
        np.add(root, disc_local.real, out=inverse[edge_pairs:])
        out = np.full(worlds * beams, 1.0 / self.max_range) if batched else self._no_hit.copy()
        np.fmax.at(out, world_beam, inverse)
        return out.reshape(positions.shape[:-1] + (beams,))

    def _heading_terms(self, heading: float | np.ndarray, batched: bool) -> tuple[float | np.ndarray, complex | np.ndarray]:
        """The bearing shift (beam units) and the rotation ``exp(i heading)``, heading taken mod 2 pi.

        One world: Python scalar math (cheaper than numpy for one number); K worlds: (K, 1) arrays
        of the same bits (:mod:`crowdnav.batch.scalar_math`).
        """
        if not batched:
            h = math.remainder(float(heading), TWO_PI)
            return (self.fov / 2 - h) / self.step - 0.5 + 3 * self._beams_per_turn, complex(math.cos(h), math.sin(h))
        hk = remainder(heading, TWO_PI)[:, None]
        rotation = np.empty(hk.shape, dtype=complex)
        rotation.real, rotation.imag = np.cos(hk), np.sin(hk)
        return (self.fov / 2 - hk) / self.step - 0.5 + 3 * self._beams_per_turn, rotation

    def _primitive_points(self, positions: np.ndarray) -> np.ndarray:
        """``(*W, 2P)`` complex: [edge ends, humans, round obstacles | edge starts, humans, round obstacles] per world."""
        humans = positions[..., 1:]
        if positions.ndim == 1:
            return np.concatenate((self._edge_end, humans, self._static_disc_center, self._edge_start, humans, self._static_disc_center))
        edges, discs = self._edge_count, self._static_disc_count
        primitives = edges + humans.shape[1] + discs
        z = np.empty((len(positions), 2 * primitives), dtype=complex)
        for at, part in enumerate((self._edge_end, self._edge_start)):
            z[:, at * primitives : at * primitives + edges] = part
            z[:, at * primitives + edges : (at + 1) * primitives - discs] = humans
            z[:, (at + 1) * primitives - discs : (at + 1) * primitives] = self._static_disc_center
        return z

    def _beam_runs(self, low: np.ndarray, high: np.ndarray, visible: np.ndarray, edges: int) -> tuple[np.ndarray, np.ndarray, int]:
        """Expand bearing intervals ``[low, high]`` (beam units, wrapping) into (beam, primitive) pairs.

        Primitives that are not ``visible`` get no pairs. Returns the beam of every pair, the
        number of pairs per primitive (pairs are grouped by primitive, in order) and how many
        pairs belong to edges (they come first).
        """
        if self._full_circle:
            first = low.astype(np.intp)  # floor: the values are positive
            count = (high.astype(np.intp) - first) % self.beams + 2  # one beam of slack each side
            count *= visible
            beam, ends = expand_runs(first, count)
            beam %= self.beams
            return beam, count, int(ends[edges - 1]) if edges else 0
        # A partial field of view: the interval may run past a full turn onto the first beams
        # again, so each primitive gets a run on each of two laps, the second shifted back by a turn.
        turn = self._beams_per_turn
        low = np.mod(low, turn)
        high = low + np.mod(high - low, turn)
        first = np.maximum(np.floor(np.stack((low, low - turn))), 0.0)  # (lap, primitive)
        last = np.minimum(np.floor(np.stack((high, high - turn))) + 1.0, self.beams - 1.0)
        count = np.maximum(last - first + 1.0, 0.0).astype(np.intp) * visible
        # primitive-major order, so that a primitive's pairs stay together
        beam, ends = expand_runs(first.T.astype(np.intp).ravel(), count.T.ravel())
        return beam, count.sum(0), int(ends[2 * edges - 1]) if edges else 0

    def _constants_for(self, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # arcsin(x) <= x * pi / 2 on [0, 1]: (r * pi / 2) / d bounds a disc's bearing half-width
        radius = np.concatenate((np.zeros(self._edge_count), radii[1:], self._static_disc_radius))
        return radius * (math.pi / 2) / self.step, radius**2
