"""Behaviour of the simulator: human motion, collisions, kinematics, determinism."""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest
import shapely
from shapely.geometry import Point

from crowdnav import Simulator


def scenario(**changes) -> dict:
    """An open 12 m x 12 m world with a robot parked in a corner and no humans; tests add what they need."""
    base = {
        "description": "test world",
        "world": {"min": [-6, -6], "max": [6, 6], "boundary_walls": False},
        "robot": {
            "radius": 0.25,
            "start": {"type": "points", "points": [[-5.5, 5.5]]},
            "goal": {"type": "points", "points": [[5.5, 5.5]]},
        },
        "time_step": 0.2,
        "max_steps": 400,
    }
    for key, value in changes.items():
        base[key] = value
    return base


def lone_humans(spawn, goal, **extra) -> dict:
    return {
        "count": len(spawn),
        "radius": 0.25,
        "preferred_speed": [1.0, 1.0],
        "spawn": [{"type": "points", "points": spawn}],
        "goal": [{"type": "points", "points": goal}],
        **extra,
    }


def place(sim: Simulator, humans: list[complex], goals: list[complex]) -> None:
    """Put humans exactly where a test wants them (the draw from points regions is random)."""
    sim.positions[1:] = humans
    sim.human_goals[:] = goals
    sim.velocities[:] = 0
    sim.refresh()


def run_humans(sim: Simulator, steps: int) -> np.ndarray:
    """Positions of the humans over ``steps`` steps with the robot standing still; shape (steps, n)."""
    out = []
    for _ in range(steps):
        sim.step(np.zeros(2))
        out.append(sim.human_positions.copy())
    return np.array(out)


def test_lone_human_reaches_its_goal_and_stops():
    sim = Simulator(scenario(humans=lone_humans([[-3, -3]], [[3, 3]], on_goal="stop")))
    sim.reset(seed=0)
    place(sim, [-3 - 3j], [3 + 3j])
    track = run_humans(sim, 100)
    final = track[-1, 0]
    assert abs(final - (3 + 3j)) <= sim.scenario.humans.social_force.goal_tolerance
    assert sim.human_stopped[0]
    speeds = np.abs(np.diff(track[:, 0])) / sim.dt
    assert speeds.max() <= sim.human_max_speed[0] + 1e-9


def test_two_humans_walking_head_on_pass_each_other_without_overlapping():
    humans = lone_humans([[-3, 0.05], [3, -0.05]], [[3, 0.05], [-3, -0.05]], on_goal="stop")
    sim = Simulator(scenario(humans=humans))
    sim.reset(seed=0)
    place(sim, [-3 + 0.05j, 3 - 0.05j], [3 + 0.05j, -3 - 0.05j])
    track = run_humans(sim, 120)
    gap = np.abs(track[:, 0] - track[:, 1])
    assert gap.min() >= 2 * 0.25 - 1e-9, "humans overlapped"
    assert np.all(np.abs(track[-1] - np.array([3 + 0.05j, -3 - 0.05j])) <= 0.3), "they did not get past each other"
    assert np.abs(track[:, 0].imag).max() > 0.2, "no sidestep: they must deviate to pass"


def test_human_walking_towards_a_wall_is_deflected_and_never_enters_it():
    # The straight line from start to goal crosses the wall's upper end, so the human must bend around it.
    wall = {"points": [[0, -2], [0, 0.5]], "thickness": 0.2}
    humans = lone_humans([[-2, -0.5]], [[2, 1.2]], on_goal="stop")
    sim = Simulator(scenario(humans=humans, walls=[wall]))
    sim.reset(seed=0)
    place(sim, [-2 - 0.5j], [2 + 1.2j])
    wall_shape = sim.obstacles.polygons[0]
    track = run_humans(sim, 150)[:, 0]
    clearance = shapely.distance(wall_shape, shapely.points(track.real, track.imag))
    assert clearance.min() >= 0.25 - 1e-9, "the human's disc entered the wall"
    crossing = track[np.argmin(np.abs(track.real))]  # where it passes the wall's line x = 0
    assert crossing.imag > 0.5 + 0.1 + 0.25 - 1e-6, "it must pass above the wall's end, deflected"
    assert abs(track[-1] - (2 + 1.2j)) <= sim.scenario.humans.social_force.goal_tolerance


