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
