"""Occlusion of the people tracker (:mod:`crowdnav.sensors.sightlines`): exact lines of sight past walls, furniture and
people, in hand-built scenes and against a brute-force reference, for one world and many at once."""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav.sensors.sightlines import SIGHT_OFFSETS, Sightlines
from crowdnav.sensors.static_edges import oriented_edges
from crowdnav.worlds.compiled import load_world

RADIUS = 0.3


def scene(furniture: list[dict], walls: list[dict] | None = None, boundary: bool = False):
    """A 20 m x 20 m world with the given furniture and walls (people are placed per test)."""
    return load_world({
        "description": "occlusion scene",
        "world": {"min": [-10, -10], "max": [10, 10], "boundary_walls": boundary},
        "robot": {"start": {"type": "points", "points": [[0, 0]]}, "goal": {"type": "points", "points": [[3, 4]]}},
        "walls": walls or [],
        "furniture": furniture,
        "humans": {"count": 1, "radius": RADIUS, "spawn": [{"type": "rectangle", "min": [-9, -9], "max": [-8, -8]}],
                   "goal": [{"type": "rectangle", "min": [-9, -9], "max": [-8, -8]}]},
    })


PILLAR = {"type": "circle", "center": [3, 0], "radius": 0.5}
TABLE = {"type": "rectangle", "center": [0, 3], "size": [2, 0.2]}


def seen(sight: Sightlines, robot: complex, people: list[complex], candidate=None) -> np.ndarray:
    """The visible fraction of each person (one world)."""
    toward = np.array([people]) - robot
    candidate = np.ones(toward.shape, dtype=bool) if candidate is None else np.array([candidate])
    return sight.visible_fraction(np.array([robot]), toward, np.abs(toward), np.full(len(people), RADIUS), candidate)[0]


def test_a_person_behind_a_pillar_is_not_seen_one_beside_it_is():
    sight = Sightlines(scene([PILLAR]))
    behind, beside, far_beside = 5 + 0j, 5 + 1.5j, 6 - 2j
    np.testing.assert_array_equal(seen(sight, 0j, [behind, beside, far_beside]), [0.0, 1.0, 1.0])


def test_a_person_half_behind_a_pillar_is_partly_seen():
    fraction = seen(Sightlines(scene([PILLAR])), 0j, [5 + 0.75j])[0]
    assert 0.0 < fraction < 1.0 and fraction * len(SIGHT_OFFSETS) % 1 == 0


def test_a_table_and_a_wall_hide_the_people_behind_them_not_those_past_their_ends():
    sight = Sightlines(scene([TABLE], walls=[{"points": [[-6, -2], [-6, 2]], "thickness": 0.2}]))
    behind_table, past_table_end, behind_wall, past_wall_end = 5j, 2 + 5j, -8 + 0j, -8 + 4j
    np.testing.assert_array_equal(seen(sight, 0j, [behind_table, past_table_end, behind_wall, past_wall_end]), [0, 1, 0, 1])


def test_a_person_hides_the_person_behind_but_never_itself():
    sight = Sightlines(scene([]))
    np.testing.assert_array_equal(seen(sight, 0j, [-3 + 0j, -6 + 0j, -6 + 2j]), [1.0, 0.0, 1.0])


def test_lines_of_sight_across_the_turn_behind_the_robot():
    sight = Sightlines(scene([]))  # bearings near +-pi on either side of the turn
    np.testing.assert_array_equal(seen(sight, 1 + 0j, [-5 + 0.01j, -5 - 0.01j, -3 + 0j]), [0.0, 0.0, 1.0])


def test_only_candidates_are_tested_but_everyone_blocks():
    sight = Sightlines(scene([]))
    np.testing.assert_array_equal(seen(sight, 0j, [-3 + 0j, -6 + 0j], candidate=[False, True]), [0.0, 0.0])


def test_a_disc_holding_the_robot_is_transparent():
    sight = Sightlines(scene([PILLAR]))  # after a collision the robot's centre may be inside the pillar
    np.testing.assert_array_equal(seen(sight, 3 + 0.1j, [6 + 0j]), [1.0])


def test_boundary_walls_are_dropped_once_they_block_nothing_inside_the_world():
    walled, furnished = scene([], boundary=True), scene([TABLE], boundary=True)
    assert len(oriented_edges(walled.obstacles.polygons).start) > 0 and len(Sightlines(walled)._edge_start) == 0
    assert len(Sightlines(furnished)._edge_start) == 4  # the table's four sides stay


def reference(world, robot: np.ndarray, people: np.ndarray, candidate: np.ndarray) -> np.ndarray:
    """One ray, one obstacle at a time, in Python: the definition the kernel must match exactly."""
    edges = oriented_edges(world.obstacles.polygons)
    discs = list(zip(world.obstacles.disc_center, world.obstacles.disc_radius, strict=True))
    out = np.zeros(people.shape)
    for k, j in zip(*np.nonzero(candidate), strict=True):
        toward = people[k, j] - robot[k]
        clear = 0
        for offset in SIGHT_OFFSETS:
            z = toward + RADIUS / abs(toward) * toward * 1j * offset
            blocked = False
            for start, vector in zip(edges.start, edges.vector, strict=True):
                a = start - robot[k]
                cross_av, den, along = (a.conjugate() * vector).imag, (z.conjugate() * vector).imag, (a.conjugate() * z).imag
                blocked |= cross_av < 0 and den < cross_av and den <= along <= 0
            others = [(people[k, i], RADIUS) for i in range(people.shape[1]) if i != j] + discs
            for center, radius in others:
                c = center - robot[k]
                if abs(c) > radius:
                    tau = min(1.0, max(0.0, (z.conjugate() * c).real / abs(z) ** 2))
                    blocked |= abs(c - tau * z) < radius
            clear += not blocked
        out[k, j] = clear / len(SIGHT_OFFSETS)
    return out


@pytest.mark.parametrize("scenario", ["room_furniture", "cafe"])
def test_many_worlds_at_once_match_the_one_ray_at_a_time_reference_exactly(scenario):
    world = load_world(scenario)
    sight = Sightlines(world)
    rng = np.random.default_rng(5)
    (x0, y0), (x1, y1) = np.add(world.scenario.world.min, RADIUS), np.subtract(world.scenario.world.max, RADIUS)  # discs inside the walls
    for _ in range(4):
        robot = rng.uniform(x0, x1, 16) + 1j * rng.uniform(y0, y1, 16)
        people = rng.uniform(x0, x1, (16, 8)) + 1j * rng.uniform(y0, y1, (16, 8))
        toward = people - robot[:, None]
        candidate = (np.abs(toward) > RADIUS) & (rng.random((16, 8)) < 0.8)
        got = sight.visible_fraction(robot, toward, np.abs(toward), np.full(8, RADIUS), candidate)
        np.testing.assert_array_equal(got, reference(world, robot, people, candidate))
        for k in (0, 7):  # one world alone: the same bits
            alone = sight.visible_fraction(robot[k : k + 1], toward[k : k + 1], np.abs(toward[k : k + 1]), np.full(8, RADIUS), candidate[k : k + 1])
            np.testing.assert_array_equal(alone[0], got[k])