def test_human_heading_straight_into_a_long_wall_stops_against_it_without_entering():
    # The social-force model has no path planning: a goal straight behind a long wall is a local minimum.
    wall = {"points": [[0, -3], [0, 3]], "thickness": 0.2}
    sim = Simulator(scenario(humans=lone_humans([[-2, 0]], [[2, 0]]), walls=[wall]))
    sim.reset(seed=0)
    place(sim, [-2 + 0j], [2 + 0j])
    track = run_humans(sim, 100)[:, 0]
    clearance = shapely.distance(sim.obstacles.polygons[0], shapely.points(track.real, track.imag))
    assert clearance.min() >= 0.25 - 1e-9
    assert track[-1].real < -0.1 - 0.25 + 1e-9


def test_robot_human_collision_is_detected_exactly_at_the_contact_distance():
    sim = Simulator(scenario(humans=lone_humans([[3, 3]], [[3, 4]])))
    sim.reset(seed=0)
    sim.positions[0] = 0j
    sim.positions[1] = 0.5 + 0j  # radii 0.25 + 0.25: touching
    sim.refresh()
    collision = sim.robot_collision()
    assert collision is not None and collision.kind == "human" and collision.partner == "human_0"
    assert collision.surface_distance == 0.0
    sim.positions[1] = 0.5 + 1e-9 + 0j
    sim.refresh()
    assert sim.robot_collision() is None


def test_robot_wall_collision_is_detected_exactly_at_the_contact_distance():
    table = {"type": "rectangle", "name": "box", "center": [1.5, 0.0], "size": [1.0, 2.0]}
    sim = Simulator(scenario(furniture=[table]))
    sim.reset(seed=0)
    sim.positions[0] = 0.75 + 0j  # radius 0.25, box face at x = 1.0
    sim.refresh()
    collision = sim.robot_collision()
    assert collision is not None and collision.kind == "static" and "box" in collision.partner
    assert collision.surface_distance == 0.0
    sim.positions[0] = 0.75 - 1e-9 + 0j
    sim.refresh()
    assert sim.robot_collision() is None


def test_robot_touching_a_round_table_collides_and_step_reports_it():
    table = {"type": "circle", "name": "round", "center": [0.0, 0.0], "radius": 0.5}
    sim = Simulator(scenario(furniture=[table]))
    sim.reset(seed=0)
    sim.robot_heading = 0.0
    sim.positions[0] = -0.9 + 0j  # 0.15 m from the table's surface, moving 0.2 m this step
    sim.refresh()
    events = sim.step(np.array([1.0, 0.0]))
    assert events.collision is not None and "round" in events.collision.partner
    assert events.outcome == "collision" and events.terminated


def drive_up_until_the_end(sim: Simulator, limit: int = 20) -> list:
    """Drive the robot (parked at y = 5.5, 0.5 m below the top of the world) straight up; the events of every step."""
    sim.robot_heading = 0.0
    events = []
    while not events or not (events[-1].terminated or events[-1].truncated):
        assert len(events) < limit, "the robot drove on past the world's edge"
        events.append(sim.step(np.array([0.0, 1.0])))  # holonomic, heading 0: +y in the world
    return events


def test_robot_leaving_an_open_world_ends_the_episode_out_of_bounds_on_the_step_it_crosses():
    sim = Simulator(scenario())  # boundary_walls false, world y <= 6
    sim.reset(seed=0)
    events = drive_up_until_the_end(sim)
    assert all(e.outcome is None and not e.left_world for e in events[:-1])
    last = events[-1]
    assert last.left_world and last.outcome == "out_of_bounds" and last.terminated and not last.truncated
    assert last.collision is None and not last.goal_reached
    assert sim.robot_position.imag > 6.0 and sim.robot_position.imag - sim.scenario.robot.max_speed * sim.dt <= 6.0
    assert len(events) == 3  # 5.5 -> 5.7 -> 5.9 -> 6.1


