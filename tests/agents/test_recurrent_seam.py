"""The agent seam carries a state: a recurrent policy (sb3-contrib's RecurrentPPO, an LSTM) plays test episodes batched
and one env at a time alike, its memory kept per episode and forgotten at an episode's start, and its exported module
steps as its ``predict`` does."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from crowdnav.agents.runs.checkpoint import AgentPolicy, RecurrentPolicyError
from crowdnav.evaluation.rollout import HeldOutEpisodes
from sb3_contrib import RecurrentPPO

import crowdnav  # noqa: F401  (registers the envs)
from crowdnav.scenario.library import library_names

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

ENV = {"scenario": "open_space", "modalities": ["goal", "velocity", "humans"], "overrides": {"max_steps": 25, "humans.count": 3}}


@pytest.fixture(scope="module")
def recurrent():
    """An untrained, seeded LSTM policy wrapped as crowdnav wraps a loaded checkpoint (raw observations, no scaling)."""
    env = gym.make("crowdnav/OpenSpace-v0", modalities=ENV["modalities"], overrides=ENV["overrides"])
    model = RecurrentPPO("MultiInputLstmPolicy", env, n_steps=8, seed=0, policy_kwargs={"lstm_hidden_size": 16})
    return AgentPolicy(model, {"algo": "recurrent_ppo", "env": ENV})


def played_by_hand(policy, seed):
    """The reference: one env, the state kept step to step, the episode's start flagged once."""
    env = policy.make_env()
    observation, _ = env.reset(seed=seed)
    state, start, actions = None, np.array([True]), []
    while True:
        action, state = policy.predict({key: np.asarray(value)[None] for key, value in observation.items()}, state, start)
        start = np.array([False])
        actions.append(action[0])
        observation, _, terminated, truncated, info = env.step(action[0])
        if terminated or truncated:
            return np.stack(actions), info["outcome"]


def test_recurrent_policy_is_recognised_and_refuses_a_stateless_call(recurrent):
    assert recurrent.recurrent
    observation, _ = recurrent.make_env().reset(seed=0)
    with pytest.raises(RecurrentPolicyError, match="carries a state between steps"):
        recurrent(observation)


def test_recurrent_state_changes_the_action_so_it_is_really_carried(recurrent):
    observation, _ = recurrent.make_env().reset(seed=1)
    batch = {key: np.repeat(np.asarray(value)[None], 2, axis=0) for key, value in observation.items()}
    first, state = recurrent.predict(batch, None, np.array([True, True]))
    again, _ = recurrent.predict(batch, state, np.array([False, True]))  # row 0 remembers a step, row 1 starts afresh
    assert np.array_equal(again[1], first[1]) and not np.array_equal(again[0], first[0])


def test_recurrent_policy_plays_the_same_episodes_batched_single_and_by_hand(recurrent):
    seeds = [0, 1, 2, 3]
    episodes = HeldOutEpisodes(recurrent.env_options, seeds)
    batched, single = episodes.run(recurrent), episodes.run(recurrent, batched=False)
    for a, b in zip(batched, single, strict=True):
        assert a["outcome"] == b["outcome"] and a["return"] == b["return"] and a["path_length"] == b["path_length"]
    ends = [played_by_hand(recurrent, seed)[1] for seed in seeds]
    assert [row["outcome"] for row in batched] == ends


def test_recurrent_actor_module_steps_as_predict_with_an_episode_start_midway(recurrent):
    import torch
    from crowdnav.agents.runs.onnx_export import RecurrentSB3Actor, sb3_actor

    keys = list(ENV["modalities"])
    actor = sb3_actor(recurrent.model, keys)
    assert isinstance(actor, RecurrentSB3Actor) and actor.state_shape == (1, 1, 16)
    envs = [recurrent.make_env() for _ in range(2)]
    observations = [env.reset(seed=seed)[0] for env, seed in zip(envs, (5, 6), strict=True)]
    state, h, c = None, torch.zeros(1, 2, 16), torch.zeros(1, 2, 16)
    for step in range(12):
        start = np.array([step == 0, step in (0, 6)])  # world 1 is told a new episode begins at step 6
        batch = {key: np.stack([o[key] for o in observations]) for key in keys}
        expected, state = recurrent.predict(batch, state, start)
        with torch.no_grad():
            traced, h, c = actor(*(torch.as_tensor(batch[key]) for key in keys), h, c, torch.as_tensor(start, dtype=torch.float32))
        np.testing.assert_allclose(traced.numpy(), expected, atol=1e-6)
        np.testing.assert_allclose(h.numpy(), state[0], atol=1e-6)
        observations = [env.step(action)[0] for env, action in zip(envs, expected, strict=True)]


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory):
    """A recurrent_ppo run trained through crowdnav (2 worlds, a few updates): the checkpoint every tool below reads."""
    from crowdnav.agents import train

    from tests.agents.test_recurrent_ppo import recurrent_config

    out = tmp_path_factory.mktemp("recurrent") / "run"
    train(recurrent_config(out, worlds=2, episodes=4, max_steps=30))
    return out


