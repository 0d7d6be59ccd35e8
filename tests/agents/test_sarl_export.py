"""crowdnav export of the SARL-style agent (agents/sarl/export.py): onnxruntime chooses the actions SarlAgent.predict
chooses on observations of real episodes, in every library scenario it drives, one at a time and batched; an agent
that cannot be exported is refused in one line."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

torch = pytest.importorskip("torch")
ort = pytest.importorskip("onnxruntime", reason='the onnx extra (pip install -e ".[onnx]") runs the exported policies')

from crowdnav.agents import load_policy, train  # noqa: E402

from crowdnav.cli import main  # noqa: E402
from crowdnav.scenario.library import library_names  # noqa: E402
from tests.agents.agents_tiny import recorded_observations  # noqa: E402

NEAR_TIE = 1e-5
"""A different choice is accepted only where its score is within this (relative) of the best: float32 matrix products
round differently in onnxruntime and torch (agents/sarl/export.py)."""


def config(out, scenario="open_space", **fields):
    document = {"algo": "sarl", "scenario": scenario, "modalities": ["humans", "goal", "velocity"], "num_envs": 1,
                "episodes": 1, "seed": 0, "out": str(out), "overrides": {"max_steps": 10}, "checkpoint_every": 1,
                "progress": False, "algo_kwargs": {"batch_size": 4, "updates_per_episode": 2, "width": 16}}
    document.update(fields)
    return document


def check_choices(policy, observations, actions):
    """Every action is one of the agent's commands; where it is not predict's choice, it scores within NEAR_TIE of it.

    Returns the number of such near-ties.
    """
    expected = policy(observations)
    scores, commands = policy.model.scores(policy.preprocess(observations), int(policy.model.options["lookahead_depth"]))
    ties = 0
    for row in range(len(actions)):
        chosen = int(np.argmin(np.abs(commands[row] - actions[row]).max(axis=1)))
        np.testing.assert_array_equal(commands[row, chosen], actions[row])  # exactly a command of the lookahead
        if chosen != int(np.argmax(scores[row])):
            best = scores[row].max()
            assert best - scores[row, chosen] <= NEAR_TIE * max(1.0, abs(best)), (row, best, scores[row, chosen])
            ties += 1
        else:
            np.testing.assert_array_equal(actions[row], expected[row])
    return ties


def random_observation(rng, room, geodesic, polar, batch=6, humans=5, statics=4, size=9):
    """Observations with humans (one at the robot's centre, one moving with it), walls (one at the robot) and a grid."""
    goal = rng.normal(size=(batch, 2)) * 3
    goal[0] = 0.0  # at the goal
    if polar:
        distance = np.hypot(goal[:, 0], goal[:, 1])
        safe = np.where(distance > 0, distance, 1.0)
        goal = np.stack([distance, goal[:, 1] / safe, goal[:, 0] / safe], axis=1)  # distance, sin, cos
    rows = np.concatenate([rng.normal(size=(batch, humans, 4)) * [1.5, 1.5, 1, 1], rng.uniform(0.2, 0.4, (batch, humans, 1)),
                           rng.random((batch, humans, 1)) < 0.7], axis=-1)
    velocity = rng.normal(size=(batch, 2)) * 0.5
    rows[1, 0, 0:2], rows[2, 1, 2:4] = 0.0, 0.0
    observation = {"humans": rows, "goal": goal, "velocity": velocity}
    if room:
        observation["obstacles"] = np.concatenate([rng.normal(size=(batch, statics, 2)), rng.random((batch, statics, 1)) < 0.8], axis=-1)
        observation["obstacles"][3, 0, 0:2] = 0.0
    if geodesic:
        observation["geodesic"] = rng.uniform(0, 10, size=(batch, size, size))
    return observation


@pytest.mark.parametrize("room, geodesic, polar, size", [(False, False, True, 9), (True, True, False, 8), (True, True, True, 1),
                                                         (False, True, False, 2)])
def test_the_lookahead_maths_in_torch_agrees_with_numpys(room, geodesic, polar, size):
    """The export runs lookahead.py's very functions on torch tensors (TorchOps): the same numbers as numpy's, two steps out."""
    from crowdnav.agents.sarl.export import TORCH
    from crowdnav.agents.sarl.lookahead import Physics, action_set, decode, features, lookahead, value_ceiling

    physics = Physics(0.3, 1.0, 0.25, 0.3, 2.0, 0.6, {"step": -0.01, "goal_progress": 0.1, "social": -0.05, "goal_reached": 1.0,
                                                      "collision": -0.25}, 0.7, 0.1)
    rng = np.random.default_rng(size)
    observation = random_observation(rng, room, geodesic, polar, size=size)
    scales = {"goal": (rng.normal(size=observation["goal"].shape[1:]), rng.uniform(0.5, 2.0, size=observation["goal"].shape[1:]))}
    actions = action_set(physics.max_speed)
    ours = decode(observation, scales)
    theirs = decode({key: torch.as_tensor(value) for key, value in observation.items()},
                    {key: tuple(torch.as_tensor(part) for part in pair) for key, pair in scales.items()}, TORCH, empty_static=False)
    assert ours["static"].shape[-2] == (4 if room else 0) and ("static" in theirs) == room  # no zero-size tensor in torch
    for depth in range(2):
        assert sorted(theirs) == sorted(key for key in ours if room or not key.startswith("static"))
        for key, value in theirs.items():
            np.testing.assert_allclose(value.numpy(), ours[key], rtol=0, atol=1e-12, err_msg=f"{depth} {key}")
        for got, expected in zip(features(theirs, physics, TORCH), features(ours, physics), strict=True):
            if got is None:
                assert not room and expected.shape[-2] == 0
            else:
                assert got.dtype == torch.float32 and expected.dtype == np.float32
                np.testing.assert_allclose(got.numpy(), expected, rtol=1e-6, atol=1e-7)
        mine, yours = lookahead(ours, physics, actions, 0.1), lookahead(theirs, physics, torch.as_tensor(actions), 0.1, TORCH)
        assert 0 < mine["done"].sum() < mine["done"].size  # collisions, goals and free moves alike
        np.testing.assert_array_equal(yours["done"].numpy(), mine["done"])
        np.testing.assert_allclose(yours["reward"].numpy(), mine["reward"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(yours["commands"].numpy(), mine["commands"], rtol=0, atol=1e-7)
        distance = np.hypot(mine["next"]["goal"][..., 0], mine["next"]["goal"][..., 1])
        np.testing.assert_allclose(value_ceiling(torch.as_tensor(distance), physics, 0.95, TORCH).numpy(),
                                   value_ceiling(distance, physics, 0.95), rtol=0, atol=1e-12)
        pick = rng.integers(0, len(actions), size=3)  # a second step from a few of the next states, as depth 2 looks
        rows = len(mine["done"]) * len(pick)
        ours = {key: value[:, pick].reshape(rows, *value.shape[2:]) for key, value in mine["next"].items()}
        theirs = {key: value[:, torch.as_tensor(pick)].reshape(rows, *value.shape[2:]) for key, value in yours["next"].items()}


@pytest.mark.slow
@pytest.mark.parametrize("scenario", library_names())
def test_onnxruntime_chooses_predicts_actions_in_every_library_scenario_sarl_drives(tmp_path, scenario):
    from crowdnav.errors import CrowdNavError

    run = tmp_path / "run"
    try:
        train(config(run, scenario))
    except CrowdNavError as error:  # a robot it cannot drive (test_sarl checks the refusal)
        assert "holonomic" in str(error)
        pytest.skip(f"{scenario}: {error}")
    out = tmp_path / "policy.onnx"
    assert main(["export", str(run), "--out", str(out)]) == 0
    policy = load_policy(run)
    observations = recorded_observations(policy, seed=1)
    session = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    assert sorted(i.name for i in session.get_inputs()) == sorted(observations)
    actions = session.run(["action"], observations)[0]
    assert actions.shape == (len(observations["goal"]), 2) and actions.dtype == np.float32
    assert check_choices(policy, observations, actions) <= 1  # elsewhere the very action predict returns
    meta = session.get_modelmeta().custom_metadata_map
    assert meta["crowdnav.algo"] == "sarl" and json.loads(meta["crowdnav.env_options"])["scenario"] == scenario


def test_the_exported_sarl_acts_as_predict_one_observation_and_a_batch(tmp_path):
    """Polar goal and normalised observations (open_space's defaults): the graph undoes the scaling as decode does."""
    run = tmp_path / "run"
    train(config(run, overrides={"max_steps": 10, "humans.count": 4}))
    out = tmp_path / "policy.onnx"
    assert main(["export", str(run), "--out", str(out)]) == 0
    policy = load_policy(run)
    assert policy.scales and policy.model.scales and policy.make_env().observation_space["goal"].shape == (3,)
    observations = recorded_observations(policy, steps=30, seed=1)
    session = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    batch = session.run(["action"], observations)[0]
    assert check_choices(policy, observations, batch) == 0
    np.testing.assert_array_equal(batch, policy(observations))
    for row in (0, 7, 30):
        one = session.run(["action"], {key: value[row:row + 1] for key, value in observations.items()})[0]
        np.testing.assert_array_equal(one[0], policy({key: value[row] for key, value in observations.items()}))
    assert len({tuple(action) for action in batch}) > 1  # not one constant command
    assert session.get_modelmeta().custom_metadata_map["crowdnav.algo"] == "sarl"
    # the torch module itself is predict, bit for bit (no onnxruntime rounding)
    module = policy.model.export_module(list(observations)).eval()
    preprocessed = policy.preprocess(observations)
    with torch.no_grad():
        traced = module(*(torch.as_tensor(preprocessed[key]) for key in observations)).numpy()
    np.testing.assert_array_equal(traced, policy.model.predict(preprocessed)[0])


def test_the_exported_two_step_lookahead_acts_as_predict(tmp_path):
    """``lookahead_depth: 2``: the best actions expanded one step further (topk, gather, the second lookahead) in the graph."""
    run = tmp_path / "run"
    train(config(run, "circle_crossing", algo_kwargs={**config("x")["algo_kwargs"], "lookahead_depth": 2, "lookahead_width": 5}))
    out = tmp_path / "policy.onnx"
    assert main(["export", str(run), "--out", str(out)]) == 0
    policy = load_policy(run)
    assert policy.model.options["lookahead_depth"] == 2
    observations = recorded_observations(policy, steps=30, seed=1)
    actions = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"]).run(["action"], observations)[0]
    assert check_choices(policy, observations, actions) == 0
    np.testing.assert_array_equal(actions, policy(observations))
    one = load_policy(run)
    one.model.options["lookahead_depth"] = 1  # the second step changes some choices: the graph did expand it
    assert not np.array_equal(one(observations), actions)


def test_export_refuses_what_it_cannot_write_in_one_line(tmp_path):
    run = tmp_path / "run"
    train(config(run))
    policy = load_policy(run)
    policy.model.options["lookahead_depth"] = 3
    with pytest.raises(ValueError, match="^algorithm 'sarl' with lookahead_depth 3: ONNX export covers depths 1 and 2$"):
        policy.model.export_module(["goal", "humans", "velocity"])
    with pytest.raises(ValueError, match="^algorithm 'sarl' reads humans, goal and velocity; the observation has no velocity$"):
        load_policy(run).model.export_module(["goal", "humans"])