def test_robot_exactly_on_the_world_edge_is_still_inside():
    sim = Simulator(scenario())
    sim.reset(seed=0)
    sim.positions[0] = 6.0 + 6.0j
    assert not sim.robot_left_world()
    sim.positions[0] = 6.0 + 6.0000001j
    assert sim.robot_left_world()
    sim.positions[0] = -6.0000001 + 0j
    assert sim.robot_left_world()


def test_with_boundary_walls_the_same_drive_ends_in_a_static_collision_inside_the_world():
    sim = Simulator(scenario(world={"min": [-6, -6], "max": [6, 6], "boundary_walls": True}))
    sim.reset(seed=0)
    events = drive_up_until_the_end(sim)
    last = events[-1]
    assert last.outcome == "collision" and last.collision.kind == "static" and "boundary" in last.collision.partner
    assert not last.left_world and not sim.robot_left_world()  # leaving is impossible: the wall is hit first
    assert sim.robot_position.imag <= 6.0


def test_outcome_precedence_is_collision_then_out_of_bounds_then_success_then_truncated():
    from crowdnav.sim.simulator import OUTCOMES, Collision, StepEvents

    hit = Collision("human", "human_0", 0.0)
    assert StepEvents(goal_reached=True, collision=hit, truncated=True, left_world=True).outcome == "collision"
    assert StepEvents(goal_reached=True, collision=None, truncated=True, left_world=True).outcome == "out_of_bounds"
    assert StepEvents(goal_reached=True, collision=None, truncated=True, left_world=False).outcome == "success"
    assert StepEvents(goal_reached=False, collision=None, truncated=True).outcome == "truncated"
    assert StepEvents(goal_reached=False, collision=None, truncated=False).outcome is None
    left = StepEvents(goal_reached=False, collision=None, truncated=False, left_world=True)
    assert left.terminated and not left.truncated
    assert OUTCOMES == ("success", "collision", "out_of_bounds", "truncated")


def test_holonomic_action_is_a_velocity_in_the_robot_frame_with_capped_norm():
    sim = Simulator(scenario())
    sim.reset(seed=0)
    sim.robot_heading = math.pi / 2
    start = sim.robot_position
    sim.step(np.array([1.0, 0.0]))  # forward = +y in the world
    assert sim.robot_position == pytest.approx(start + 1j * sim.scenario.robot.max_speed * sim.dt, abs=1e-12)
    before = sim.robot_position
    sim.step(np.array([1.0, 1.0]))  # diagonal: norm capped at max speed
    moved = sim.robot_position - before
    assert abs(moved) == pytest.approx(sim.scenario.robot.max_speed * sim.dt, abs=1e-12)
    assert cmath.phase(moved) == pytest.approx(math.pi / 2 + math.pi / 4, abs=1e-12)
    assert sim.robot_heading == math.pi / 2


def test_unicycle_follows_the_exact_arc_formula():
    robot = {
        "radius": 0.25,
        "kinematics": "unicycle",
        "max_speed": 1.0,
        "max_angular_speed": 2.0,
        "start": {"type": "points", "points": [[0, 0]]},
        "goal": {"type": "points", "points": [[5, 5]]},
    }
    sim = Simulator(scenario(robot=robot))
    sim.reset(seed=0)
    sim.robot_heading = theta = 0.3
    x, y = sim.robot_position.real, sim.robot_position.imag
    sim.step(np.array([0.8, 0.5]))
    v, w, dt = 0.8, 1.0, sim.dt
    expected_x = x + v / w * (math.sin(theta + w * dt) - math.sin(theta))
    expected_y = y - v / w * (math.cos(theta + w * dt) - math.cos(theta))
    assert sim.robot_position.real == pytest.approx(expected_x, abs=1e-12)
    assert sim.robot_position.imag == pytest.approx(expected_y, abs=1e-12)
    assert sim.robot_heading == pytest.approx(theta + w * dt, abs=1e-12)
    before = sim.robot_position
    sim.step(np.array([-0.5, 0.0]))  # no turn: straight line backwards
    heading = sim.robot_heading
    assert sim.robot_position == pytest.approx(before - 0.5 * dt * cmath.exp(1j * heading), abs=1e-12)