def test_a_trained_recurrent_run_is_evaluated_from_the_command_line(trained_run, tmp_path, capsys):
    from crowdnav.cli import main

    assert main(["evaluate", str(trained_run), "--scenario", "open_space", "--episodes", "3", "--out", str(tmp_path / "eval"), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "on 3 test episodes" in printed and "seeds_0-2" in printed


def test_a_trained_recurrent_run_renders_with_its_state_kept(trained_run, tmp_path):
    from crowdnav.agents.runs.render import render_policy

    paths = render_policy("open_space", str(trained_run), episodes=1, out=tmp_path, progress=False, video_format="gif")
    assert len(paths) == 1 and paths[0].stat().st_size > 0


def test_a_trained_recurrent_run_exports_to_onnx_with_its_state_in_and_out(trained_run, tmp_path):
    ort = pytest.importorskip("onnxruntime")
    import json

    from crowdnav.agents import load_policy
    from crowdnav.agents.runs.onnx_export import EPISODE_START_INPUT, export_onnx

    policy = load_policy(trained_run)
    session = ort.InferenceSession(str(export_onnx(trained_run, tmp_path / "policy.onnx")), providers=["CPUExecutionProvider"])
    shapes = json.loads(session.get_modelmeta().custom_metadata_map["crowdnav.state"])
    assert [i.name for i in session.get_inputs()][-3:] == ["lstm_h", "lstm_c", EPISODE_START_INPUT]
    assert [o.name for o in session.get_outputs()] == ["action", "next_lstm_h", "next_lstm_c"]
    envs = [policy.make_env() for _ in range(2)]
    observations = [env.reset(seed=seed)[0] for env, seed in zip(envs, (3, 4), strict=True)]
    layers, _, hidden = shapes["lstm_h"]
    state, h, c = None, np.zeros((layers, 2, hidden), np.float32), np.zeros((layers, 2, hidden), np.float32)
    for step in range(20):
        start = np.array([step == 0, step in (0, 10)])
        batch = {key: np.stack([o[key] for o in observations]) for key in observations[0]}
        expected, state = policy.predict(batch, state, start)
        action, h, c = session.run(None, {**batch, "lstm_h": h, "lstm_c": c, EPISODE_START_INPUT: start.astype(np.float32)})
        np.testing.assert_allclose(action, expected, atol=1e-5)
        observations = [env.step(a)[0] for env, a in zip(envs, expected, strict=True)]


@pytest.mark.parametrize("scenario", library_names())
def test_a_recurrent_run_trains_evaluates_and_exports_in_every_library_scenario(tmp_path, scenario):
    ort = pytest.importorskip("onnxruntime")
    from crowdnav.agents import load_policy, train
    from crowdnav.agents.runs.onnx_export import EPISODE_START_INPUT, export_onnx

    train({"scenario": scenario, "algo": "recurrent_ppo", "modalities": ["humans", "closest_obstacle", "goal"], "num_envs": 2,
           "n_steps": 16, "batch_size": 32, "timesteps": 64, "net_arch": [16], "policy_kwargs": {"lstm_hidden_size": 8},
           "overrides": {"max_steps": 15}, "out": str(tmp_path / "run"), "progress": False})
    policy = load_policy(tmp_path / "run")
    rows = HeldOutEpisodes(policy.env_options, [0, 1]).run(policy)
    assert [row["test_seed"] for row in rows] == [0, 1] and all(row["steps"] <= 15 for row in rows)
    session = ort.InferenceSession(str(export_onnx(tmp_path / "run", tmp_path / "policy.onnx")), providers=["CPUExecutionProvider"])
    observation, _ = policy.make_env().reset(seed=0)
    batch = {key: np.asarray(value)[None] for key, value in observation.items()}
    expected, _ = policy.predict(batch, None, np.array([True]))
    zeros = np.zeros((1, 1, 8), np.float32)
    action = session.run(["action"], {**batch, "lstm_h": zeros, "lstm_c": zeros, EPISODE_START_INPUT: np.ones(1, np.float32)})[0]
    np.testing.assert_allclose(action, expected, atol=1e-5)
