"""Groups that walk together (``walk_together``; Moussaïd et al. 2010's group terms): cohesion, shared goals, formations."""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav import Simulator
from crowdnav.scenario.crowd import GroupForce
from crowdnav.scenario.errors import ScenarioError
from crowdnav.scenario.library import library_names
from crowdnav.sim import forces as sf
from crowdnav.worlds.compiled import load_world
from tests.core.test_vector_env import check_batch_equals_singles


def open_square(together: bool, count: int = 3, **group: object) -> dict[str, object]:
    """One group of ``count`` in 30 m x 30 m of open space, goals anywhere within 12 m of the centre."""
    return {
        "description": "one group walking between random goals in open space",
        "world": {"min": [-15, -15], "max": [15, 15], "boundary_walls": False},
        "robot": {"start": {"type": "rectangle", "min": [-14, -14], "max": [-13, -13]},
                  "goal": {"type": "rectangle", "min": [13, 13], "max": [14, 14]}},
        "humans": {"groups": [{"name": "friends", "count": count, "walk_together": together,
                               "spawn": [{"type": "rectangle", "min": [-3, -3], "max": [3, 3]}],
                               "goal": [{"type": "rectangle", "min": [-12, -12], "max": [12, 12]}], **group}]},
        "max_steps": 2000,
    }


def pillar_hall() -> dict[str, object]:
    """A group of 3 walking east along y = 0 straight at a 0.5 m pillar at the origin."""
    return {
        "description": "a walking group passes a pillar",
        "world": {"min": [-12, -5], "max": [12, 5]},
        "furniture": [{"type": "circle", "name": "pillar", "center": [0, 0], "radius": 0.5}],
        "robot": {"start": {"type": "rectangle", "min": [-11, 4], "max": [-10.5, 4.5]},
                  "goal": {"type": "rectangle", "min": [10.5, 4], "max": [11, 4.5]}},
        "humans": {"groups": [{"name": "friends", "count": 3, "walk_together": True, "preferred_speed": [1.0, 1.1],
                               "spawn": [{"type": "rectangle", "min": [-8, -0.3], "max": [-7.5, 0.3]}],
                               "goal": [{"type": "rectangle", "min": [9, -0.2], "max": [9.5, 0.2]}]}]},
        "max_steps": 1000,
    }


def _spread(sim: Simulator, steps: int) -> np.ndarray:
    """The farthest member's distance (m) from the humans' centroid after each of ``steps`` steps."""
    out = np.empty(steps)
    for t in range(steps):
        sim.step(np.zeros(2))
        humans = sim.human_positions
        out[t] = np.abs(humans - humans.mean()).max()
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_group_of_three_stays_within_one_and_a_half_metres_of_its_centroid_while_independent_walkers_drift_apart(seed):
    together = Simulator(open_square(True))
    together.reset(seed=seed)
    assert _spread(together, 300).max() < 1.5
    apart = Simulator(open_square(False))
    apart.reset(seed=seed)
    assert _spread(apart, 300)[-100:].max() > 4.0


def test_a_group_shares_one_goal_reached_by_its_centre_and_takes_the_next_goal_together():
    sim = Simulator(open_square(True, 4))
    sim.reset(seed=2)
    goals = [sim.human_goals.copy()]
    tolerance = sim.scenario.humans.social_force.goal_tolerance
    for _ in range(2000):
        before = sim.human_goals.copy()
        sim.step(np.zeros(2))
        assert len(set(sim.human_goals.tolist())) == 1  # one goal for the group, always
        if sim.human_arrived.any():
            assert sim.human_arrived.all()  # the whole group arrives at once
            assert abs(sim.human_positions.mean() - before[0]) <= tolerance  # by its centre, not by one member
            goals.append(sim.human_goals.copy())
    assert len(goals) > 10 and sim.human_stalls.sum() == 0


def test_a_stalled_member_gives_the_whole_group_a_new_goal():
    sim = Simulator(open_square(True, 3), {"humans.stall.time": 2.0})
    sim.reset(seed=0)
    goal = sim.human_goals.copy()
    for _ in range(10):  # held still by zero actions: no progress in the first window
        sim.step(np.zeros(2), human_actions=np.zeros((3, 2)))
    assert sim.human_stalls.sum() >= 1
    assert len(set(sim.human_goals.tolist())) == 1 and sim.human_goals[0] != goal[0]
    assert np.isinf(sim.human_stall_mark).all()  # every member's window starts again


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_a_group_opens_around_a_pillar_and_re_forms_behind_it(seed):
    sim = Simulator(pillar_hall())
    sim.reset(seed=seed)
    centre, spread, sides = [], [], None
    for _ in range(120):
        sim.step(np.zeros(2))
        humans = sim.human_positions
        centre.append(humans.mean().real)
        spread.append(np.abs(humans - humans.mean()).max())
        if sides is None and humans.mean().real > 0:
            sides = np.sign(humans.imag)  # who passes on which side, as the centre passes the pillar
    centre, spread = np.array(centre), np.array(spread)
    assert sides is not None and (sides > 0).any() and (sides < 0).any()  # it opened: the pillar went between members
    before, behind = spread[centre < -3].max(), spread[centre > 3]
    assert len(behind) > 10 and behind[-10:].max() < before + 0.1  # and closed again behind it