def test_actions_outside_the_box_are_clipped_and_non_finite_actions_are_rejected():
    sim = Simulator(scenario())
    sim.reset(seed=0)
    sim.robot_heading = 0.0
    before = sim.robot_position
    sim.step(np.array([5.0, 0.0]))
    assert abs(sim.robot_position - before) == pytest.approx(sim.scenario.robot.max_speed * sim.dt)
    with pytest.raises(ValueError, match="finite"):
        sim.step(np.array([np.nan, 0.0]))


def run_episode(sim: Simulator, seed: int, steps: int = 200) -> list[np.ndarray]:
    actions = np.random.default_rng(1234).uniform(-1, 1, size=(steps, 2))
    sim.reset(seed=seed)
    frames = [sim.positions.copy()]
    for action in actions:
        events = sim.step(action)
        frames.append(np.concatenate([sim.positions, sim.velocities, sim.human_goals]))
        if events.terminated or events.truncated:
            sim.reset()
    return frames


def test_same_seed_reproduces_an_episode_bit_for_bit_and_another_seed_does_not():
    first = run_episode(Simulator("room_furniture"), seed=7)
    second = run_episode(Simulator("room_furniture"), seed=7)
    other = run_episode(Simulator("room_furniture"), seed=8)
    assert all(np.array_equal(a, b) for a, b in zip(first, second, strict=True))
    assert not np.array_equal(first[0], other[0])


def test_crowd_size_range_is_sampled_per_episode_within_bounds():
    sim = Simulator("room_furniture", overrides={"humans.count": [2, 6]})
    sizes = set()
    for seed in range(30):
        sim.reset(seed=seed)
        sizes.add(sim.n_humans)
        assert len(sim.human_goals) == sim.n_humans == len(sim.positions) - 1
    assert sizes <= set(range(2, 7)) and len(sizes) >= 3


def test_reset_places_everyone_apart_and_clear_of_obstacles_at_high_density():
    sim = Simulator("room_furniture", overrides={"humans.count": 60})
    union = sim.obstacles.union
    for seed in range(20):
        sim.reset(seed=seed)
        z = sim.positions
        gaps = np.abs(z[:, None] - z[None, :]) - (sim.radii[:, None] + sim.radii[None, :])
        np.fill_diagonal(gaps, np.inf)
        assert gaps.min() > 0
        clearance = shapely.distance(union, shapely.points(z.real, z.imag))
        assert np.all(clearance > sim.radii)
        assert abs(sim.robot_goal - z[0]) >= sim.scenario.robot.min_start_goal_distance


def test_humans_take_new_goals_or_respawn_when_they_arrive():
    spawn = [[-4, -4], [-4, 4], [4, -4], [4, 4]]
    new_goal = Simulator(scenario(humans=lone_humans(spawn, [[0, 0]], on_goal="new_goal")))
    new_goal.reset(seed=0)
    new_goal.positions[1] = 0.1 + 0j  # within tolerance of its goal
    new_goal.human_goals[0] = 0j
    new_goal.refresh()
    new_goal.step(np.zeros(2))
    assert new_goal.human_goals[0] == 0j  # the only goal point: drawn again (with replacement)

    respawn = Simulator(scenario(humans=lone_humans(spawn[:1], [[0, 0]], on_goal="respawn")))
    respawn.reset(seed=0)
    respawn.positions[1] = 0.1 + 0j
    respawn.human_goals[0] = 0j
    respawn.refresh()
    respawn.step(np.zeros(2))
    assert respawn.human_positions[0] == -4 - 4j and respawn.human_velocities[0] == 0


