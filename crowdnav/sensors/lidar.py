"""``lidar``: an exact 2-D raycast scan against human discs, round furniture and polygon edges.

Beam ``k`` of ``B`` points at ``-fov/2 + fov * (k + 0.5) / B`` radians from the heading
(counter-clockwise positive), so a 360-degree scan starts just right of straight behind and
sweeps counter-clockwise; beams are symmetric about the heading.

Instead of intersecting every beam with every obstacle (a beams x obstacles matrix), each
obstacle is paired only with the beams inside the angle it subtends from the robot: a
polygon edge or a disc covers an interval of bearings, which maps to a run of beam indices
(one beam of slack each side; the exact hit test below decides). Polygon edges whose outer
side faces away from the robot are skipped: the first surface a ray meets from outside a
polygon is always one that faces it. Polygons and discs beyond ``max_range`` are skipped too.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

from crowdnav.scenario.schema import LidarSensor
from crowdnav.sensors.base import Modality, register_modality
from crowdnav.sensors.frames import to_robot_frame
from crowdnav.sensors.static_edges import oriented_edges

if TYPE_CHECKING:
    from crowdnav.simulator import Simulator
    from crowdnav.world import CompiledWorld

TWO_PI = 2.0 * math.pi


@register_modality
class LidarModality(Modality):
    """Normalized ranges ``range / max_range`` per beam, float32 in [0, 1]; 1 means nothing within range.

    Surfaces are seen from outside: an obstacle that contains the robot's centre (possible only
    after a collision) is transparent, and what lies behind an obstacle is occluded.
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
        edges = oriented_edges(world.obstacles.polygons)
        self._edge_start, self._edge_vector, self._edge_owner = edges.start, edges.vector, edges.owner
        self._has_polygons = world.obstacles.polygon_count > 0
        self._has_static_discs = world.obstacles.disc_count > 0
        self._static_disc_radius = world.obstacles.disc_radius

    def make_space(self) -> spaces.Box:
        return spaces.Box(low=0.0, high=1.0, shape=(self.beams,), dtype=np.float32)

    def observe(self, sim: Simulator) -> np.ndarray:
        return (self.ranges(sim) / self.max_range).astype(np.float32)

    # ------------------------------------------------------------------ raycast

    def ranges(self, sim: Simulator) -> np.ndarray:
        """(B,) float64 distances in metres from the robot's centre, ``max_range`` where nothing is hit."""
        rotate = to_robot_frame(sim)
        # Polygon edges in the robot frame; cross(start, vector) < 0 puts the robot on an
        # edge's outer side, the only side it can be seen from.
        start = (self._edge_start - complex(sim.positions[0])) * rotate
        vector = self._edge_vector * rotate
        cross = (start.conj() * vector).imag
        facing = cross < 0.0
        if self._has_polygons:
            facing &= (sim.polygon_distance[0] <= self.max_range)[self._edge_owner]
        edge = np.flatnonzero(facing)
        start, vector, cross = start[edge], vector[edge], cross[edge]
        # Seen from the robot, a facing edge spans the bearings from its end counter-clockwise to its start.
        edge_low = np.angle(start + vector)
        edge_span = np.mod(np.angle(start) - edge_low, TWO_PI)

        centre, radius, gap2 = self._discs_in_range(sim, rotate)
        half_width = np.arcsin(radius / np.abs(centre))
        disc_low = np.angle(centre) - half_width

        edge_beam, edge_index = self._beam_pairs(edge_low, edge_span)
        disc_beam, disc_index = self._beam_pairs(disc_low, 2.0 * half_width)
        out = np.full(self.beams, self.max_range)
        np.minimum.at(out, edge_beam, _edge_hits(self._directions[edge_beam], start[edge_index], vector[edge_index], cross[edge_index]))
        np.minimum.at(out, disc_beam, _disc_hits(self._directions[disc_beam], centre[disc_index], radius[disc_index], gap2[disc_index]))
        return out

    def _discs_in_range(self, sim: Simulator, rotate: complex) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Humans and round obstacles within range and not containing the robot: robot-frame centre, radius, d^2 - r^2."""
        offset, distance, radius = sim.pair_offset[0, 1:], sim.pair_distance[0, 1:], sim.radii[1:]
        if self._has_static_discs:
            offset = np.concatenate((offset, sim.disc_offset[0]))
            distance = np.concatenate((distance, sim.disc_distance[0]))
            radius = np.concatenate((radius, self._static_disc_radius))
        keep = np.flatnonzero((distance > radius) & (distance - radius <= self.max_range))
        distance, radius = distance[keep], radius[keep]
        return offset[keep] * rotate, radius, (distance - radius) * (distance + radius)

    def _beam_pairs(self, low: np.ndarray, span: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(beam, obstacle) index pairs for obstacles spanning bearings ``[low, low + span]`` (span < 2 pi).

        In beam units (beam k sits at u = k) an interval becomes ``[u0, u1]``; it may run past a
        full turn, so the indices are taken on two laps, the second shifted back by one turn.
        """
        u0 = np.mod(low + self.fov / 2, TWO_PI) / self.step - 0.5
        u1 = u0 + span / self.step
        u0 = np.concatenate((u0, u0 - self._beams_per_turn))
        u1 = np.concatenate((u1, u1 - self._beams_per_turn))
        first = np.maximum(np.floor(u0), 0.0).astype(np.intp)
        last = np.minimum(np.floor(u1) + 1.0, self.beams - 1).astype(np.intp)
        count = np.maximum(last - first + 1, 0)
        owner = np.tile(np.arange(len(low)), 2)
        # Run-length expansion: beam = first[i] + position within run i.
        total = int(count.sum())
        run_start = np.cumsum(count) - count
        beam = np.arange(total) + np.repeat(first - run_start, count)
        return beam, np.repeat(owner, count)


def _edge_hits(direction: np.ndarray, start: np.ndarray, vector: np.ndarray, cross: np.ndarray) -> np.ndarray:
    """Range along each unit ``direction`` to its paired edge (robot at the origin), inf on a miss.

    Solving ``t * d = a + s * e``: ``t = cross(a, e) / cross(d, e)``, ``s = cross(a, d) / cross(d, e)``;
    a hit needs the ray to enter the edge from its outer side (``cross(d, e) < 0``) and ``s`` in [0, 1].
    """
    denominator = (direction.conj() * vector).imag
    along = (start.conj() * direction).imag
    hit = (denominator < 0.0) & (along <= 0.0) & (along >= denominator)
    return np.divide(cross, denominator, out=np.full(len(direction), np.inf), where=hit)


def _disc_hits(direction: np.ndarray, centre: np.ndarray, radius: np.ndarray, gap2: np.ndarray) -> np.ndarray:
    """Range along each unit ``direction`` to its paired disc's near surface (robot outside), inf on a miss.

    With ``b`` the centre's distance along the ray and ``h`` its distance off the ray, the near
    root is ``b - sqrt(r^2 - h^2)``, written as ``(d^2 - r^2) / (b + sqrt(r^2 - h^2))`` to stay
    exact when the beam grazes the disc.
    """
    local = centre.conj() * direction  # |c| * exp(i * (beam bearing - centre bearing))
    along, off2 = local.real, local.imag**2
    inside = radius * radius - off2
    hit = (inside >= 0.0) & (along > 0.0)
    root = np.sqrt(np.maximum(inside, 0.0))
    return np.divide(gap2, along + root, out=np.full(len(direction), np.inf), where=hit)