def test_batch_equals_singles_with_a_group_walking_together_by_the_mirror_rule():
    world = load_world(open_square(True, [2, 4], goal_rule="mirror", goal=[], mirror_center=[0.5, -0.5]), {"humans.stall.time": 3.0})
    check_batch_equals_singles(world, worlds=5, first_seed=3, steps=150, rng_seed=2, scale=1.0)


def test_group_force_kernel_gives_the_papers_terms_on_a_hand_built_trio():
    params = GroupForce()
    # members 0, 1, 2 of group 1; human 3 walks alone (group 0). Member 2 lags 2 m behind, walking away from the others.
    positions = np.array([0.0, 0.5j, -2.0 + 0.25j, 5.0])
    velocities = np.array([1.0, 1.0, -1.0, 1.0])
    group = np.array([1, 1, 1, 0])
    member = np.array([True, True, True, False])
    force = sf.group_force(positions, velocities, np.ones(4), member, group, 2, params, relaxation_time=0.5)
    centre = positions[:3].mean()
    assert force[3] == 0
    # member 2: 1.33 m from the centre > (3 - 1) * 0.5: attracted; it looks 180 deg away from the centre: gaze slows it (pi - pi/2)
    expected = 3.0 * (centre - positions[2]) / abs(centre - positions[2]) - 4.0 * (np.pi / 2) * velocities[2]
    assert force[2] == pytest.approx(0.5 * expected)
    # members 0 and 1: 0.5 m apart < d0 = 0.8 m: pushed apart (unit vectors), both within 1 m of the centre; the centre
    # is behind them beyond the vision field, so the gaze slows them too
    angle0 = abs(np.angle((centre - positions[0]) / velocities[0]))
    assert force[0] == pytest.approx(0.5 * (-1.0j - 4.0 * (angle0 - np.pi / 2) * velocities[0]))
    # the same world twice as a batch of two worlds gives the same bits
    batch = sf.group_force(np.stack([positions, positions]), np.stack([velocities, velocities]), np.ones((2, 4)),
                           np.stack([member, member]), np.stack([group, group]), 2, params, relaxation_time=0.5)
    assert batch[0].tobytes() == force.tobytes() and batch[1].tobytes() == force.tobytes()


@pytest.mark.parametrize(("overrides", "message"), [
    ({"humans.groups.0.on_goal": "respawn"}, "humans.groups.0: a group that walks together cannot respawn one by one"),
    ({"humans.groups.0.model": "orca"}, "humans.groups.0.walk_together: a group walks together by the social-force group terms"),
    ({"humans.groups.0.behaviour": "stand", "humans.groups.0.goal": [], "humans.groups.0.preferred_speed": None},
     "a standing group does not walk; remove walk_together"),
    ({"humans.group_force.vision_angle": 0}, "humans.group_force.vision_angle: expected a number > 0"),
    ({"humans.group_force.repulsion_distance": -1}, "humans.group_force.repulsion_distance: expected a number > 0"),
    ({"humans.group_force.gaze": 4}, "humans.group_force.gaze"),
])
def test_bad_walking_group_fields_are_refused_in_one_line(overrides, message):
    with pytest.raises(ScenarioError) as caught:
        load_world(open_square(True), overrides)
    text = str(caught.value).strip()
    assert message in text and "\n" not in text


@pytest.mark.parametrize("name", library_names())
def test_library_groups_that_walk_together_start_on_their_circle_with_one_goal(name):
    sim = Simulator(name)
    if sim.together is None:
        pytest.skip(f"{name} has no group that walks together")
    for seed in range(5):
        sim.reset(seed=seed)
        for g in np.flatnonzero(sim.together):
            mine = sim.human_group == g
            if mine.sum() < 2:
                continue
            assert len(set(sim.human_goals[mine].tolist())) == 1
            members = sim.human_positions[mine]
            assert np.abs(members - members.mean()).max() < 1.0


def test_the_renderer_links_the_members_of_a_group_that_walks_together_in_its_darkened_colour():
    pytest.importorskip("pygame")
    from crowdnav.rendering.group_links import group_links
    from crowdnav.rendering.renderer import Renderer

    alone = {"humans.groups.4.walk_together": False}  # station_hall's friends walk alone here: only the shoppers are linked
    sim = Simulator("station_hall", {**alone, "humans.groups.1.walk_together": True, "humans.groups.1.count": 2,
                                     "humans.groups.1.colour": "#ff0000"})
    sim.reset(seed=0)
    renderer = Renderer(sim)
    links = group_links(sim, renderer._group_colours)
    assert len(links) == 1 and links[0][0] == (153, 0, 0) and not links[0][2]  # two members: one open segment
    a, b = links[0][1]
    frame = renderer.frame()
    x, y = np.round(renderer.to_pixels((a + b) / 2)).astype(int)  # the middle of the link, between the two discs
    assert (frame[y - 1 : y + 2, x - 1 : x + 2] == (153, 0, 0)).all(axis=-1).any()
    assert group_links(Simulator("station_hall", alone), renderer._group_colours) == []  # no group walks together: nothing linked