def test_external_human_actions_drive_humans_and_are_validated():
    sim = Simulator(scenario(humans=lone_humans([[0, 0]], [[3, 0]])))
    sim.reset(seed=0)
    before = sim.human_positions.copy()
    sim.step(np.zeros(2), human_actions=np.array([[0.0, 1.0]]))
    assert sim.human_positions[0] == pytest.approx(before[0] + 1j * sim.human_max_speed[0] * sim.dt)
    with pytest.raises(ValueError, match="shape"):
        sim.step(np.zeros(2), human_actions=np.zeros((2, 2)))


def test_humans_ignore_the_robot_unless_see_robot_is_on():
    def push_from_robot(see_robot: bool) -> complex:
        sim = Simulator(scenario(humans=lone_humans([[0, 0]], [[0, 0]], see_robot=see_robot)))
        sim.reset(seed=0)
        sim.positions[0] = -0.6 + 0j
        sim.positions[1] = 0j
        sim.human_goals[0] = 0j
        sim.refresh()
        return sim.social_force_commands()[0]

    assert push_from_robot(False) == 0
    assert push_from_robot(True).real > 0  # pushed away from the robot, along +x


def test_social_force_on_the_robot_grows_as_humans_get_closer():
    sim = Simulator(scenario(humans=lone_humans([[0, 0]], [[0, 0]])))
    sim.reset(seed=0)
    magnitudes = []
    for distance in (3.0, 1.5, 0.8):
        sim.positions[0] = 0j
        sim.positions[1] = distance
        sim.refresh()
        magnitudes.append(abs(sim.robot_social_force))
        assert sim.robot_social_force.real < 0  # pushes the robot away from the human
    assert magnitudes[0] < magnitudes[1] < magnitudes[2]


def test_step_before_reset_is_an_error():
    with pytest.raises(RuntimeError, match="reset"):
        Simulator(scenario()).step(np.zeros(2))


def test_no_obstacles_and_no_humans_still_steps():
    sim = Simulator(scenario())
    sim.reset(seed=3)
    events = sim.step(np.array([1.0, 0.0]))
    assert events.collision is None
    assert Point(sim.robot_position.real, sim.robot_position.imag).distance(Point(-5.5, 5.5)) > 0


@pytest.mark.parametrize("field", ["human_range", "obstacle_range", "robot_range"])
def test_force_ranges_below_one_centimetre_are_refused_with_the_field_named(field):
    from crowdnav import ScenarioError

    with pytest.raises(ScenarioError, match=rf"humans\.social_force\.{field}: expected a number >= 0\.01"):
        Simulator("open_space", overrides={f"humans.social_force.{field}": 5e-4})


def test_shortest_force_ranges_with_a_dense_crowd_keep_every_state_and_reward_finite():
    import gymnasium as gym

    ranges = {f"humans.social_force.{name}": 0.01 for name in ("human_range", "obstacle_range", "robot_range")}
    env = gym.make("crowdnav/RoomFurniture-v0", overrides={**ranges, "humans.count": 20, "humans.see_robot": True})
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(200):
        _, reward, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 2))
        sim = env.unwrapped.simulator
        assert np.isfinite(reward) and np.isfinite(sim.human_positions).all() and np.isfinite(sim.human_velocities).all()
        if terminated or truncated:
            env.reset()


def test_repulsion_gain_never_overflows_to_inf():
    from crowdnav.sim import forces as sf

    gain = sf.repulsion_gain(np.array([2.0]), np.array([1e6]), 1e-3)
    assert np.isfinite(gain).all()


@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")
def test_a_non_finite_state_stops_the_step_with_the_agent_named():
    from crowdnav import SimulationError

    sim = Simulator("open_space")
    sim.reset(seed=0)
    sim.human_goals[1] = complex(np.inf, 0.0)  # the goal force of human 1 becomes non-finite
    with pytest.raises(SimulationError, match=r"step 1: the position of human 1 became non-finite"):
        sim.step(np.zeros(2))
