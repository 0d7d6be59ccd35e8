"""Exactness of the geometric modalities: LIDAR, occupancy grid (LEOG) and closest obstacle.

Test worlds are scenario mappings; the robot and humans are then placed by writing the
simulator's state and refreshing its cached geometry (``sim.refresh()``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from shapely.geometry import Point
from shapely.ops import nearest_points

from crowdnav import Simulator, load_scenario
from crowdnav.sensors import build_modalities

HUMAN_RADIUS = 0.3


def make_sim(furniture=(), walls=(), humans=0, sensors=None, extent=10.0) -> Simulator:
    """An open square world (no boundary walls) with the given obstacles and crowd size."""
    corner = [extent - 2.0, extent - 2.0]
    scenario = {
        "description": "sensor geometry test world",
        "world": {"min": [-extent, -extent], "max": [extent, extent], "boundary_walls": False},
        "furniture": list(furniture),
        "walls": list(walls),
        "robot": {
            "start": {"type": "rectangle", "min": [-extent + 0.5, -extent + 0.5], "max": [-extent + 1.5, -extent + 1.5]},
            "goal": {"type": "points", "points": [corner]},
        },
        "humans": {
            "count": humans,
            "radius": HUMAN_RADIUS,
            "spawn": [{"type": "rectangle", "min": [-extent + 0.5, extent - 4.5], "max": [-extent + 4.5, extent - 0.5]}],
            "goal": [{"type": "points", "points": [corner]}],
        },
        "sensors": sensors or {},
    }
    sim = Simulator(load_scenario(scenario))
    sim.reset(seed=0)
    return sim


def place(sim: Simulator, robot: complex, heading: float, humans=()) -> None:
    """Put the robot and the humans where a test wants them and refresh the cached geometry."""
    assert len(humans) == sim.n_humans
    sim.positions = np.array([robot, *humans], dtype=complex)
    sim.velocities = np.zeros(len(sim.positions), dtype=complex)
    sim.robot_heading = heading
    sim.refresh()


def modality(sim: Simulator, key: str):
    return build_modalities([key], sim.world, sim.scenario.sensors)[key]


def static_shapes(sim: Simulator, quad_segs: int = 512):
    obstacles = sim.obstacles
    discs = [Point(c.real, c.imag).buffer(r, quad_segs=quad_segs) for c, r in zip(obstacles.disc_center, obstacles.disc_radius, strict=True)]
    return list(obstacles.polygons) + discs


def human_shapes(sim: Simulator, quad_segs: int = 512):
    return [Point(z.real, z.imag).buffer(r, quad_segs=quad_segs) for z, r in zip(sim.positions[1:], sim.radii[1:], strict=True)]


def random_states(sim: Simulator, count: int, seed: int):
    """Real simulator states of a random-walking robot, skipping those with its centre inside an obstacle."""
    rng = np.random.default_rng(seed)
    sim.reset(seed=seed)
    produced = 0
    while produced < count:
        union = shapely.union_all(static_shapes(sim, 64) + human_shapes(sim, 64))
        if not union.contains(Point(sim.positions[0].real, sim.positions[0].imag)):
            produced += 1
            yield
        if sim.step(rng.uniform(-1, 1, size=2)).terminated:
            sim.reset(seed=int(rng.integers(1 << 30)))


# ------------------------------------------------------------------------------ LIDAR

WALL = {"type": "rectangle", "center": [2.2, 0.0], "size": [0.4, 6.0]}  # front face x = 2, y in [-3, 3]


def test_lidar_reads_the_exact_distance_to_a_wall():
    sim = make_sim(furniture=[WALL])
    place(sim, 0j, 0.0)
    lidar = modality(sim, "lidar")
    angles = -math.pi + 2 * math.pi * (np.arange(360) + 0.5) / 360  # documented beam layout
    np.testing.assert_allclose(lidar.angles, angles, atol=1e-12)
    hits = np.abs(angles) < math.atan2(3.0, 2.0)
    expected = np.where(hits, 2.0 / np.cos(angles), 5.0)
    np.testing.assert_allclose(lidar.ranges(sim), expected, atol=1e-6)
    np.testing.assert_allclose(lidar.observe(sim) * 5.0, expected, atol=1e-6)
    assert hits.sum() == 112  # the beams within +-56.3 degrees of the heading


def test_lidar_beams_turn_with_the_robot_and_cover_a_partial_field_of_view():
    sensors = {"lidar": {"beams": 4, "fov_deg": 90, "max_range": 5.0}}
    # wall across world +y at distance 2, x in [-2, 2]: straight ahead when the robot faces +y
    sim = make_sim(furniture=[{"type": "rectangle", "center": [0.0, 2.2], "size": [4.0, 0.4]}], sensors=sensors)
    place(sim, 0j, math.pi / 2)
    lidar = modality(sim, "lidar")
    angles = np.radians([-33.75, -11.25, 11.25, 33.75])  # -fov/2 + fov * (k + 0.5) / B, k = 0 is the rightmost
    np.testing.assert_allclose(lidar.ranges(sim), 2.0 / np.cos(angles), atol=1e-9)
    place(sim, 0j, 0.0)  # facing +x, the wall is at +90 degrees: outside the 90-degree field of view
    np.testing.assert_array_equal(lidar.observe(sim), np.ones(4, dtype=np.float32))
    place(sim, 0j, math.radians(50))  # beams at 61.25 and 83.75 degrees reach y = 2 within |x| <= 2
    expected = [5.0, 5.0, 2.0 / math.sin(math.radians(61.25)), 2.0 / math.sin(math.radians(83.75))]
    np.testing.assert_allclose(lidar.ranges(sim), expected, atol=1e-9)


def test_lidar_hits_a_human_disc_at_its_near_surface():
    sim = make_sim(humans=1)
    place(sim, 0j, 0.0, humans=[3.0 + 0j])
    ranges = modality(sim, "lidar").ranges(sim)
    angles = modality(sim, "lidar").angles
    # ray t * (cos a, sin a) meets the circle |p - (3, 0)| = r at t = 3 cos a - sqrt(r^2 - 9 sin^2 a)
    off2 = 9 * np.sin(angles) ** 2
    hit = (off2 <= HUMAN_RADIUS**2) & (np.cos(angles) > 0)
    expected = np.where(hit, 3 * np.cos(angles) - np.sqrt(np.maximum(HUMAN_RADIUS**2 - off2, 0)), 5.0)
    np.testing.assert_allclose(ranges, expected, atol=1e-9)
    assert hit.sum() == 12  # +-5.7 degrees around the heading


def test_human_hidden_behind_a_box_is_not_seen_by_the_lidar_but_is_in_the_leog():
    box_item = {"type": "rectangle", "center": [1.25, 0.0], "size": [0.5, 1.0]}  # x in [1, 1.5], y in [-0.5, 0.5]
    sim = make_sim(furniture=[box_item], humans=1, sensors={"leog": {"size": 8.0, "resolution": 0.1}})
    place(sim, 0j, 0.0, humans=[3.0 + 0j])
    lidar = modality(sim, "lidar")
    with_human = lidar.ranges(sim)
    place(sim, 0j, 0.0, humans=[-8.0 - 8.0j])  # far away, out of range
    without_human = lidar.ranges(sim)
    np.testing.assert_array_equal(with_human, without_human)
    assert not np.any(np.abs(with_human - 2.7) < 0.1)
    place(sim, 0j, 0.0, humans=[3.0 + 0j])
    grid = modality(sim, "leog").observe(sim)[0]
    # cell centre (x, y) = (3.05, 0.05): row 40 - 30 - 1 = 9, column 40 - 0 - 1 = 39
    assert grid[9, 39] == 255 and grid[9, 40] == 255
    assert grid[9, 36] == 0  # 0.35 m to the left of the human centre: outside its disc


def test_lidar_matches_a_brute_force_raycast_on_real_states():
    sim = Simulator("room_furniture", {"humans.count": 20})
    lidar = modality(sim, "lidar")
    for _ in random_states(sim, 25, seed=1):
        np.testing.assert_allclose(lidar.ranges(sim), brute_force_ranges(sim, lidar.angles, lidar.max_range), atol=1e-9)


def brute_force_ranges(sim: Simulator, angles: np.ndarray, max_range: float) -> np.ndarray:
    """Every beam against every polygon edge (padded edges included) and every disc."""
    p = sim.positions[0]
    d = np.exp(1j * (angles + sim.robot_heading))[:, None]
    obstacles = sim.obstacles
    a, e = obstacles.edge_start.ravel() - p, obstacles.edge_vector.ravel()
    cross = lambda u, v: (np.conj(u) * v).imag  # noqa: E731
    with np.errstate(divide="ignore", invalid="ignore"):
        den = cross(d, e)
        t, s = cross(a, e) / den, cross(a, d) / den
        edge_t = np.where((t >= 0) & (s >= 0) & (s <= 1) & (den != 0), t, np.inf).min(1, initial=np.inf)
        centres = np.concatenate((sim.positions[1:], obstacles.disc_center)) - p
        radii = np.concatenate((sim.radii[1:], obstacles.disc_radius))
        b = (np.conj(centres) * d).real
        root = b**2 - (np.abs(centres) ** 2 - radii**2)
        disc_t = np.where((root >= 0) & (b - np.sqrt(root) >= 0), b - np.sqrt(root), np.inf).min(1, initial=np.inf)
    return np.minimum(np.minimum(edge_t, disc_t), max_range)


# ------------------------------------------------------------------------------- LEOG

LEOG_4x4 = {"leog": {"size": 2.0, "resolution": 0.5}}  # cell centres at +-0.25 and +-0.75 m


def test_leog_of_a_known_layout_matches_the_hand_computed_grid():
    box_item = {"type": "rectangle", "center": [1.0, 0.75], "size": [1.0, 1.5]}  # x in [0.5, 1.5], y in [0, 1.5]
    sim = make_sim(furniture=[box_item], humans=1, sensors=LEOG_4x4)
    leog = modality(sim, "leog")
    place(sim, 0j, 0.0, humans=[-0.75 - 0.6j])
    # Facing +x: row 0 is x = 0.75 (ahead), column 0 is y = 0.75 (left). The box covers the
    # centres (0.75, 0.75) and (0.75, 0.25); the human covers only (-0.75, -0.75); the robot
    # itself is not drawn.
    expected = np.array([[1, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1]], dtype=np.uint8) * 255
    np.testing.assert_array_equal(leog.observe(sim), expected[None])
    # Facing +y: ahead is world +y and left is world -x, so the box is ahead-right and the
    # human behind-left.
    place(sim, 0j, math.pi / 2, humans=[-0.75 - 0.6j])
    expected = np.array([[0, 0, 0, 1], [0, 0, 0, 1], [0, 0, 0, 0], [1, 0, 0, 0]], dtype=np.uint8) * 255
    np.testing.assert_array_equal(leog.observe(sim), expected[None])


def test_leog_fills_polygons_with_holes_and_overlaps():
    # A square ring of walls (a polygon with a hole) and two overlapping boxes.
    ring = {"points": [[-3, -3], [3, -3], [3, 3], [-3, 3], [-3, -3]], "thickness": 0.4}
    boxes = [
        {"type": "rectangle", "center": [1.0, 1.0], "size": [1.0, 1.0]},
        {"type": "rectangle", "center": [1.4, 1.4], "size": [1.0, 1.0], "angle": 30},
    ]
    sim = make_sim(furniture=boxes, walls=[ring], sensors={"leog": {"size": 8.0, "resolution": 0.1}})
    leog = modality(sim, "leog")
    for heading in (0.0, 0.4, 2.0):
        place(sim, 0.13 - 0.07j, heading)
        assert_leog_matches_reference(sim, leog)


def test_leog_matches_a_point_in_shape_reference_on_real_states():
    sim = Simulator("room_furniture", {"humans.count": 20})
    leog = modality(sim, "leog")
    for _ in random_states(sim, 25, seed=2):
        assert_leog_matches_reference(sim, leog)


def cell_centres(sim: Simulator, leog) -> np.ndarray:
    """(H, W) complex world positions of the cell centres (row 0 ahead, column 0 left)."""
    n, res = leog.cells, leog.resolution
    x = (n / 2 - np.arange(n) - 0.5) * res
    local = x[:, None] + 1j * x[None, :]
    return sim.positions[0] + local * np.exp(1j * sim.robot_heading)


def assert_leog_matches_reference(sim: Simulator, leog) -> None:
    centres = cell_centres(sim, leog)
    polygons = shapely.union_all(sim.obstacles.polygons)
    inside = shapely.contains_xy(polygons, centres.real, centres.imag)
    discs = np.concatenate((sim.positions[1:], sim.obstacles.disc_center))
    radii = np.concatenate((sim.radii[1:], sim.obstacles.disc_radius))
    gap = np.abs(centres[..., None] - discs) - radii
    inside |= (gap < 0).any(-1)
    # exclude centres within rounding distance of an outline (ties may go either way)
    boundary = shapely.distance(polygons.boundary, shapely.points(centres.real, centres.imag))
    certain = (boundary > 1e-9) & (np.abs(gap) > 1e-9).all(-1)
    grid = leog.observe(sim)[0] > 0
    np.testing.assert_array_equal(grid[certain], inside[certain])


# ------------------------------------------------------------------- closest obstacle


def test_closest_obstacle_matches_shapelys_nearest_point_on_real_states():
    sim = Simulator("room_furniture", {"humans.count": 20})
    sensor = modality(sim, "closest_obstacle")
    assert sensor.frame == "polar"
    for _ in random_states(sim, 40, seed=3):
        offset = reference_nearest_offset(sim) * np.exp(-1j * sim.robot_heading)
        distance, sin, cos = sensor.observe(sim)
        if abs(offset) >= sensor.max_range:
            np.testing.assert_array_equal([distance, sin, cos], [sensor.max_range, 0, 1])
            continue
        assert distance == pytest.approx(abs(offset), abs=1e-6)
        np.testing.assert_allclose(distance * np.array([cos, sin]), [offset.real, offset.imag], atol=1e-6)


def reference_nearest_offset(sim: Simulator) -> complex:
    """Robot -> nearest obstacle point: shapely's nearest point of the polygons, exact disc surface points.

    Discs are kept exact (a shapely buffer would be a polygon approximating them); the two
    candidates are checked against shapely's polygonized discs to 1e-3 m.
    """
    robot = Point(sim.positions[0].real, sim.positions[0].imag)
    nearest = nearest_points(robot, shapely.union_all(sim.obstacles.polygons))[1]
    candidates = [complex(nearest.x - robot.x, nearest.y - robot.y)]
    centres = np.concatenate((sim.positions[1:], sim.obstacles.disc_center))
    radii = np.concatenate((sim.radii[1:], sim.obstacles.disc_radius))
    for centre, radius in zip(centres, radii, strict=True):
        to_centre = complex(centre) - complex(sim.positions[0])
        candidates.append(to_centre * (1 - radius / abs(to_centre)))
    best = min(candidates, key=abs)
    polygonized = shapely.union_all(static_shapes(sim) + human_shapes(sim))
    assert abs(best) == pytest.approx(robot.distance(polygonized), abs=1e-3)
    return best


def test_closest_obstacle_is_exact_against_polygons():
    document = load_scenario("room_furniture").model_dump(mode="json")
    document["furniture"] = [item for item in document["furniture"] if item["type"] != "circle"]
    document["humans"]["count"] = 0
    sim = Simulator(load_scenario(document))
    sim.reset(seed=0)
    sensor = modality(sim, "closest_obstacle")
    polygons = shapely.union_all(sim.obstacles.polygons)
    rng = np.random.default_rng(4)
    checked = 0
    for robot in rng.uniform(-5, 5, size=40) + 1j * rng.uniform(-5, 5, size=40):
        point = Point(robot.real, robot.imag)
        if polygons.contains(point):
            continue
        place(sim, robot, float(rng.uniform(-math.pi, math.pi)))
        nearest = nearest_points(point, polygons)[1]
        offset = complex(nearest.x - robot.real, nearest.y - robot.imag) * np.exp(-1j * sim.robot_heading)
        distance, sin, cos = sensor.observe(sim)
        assert distance == pytest.approx(abs(offset), abs=1e-6)
        np.testing.assert_allclose([sin, cos], [offset.imag / abs(offset), offset.real / abs(offset)], atol=1e-6)
        checked += 1
    assert checked > 25


def test_closest_obstacle_reports_max_range_at_bearing_zero_when_nothing_is_near():
    sim = make_sim(furniture=[WALL], sensors={"closest_obstacle": {"max_range": 1.5}})
    place(sim, -5.0 + 0j, 1.0)  # the wall is 7 m away
    np.testing.assert_array_equal(modality(sim, "closest_obstacle").observe(sim), np.array([1.5, 0, 1], dtype=np.float32))
    sim = make_sim(furniture=[WALL], sensors={"closest_obstacle": {"max_range": 1.5, "frame": "cartesian"}})
    place(sim, -5.0 + 0j, 1.0)
    np.testing.assert_array_equal(modality(sim, "closest_obstacle").observe(sim), np.array([1.5, 0], dtype=np.float32))


def test_closest_obstacle_cartesian_points_at_the_human_surface():
    sim = make_sim(humans=1, sensors={"closest_obstacle": {"frame": "cartesian"}})
    place(sim, 1.0 + 1.0j, math.pi / 2, humans=[1.0 + 3.0j])  # human 2 m straight ahead
    np.testing.assert_allclose(modality(sim, "closest_obstacle").observe(sim), [2.0 - HUMAN_RADIUS, 0.0], atol=1e-6)


# ------------------------------------------------------------------------- invariance


def test_moving_the_whole_world_with_the_robot_leaves_the_observations_unchanged():
    sensors = {"leog": {"size": 6.0, "resolution": 0.1}, "closest_obstacle": {"max_range": 10.0}}
    layout = {
        "furniture": [
            {"type": "rectangle", "center": [2.0, 1.0], "size": [1.2, 0.6], "angle": 25},
            {"type": "polygon", "points": [[-2.5, -1.0], [-1.0, -1.2], [-1.4, 0.3], [-2.2, 0.1]]},
            {"type": "circle", "center": [0.3, -2.0], "radius": 0.5},
        ],
        "walls": [{"points": [[-3.0, 2.5], [0.0, 3.0], [2.5, 2.6]], "thickness": 0.2}],
        "robot": 0.2 + 0.1j,
        "heading": 0.3,
        "goal": 4.0 - 3.0j,
        "humans": [1.0 - 1.0j, -0.5 + 1.5j, 2.6 + 0.2j],
    }
    keys = ["goal", "closest_obstacle", "lidar", "leog"]
    base, base_obs = observe_layout(layout, sensors, keys)
    rotation, shift = 1.1, 3.0 - 2.0j
    moved, moved_obs = observe_layout(transform_layout(layout, rotation, shift), sensors, keys)
    for key in ("goal", "closest_obstacle", "lidar"):
        np.testing.assert_allclose(moved_obs[key], base_obs[key], atol=1e-6, err_msg=key)
    changed = moved_obs["leog"][0] != base_obs["leog"][0]
    leog = modality(base, "leog")
    cut = cells_cut_by_an_outline(base, leog)
    assert not np.any(changed & ~cut)
    assert base_obs["leog"].any()


def observe_layout(layout, sensors, keys):
    sim = make_sim(furniture=layout["furniture"], walls=layout["walls"], humans=len(layout["humans"]), sensors=sensors)
    place(sim, layout["robot"], layout["heading"], humans=layout["humans"])
    sim.robot_goal = layout["goal"]
    built = build_modalities(keys, sim.world, sim.scenario.sensors)
    return sim, {key: m.observe(sim) for key, m in built.items()}


def transform_layout(layout, rotation: float, shift: complex):
    turn = np.exp(1j * rotation)
    move = lambda z: complex(z) * turn + shift  # noqa: E731
    move_xy = lambda xy: [move(complex(*xy)).real, move(complex(*xy)).imag]  # noqa: E731
    furniture = []
    for item in layout["furniture"]:
        item = dict(item)
        if "points" in item:
            item["points"] = [move_xy(xy) for xy in item["points"]]
        else:
            item["center"] = move_xy(item["center"])
        if item["type"] == "rectangle":
            item["angle"] = item.get("angle", 0.0) + math.degrees(rotation)
        furniture.append(item)
    walls = [dict(wall, points=[move_xy(xy) for xy in wall["points"]]) for wall in layout["walls"]]
    return {
        "furniture": furniture,
        "walls": walls,
        "robot": move(layout["robot"]),
        "heading": layout["heading"] + rotation,
        "goal": move(layout["goal"]),
        "humans": [move(z) for z in layout["humans"]],
    }


def cells_cut_by_an_outline(sim: Simulator, leog) -> np.ndarray:
    """(H, W) bool: grid cells (as squares) that an obstacle outline passes through."""
    half = leog.resolution / 2
    corners = np.array([-half - half * 1j, half - half * 1j, half + half * 1j, -half + half * 1j]) * np.exp(1j * sim.robot_heading)
    squares = cell_centres(sim, leog).ravel()[:, None] + corners
    cells = shapely.polygons(np.stack((squares.real, squares.imag), axis=-1))
    outline = shapely.union_all(static_shapes(sim) + human_shapes(sim)).boundary
    return shapely.intersects(cells, outline).reshape(leog.cells, leog.cells)


def test_an_empty_world_reads_free_everywhere():
    sim = make_sim()
    place(sim, 1.0 + 2.0j, 0.7)
    observation = {key: m.observe(sim) for key, m in build_modalities(["closest_obstacle", "lidar", "leog"], sim.world, sim.scenario.sensors).items()}
    np.testing.assert_array_equal(observation["closest_obstacle"], np.array([10.0, 0.0, 1.0], dtype=np.float32))
    np.testing.assert_array_equal(observation["lidar"], np.ones(360, dtype=np.float32))
    assert not observation["leog"].any()


def test_humans_only_world_matches_the_references():
    sim = make_sim(humans=3, sensors={"leog": {"size": 4.0, "resolution": 0.1}})
    place(sim, 0j, -0.4, humans=[1.0 + 0.2j, -0.7 - 1.1j, 0.3 + 1.6j])
    lidar, leog = modality(sim, "lidar"), modality(sim, "leog")
    np.testing.assert_allclose(lidar.ranges(sim), brute_force_ranges(sim, lidar.angles, lidar.max_range), atol=1e-9)
    assert_leog_matches_reference(sim, leog)
    assert (leog.observe(sim) > 0).sum() > 3 * 20  # each disc of radius 0.3 covers about 28 cells


def test_sensors_follow_the_crowd_size_across_resets():
    sim = Simulator("room_furniture", {"humans.count": [0, 12]})
    lidar, leog = modality(sim, "lidar"), modality(sim, "leog")
    sizes = set()
    for seed in range(8):
        sim.reset(seed=seed)
        sizes.add(sim.n_humans)
        np.testing.assert_allclose(lidar.ranges(sim), brute_force_ranges(sim, lidar.angles, lidar.max_range), atol=1e-9)
        assert_leog_matches_reference(sim, leog)
    assert len(sizes) > 2
