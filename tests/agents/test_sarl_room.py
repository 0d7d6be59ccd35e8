"""The SARL-style agent that reads the room (the ``obstacles`` and ``geodesic`` modalities): its lookahead predicts
contact with walls and furniture and reads the distance to the goal around them, its value network pools the nearest
shapes beside the humans; it trains, acts, resumes and exports in every library scenario it drives, and an agent that
reads no obstacles warns where the floor has them."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

torch = pytest.importorskip("torch")

from crowdnav.agents.sarl.lookahead import Physics, action_set, decode, features, geodesic_at, lookahead  # noqa: E402

from crowdnav.scenario.library import library_names  # noqa: E402
from tests.agents.test_sarl import assert_acts  # noqa: E402

ROOM = ["humans", "goal", "velocity", "obstacles", "geodesic"]
WEIGHTS = {"step": -0.01, "goal_progress": 0.1, "social": 0.0, "goal_reached": 1.0, "collision": -1.0}
PHYSICS = Physics(0.3, 1.0, 0.2, 0.3, 0.0, 1.0, WEIGHTS)


def config(out, scenario="room_furniture", **fields):
    document = {"algo": "sarl", "scenario": scenario, "modalities": ROOM, "num_envs": 2, "episodes": 2, "seed": 0,
                "out": str(out), "overrides": {"max_steps": 8}, "checkpoint_every": 1, "progress": False,
                "algo_kwargs": {"batch_size": 4, "updates_per_episode": 2, "width": 16}}
    document.update(fields)
    return document


def state_with_wall(distance: float, grid: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """One joint state: goal 4 m ahead (+x), no human, a wall whose nearest point is ``distance`` m to the left (+y)."""
    observation = {"goal": np.array([[4.0, 0.0, 1.0]]), "velocity": np.zeros((1, 2)), "humans": np.zeros((1, 2, 6)),
                   "obstacles": np.array([[[0.0, distance, 1.0], [0.0, 0.0, 0.0]]])}
    if grid is not None:
        observation["geodesic"] = grid[None]
    return decode(observation, {})


def test_the_lookahead_ends_moves_into_a_wall_and_keeps_moves_along_it():
    actions = action_set(1.0)
    ahead = lookahead(state_with_wall(0.45), PHYSICS, actions)
    sideways = ahead["next"]["velocity"][0, :, 1] * 0.2  # metres moved toward the wall (+y)
    assert np.array_equal(ahead["done"][0], sideways >= 0.15 - 1e-12)  # clearance 0.45 - move <= radius 0.3
    hit = ahead["done"][0] & (sideways > 0.16)
    assert hit.any() and np.all(ahead["reward"][0][hit] < WEIGHTS["collision"] + 0.05)  # predicted: the collision's cost
    along = np.flatnonzero(np.abs(sideways) < 1e-9)
    assert not ahead["done"][0, along].any()
    # the wall's nearest point follows the robot along the wall: the same clearance after a move along it
    np.testing.assert_allclose(ahead["next"]["static"][0, along, 0], [[0.0, 0.45]] * len(along))


def test_a_wall_out_of_reach_of_one_step_changes_nothing_but_the_features():
    near, far = lookahead(state_with_wall(0.6), PHYSICS, action_set(1.0)), lookahead(state_with_wall(3.0), PHYSICS, action_set(1.0))
    np.testing.assert_array_equal(near["done"], far["done"])
    np.testing.assert_array_equal(near["reward"], far["reward"])
    assert not np.array_equal(features(near["next"], PHYSICS)[2], features(far["next"], PHYSICS)[2])


def test_geodesic_reads_the_grid_at_its_points_and_interpolates_between_them():
    grid = np.arange(81, dtype=np.float64).reshape(9, 9)  # value 9 i + j at offset ((i - 4) 0.1, (j - 4) 0.1)
    origins = np.array([[0.0, 0.0], [0.1, -0.2], [0.05, 0.05], [5.0, -5.0]])
    got = geodesic_at(np.broadcast_to(grid, (4, 9, 9)), origins, 0.1)
    np.testing.assert_allclose(got, [40.0, 9 * 5 + 2, 40.0 + 4.5 + 0.5, 9 * 8 + 0])  # the last one clamped to the edge


def test_the_robots_row_carries_the_geodesic_distance_where_the_move_leads():
    grid = np.repeat((4.0 - 0.1 * (np.arange(9) - 4))[:, None], 9, axis=1)  # falls by 0.1 m per 0.1 m toward +x
    state = state_with_wall(3.0, grid)
    robot, _, statics = features(state, PHYSICS)
    assert robot.shape == (1, 4) and statics.shape == (1, 2, 4)
    ahead = lookahead(state, PHYSICS, action_set(1.0))
    forward = int(np.argmax(ahead["next"]["velocity"][0, :, 0]))  # full speed toward the goal (+x): 0.2 m
    row = features(ahead["next"], PHYSICS)[0][0, forward]
    np.testing.assert_allclose(row[3], (4.0 - 0.2) * 0.25, rtol=1e-6)


@pytest.mark.parametrize("scenario", library_names())
def test_sarl_reading_the_room_trains_acts_and_resumes_in_every_library_scenario_or_refuses_in_one_line(tmp_path, scenario):
    from crowdnav.agents import load_policy, train

    from crowdnav.errors import CrowdNavError

    try:
        train(config(tmp_path / "run", scenario))
    except CrowdNavError as error:  # a robot it cannot drive, a map it cannot build: one line that says why
        assert "\n" not in str(error) and "holonomic" in str(error), str(error)
        return
    policy = load_policy(tmp_path / "run")
    assert policy.model.statics == 8 and policy.model.geodesic
    assert_acts(policy)
    train(config(tmp_path / "run", scenario, episodes=3), resume=True)
    assert load_policy(tmp_path / "run").model.episodes == 3


def test_a_resumed_run_that_reads_the_room_equals_the_uninterrupted_one(tmp_path):
    from crowdnav.agents import load_policy, train

    train(config(tmp_path / "whole", episodes=4, num_envs=1))
    train(config(tmp_path / "cut", episodes=2, num_envs=1))
    train(config(tmp_path / "cut", episodes=4, num_envs=1), resume=True)
    whole, cut = load_policy(tmp_path / "whole").model, load_policy(tmp_path / "cut").model
    for (name, a), (_, b) in zip(whole.network.state_dict().items(), cut.network.state_dict().items(), strict=True):
        assert torch.equal(a, b), name
    assert whole.memory.size == cut.memory.size and np.array_equal(whole.memory.statics, cut.memory.statics)


def test_an_agent_that_reads_no_obstacles_warns_in_a_furnished_room_and_not_in_open_space(tmp_path):
    from crowdnav.agents import train

    blind = ["humans", "goal", "velocity"]
    with pytest.warns(UserWarning, match="reads no walls nor furniture.*'obstacles'") as caught:
        train(config(tmp_path / "blind", modalities=blind, episodes=1))
    assert all("\n" not in str(item.message) for item in caught)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        train(config(tmp_path / "seeing", episodes=1))
        train(config(tmp_path / "open", scenario="open_space", modalities=blind, episodes=1))


def test_an_agent_that_reads_obstacles_but_not_the_world_edge_warns_where_leaving_the_world_ends_the_episode(tmp_path):
    from crowdnav.agents import train

    with pytest.warns(UserWarning, match="not the world's edge.*world_edge: true") as caught:
        train(config(tmp_path / "edgeless", scenario="open_space", episodes=1))
    assert all("\n" not in str(item.message) for item in caught)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        train(config(tmp_path / "edge", scenario="open_space", sensors={"obstacles": {"world_edge": True}}, episodes=1))


def test_onnx_export_of_an_agent_that_reads_the_room_acts_as_predict(tmp_path):
    ort = pytest.importorskip("onnxruntime", reason='the onnx extra (pip install -e ".[onnx]") runs the exported policies')
    from crowdnav.agents import load_policy, train

    from crowdnav.cli import main
    from tests.agents.agents_tiny import recorded_observations
    from tests.agents.test_sarl_export import check_choices

    run = tmp_path / "run"
    # a margin around people too: the exported lookahead carries it
    train(config(run, algo_kwargs={"batch_size": 4, "updates_per_episode": 2, "width": 16, "lookahead_depth": 2, "human_margin": 0.1}))
    out = tmp_path / "policy.onnx"
    assert main(["export", str(run), "--out", str(out)]) == 0
    policy = load_policy(run)
    observations = recorded_observations(policy, seed=1)
    session = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    assert sorted(i.name for i in session.get_inputs()) == sorted(observations) == sorted(ROOM)
    actions = session.run(["action"], observations)[0]
    assert check_choices(policy, observations, actions) <= 1
