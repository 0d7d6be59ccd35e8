"""Recurrent PPO (``algo: recurrent_ppo``, sb3-contrib's LSTM policy) trains through crowdnav's SB3 session like PPO:
from several worlds, reproducibly, with checkpoints that load without unpickling and resumes that continue the
uninterrupted run bit for bit (its LSTM memory included)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from crowdnav.agents import ConfigError, load_policy, train
from crowdnav.agents.networks.size import NetworkSizeError, model_parameters
from crowdnav.agents.runs.folder import checkpoint_dir, policy_snapshots
from crowdnav.agents.runs.resume_state import ROLLOUT_ARRAYS
from crowdnav.agents.sb3.factory import hyperparameters, make_env, make_model
from crowdnav.agents.training.config import config_from_mapping
from crowdnav.agents.training.seeding import train_seed

from crowdnav.registry import algorithm_spec
from tests.agents.agents_tiny import tiny_config

WORLDS = 4
LSTM = {"lstm_hidden_size": 8}
"""A tiny LSTM: the tests exercise the recurrent path, not its capacity."""


def recurrent_config(out, worlds: int = WORLDS, **fields):
    """``tiny_config`` for recurrent_ppo: rollouts of 16 steps per world (32 with one world), one epoch, an 8-unit LSTM."""
    settings = {"algo": "recurrent_ppo", "num_envs": worlds, "policy_kwargs": dict(LSTM), "algo_kwargs": {"n_epochs": 1},
                "modalities": ["goal", "velocity", "humans"], "batch_size": 16}
    if worlds > 1:
        settings["n_steps"] = 16
    else:
        settings["algo_kwargs"] = {"n_epochs": 1, "n_steps": 32}
    return tiny_config(out, **{**settings, **fields})


class Stopped(Exception):
    """Stands for a kill right after a checkpoint (as in test_resume_exact.py)."""


def _log(folder) -> pd.DataFrame:
    return pd.read_csv(folder / "episodes.csv").drop(columns=["seconds"])


def _episodes(result) -> list[tuple]:
    return [(r.episode, r.seed, r.outcome, r.reward, r.length, r.timesteps) for r in result.records]


def _weights(model) -> list[bytes]:
    return [p.detach().numpy().tobytes() for p in model.policy.parameters()]


def test_recurrent_ppo_builds_sb3_contribs_lstm_policy_on_crowdnavs_extractor_with_a_small_lstm(tmp_path):
    from crowdnav.agents.networks.extractor import MultiModalExtractor
    from sb3_contrib import RecurrentPPO
    from sb3_contrib.common.recurrent.policies import RecurrentActorCriticPolicy

    spec = algorithm_spec("recurrent_ppo")
    assert spec.sb3 and spec.recurrent and not spec.off_policy
    config = config_from_mapping({**recurrent_config(tmp_path), "policy_kwargs": {}})
    model = make_model(config, make_env(config))
    assert type(model) is RecurrentPPO and isinstance(model.policy, RecurrentActorCriticPolicy)
    assert isinstance(model.policy.features_extractor, MultiModalExtractor)
    assert model.policy.lstm_actor.hidden_size == spec.policy_kwargs["lstm_hidden_size"] == 64  # crowdnav's, not sb3-contrib's 256
    wider = config.model_copy(update={"policy_kwargs": {"lstm_hidden_size": 12}})  # the config's own policy_kwargs win
    assert make_model(wider, make_env(wider)).policy.lstm_actor.hidden_size == 12


@pytest.mark.parametrize("policy_kwargs", [
    {},
    {"lstm_hidden_size": 8, "n_lstm_layers": 2},
    {"lstm_hidden_size": 8, "enable_critic_lstm": False},
    {"lstm_hidden_size": 8, "enable_critic_lstm": False, "shared_lstm": True},
    {"lstm_hidden_size": 8, "share_features_extractor": False},
], ids=["default", "two-layers", "critic-linear", "shared-lstm", "separate-extractors"])
def test_the_counted_parameters_are_those_the_built_recurrent_model_holds(tmp_path, policy_kwargs):
    config = config_from_mapping(recurrent_config(tmp_path, worlds=1, policy_kwargs=policy_kwargs))
    env = make_env(config)
    built = sum(parameter.numel() for parameter in make_model(config, env).policy.parameters())
    assert model_parameters(config, hyperparameters(config)["net_arch"], env.observation_space, env.action_space) == built


@pytest.mark.parametrize(("policy_kwargs", "message"), [
    ({"lstm_hidden_size": 4000, "n_lstm_layers": 4}, "would hold"),  # counted, refused before a tensor exists
    ({"lstm_hidden_size": "wide"}, "policy_kwargs.lstm_hidden_size must be an integer 1..4096"),
    ({"n_lstm_layers": 0}, "policy_kwargs.n_lstm_layers must be an integer 1..16"),
])
def test_an_lstm_beyond_the_bounds_is_refused_in_one_line_before_building(tmp_path, policy_kwargs, message):
    config = config_from_mapping(recurrent_config(tmp_path, worlds=1, policy_kwargs=policy_kwargs))
    with pytest.raises(NetworkSizeError, match=message) as refused:
        make_model(config, make_env(config))
    assert "\n" not in str(refused.value)


def test_a_wide_lstm_in_a_policy_json_is_refused_in_one_line_before_its_network_is_built(tmp_path):
    from crowdnav.agents.runs.checkpoint import POLICY_FORMAT, UntrustedCheckpointError
    from crowdnav.agents.sb3.factory import env_options
    from crowdnav.agents.training.config import config_to_dict

    config = config_from_mapping(recurrent_config(tmp_path, policy_kwargs={"lstm_hidden_size": 4096, "n_lstm_layers": 16}))
    info = {"format": POLICY_FORMAT, "algo": config.algo, "env": env_options(config), "observation_normalization": None,
            "episodes": 1, "timesteps": 60, "config": config_to_dict(config), "leog_encoder": None}
    (tmp_path / "policy.json").write_text(json.dumps(info), encoding="utf-8")  # no model.zip: the refusal comes first
    with pytest.raises(UntrustedCheckpointError, match=r"would hold [\d,]+ parameters") as refused:
        load_policy(tmp_path)
    assert "\n" not in str(refused.value)


def test_a_warm_start_from_demonstrations_is_refused_in_one_line(tmp_path):
    with pytest.raises(ConfigError, match="LSTM policy cannot be warm-started by behaviour cloning; set it to 0"):
        config_from_mapping(recurrent_config(tmp_path, demonstrations={"episodes": 2}))


def test_the_same_seed_gives_the_same_episodes_and_final_weights(tmp_path):
    first = train(recurrent_config(tmp_path / "first", episodes=8))
    again = train(recurrent_config(tmp_path / "again", episodes=8))
    assert first.model.n_envs == WORLDS and first.model._n_updates > 0
    pd.testing.assert_frame_equal(_log(tmp_path / "first"), _log(tmp_path / "again"))
    assert _weights(first.model) == _weights(again.model)
    other = train(recurrent_config(tmp_path / "other", episodes=8, seed=1))
    assert _weights(other.model) != _weights(first.model)


def test_a_checkpoint_loads_from_its_parameters_without_unpickling_and_acts_like_sb3s_full_load(tmp_path, monkeypatch):
    import cloudpickle

    trained = train(recurrent_config(tmp_path, episodes=6))
    info = json.loads((checkpoint_dir(tmp_path) / "policy.json").read_text())
    assert info["algo"] == "recurrent_ppo" and info["episodes"] == 6
    full = load_policy(tmp_path, trusted=True)  # SB3's own load (it unpickles), before the poison below

    def poisoned(*args, **kwargs):
        raise AssertionError("a pickle was loaded")

    monkeypatch.setattr(cloudpickle, "loads", poisoned)
    monkeypatch.setattr("pickle.loads", poisoned)
    safe = load_policy(tmp_path)  # would fail if SB3's data (cloudpickle) or any pickle were read
    assert type(safe.model).__name__ == "RecurrentPPO" and _weights(safe.model) == _weights(trained.model)
    # the memory carried from step to step, in SB3's own predict: both loads act alike over an episode
    env = safe.make_env()
    observation, _ = env.reset(seed=2)
    states, start, acted = [None, None], np.array([True]), 0
    for _ in range(15):
        actions = []
        for i, policy in enumerate((safe, full)):
            action, states[i] = policy.model.predict(policy.preprocess(observation), states[i], start, deterministic=True)
            actions.append(action)
        np.testing.assert_array_equal(actions[0], actions[1])
        observation, _, terminated, truncated, _ = env.step(actions[0])
        start = np.array([terminated or truncated])
        acted += 1
        if terminated or truncated:
            observation, _ = env.reset()
    assert acted == 15 and states[0][0].shape == (1, 1, LSTM["lstm_hidden_size"]) and np.any(states[0][0] != 0)


@pytest.mark.parametrize("worlds", [1, WORLDS], ids=["one-world", "batched"])
def test_a_run_stopped_after_a_checkpoint_and_resumed_trains_bit_for_bit_like_the_uninterrupted_run(tmp_path, worlds):
    whole = train(recurrent_config(tmp_path / "whole", worlds=worlds, episodes=10))
    config = recurrent_config(tmp_path / "stopped", worlds=worlds, episodes=10)
    stored = {}

    def stop(episodes):
        # the first checkpoint that leaves worlds mid-episode, the LSTM's memory of them non-zero: the resume must continue both
        with np.load(checkpoint_dir(tmp_path / "stopped") / ROLLOUT_ARRAYS, allow_pickle=False) as saved:
            if (saved["worlds/episode_lengths"] > 0).any():
                stored.update(episodes=episodes, **{key: saved[key] for key in saved.files if key.startswith("lstm_states/")})
                raise Stopped

    with pytest.raises(Stopped):
        train(config, on_checkpoint=stop)
    assert 0 < stored["episodes"] < 10
    assert sorted(key for key in stored if key != "episodes") == [f"lstm_states/{head}/{i}" for head in ("pi", "vf") for i in (0, 1)]
    assert np.any(stored["lstm_states/pi/0"] != 0)
    resumed = train(config, resume=True)
    assert resumed.records and _episodes(resumed) == _episodes(whole)[stored["episodes"]:]
    pd.testing.assert_frame_equal(_log(tmp_path / "stopped"), _log(tmp_path / "whole"))  # episode numbers continue, none lost
    assert _weights(resumed.model) == _weights(whole.model)
    assert resumed.model._n_updates == whole.model._n_updates


def test_a_stored_rollout_without_its_lstm_memory_is_refused_in_one_line_naming_the_way_on(tmp_path):
    config = recurrent_config(tmp_path, episodes=10)

    def stop(episodes):
        raise Stopped

    with pytest.raises(Stopped):
        train(config, on_checkpoint=stop)
    path = checkpoint_dir(tmp_path) / ROLLOUT_ARRAYS
    with np.load(path, allow_pickle=False) as saved:
        kept = {key: saved[key] for key in saved.files if not key.startswith("lstm_states/")}
    np.savez(path, **kept)
    with pytest.raises(ConfigError, match=r"lstm_states/pi/0 is nothing.*remove .*rollout_state\.npz to resume with new episodes") as refused:
        train(config, resume=True)
    assert "\n" not in str(refused.value)


def test_a_finished_run_resumed_with_a_larger_budget_continues_its_episodes_and_overwrites_nothing(tmp_path):
    first = train(recurrent_config(tmp_path, episodes=6))
    before = _log(tmp_path)
    snapshots = {point: (folder / "model.zip").read_bytes() for point, folder in policy_snapshots(tmp_path).items()}
    assert sorted(snapshots) == [2, 4, 6]
    more = train(recurrent_config(tmp_path, episodes=10), resume=True)
    log = _log(tmp_path)
    assert list(log["episode"]) == list(range(10)) and log["seed"].is_unique
    pd.testing.assert_frame_equal(log.iloc[:6], before)  # the first session's rows as they were
    assert [r.episode for r in more.records] == [6, 7, 8, 9] and more.timesteps > first.timesteps
    assert all(r.seed >= train_seed(0, 6) for r in more.records)  # new episodes, never one the first session played
    assert {point: (policy_snapshots(tmp_path)[point] / "model.zip").read_bytes() for point in snapshots} == snapshots
    assert sorted(policy_snapshots(tmp_path)) == [2, 4, 6, 8, 10]
    assert _weights(more.model) != _weights(first.model)  # it trained on
