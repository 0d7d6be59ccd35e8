"""Batched training (``num_envs > 1``, the native vector env): reproducible from the seed, every
episode seeded by the run's own numbering, an exact budget, exact resumes, step budgets,
reward scaling for the algorithm only, and the frozen encoder's latents computed in the env."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from crowdnav.agents import ConfigError, train
from crowdnav.agents.runs.folder import checkpoint_dir, checkpoint_info, policy_snapshots
from crowdnav.agents.runs.resume_state import ROLLOUT_ARRAYS
from crowdnav.agents.sb3.vec_env import CrowdNavSB3VecEnv
from crowdnav.agents.training.config import config_from_mapping
from crowdnav.agents.training.seeding import TRAIN_SEED_BASE, EpisodeSeedCounter, train_seed

from crowdnav.scenario.library import library_names
from tests.agents.agents_tiny import TINY_EXTRACTOR, tiny_config

WORLDS = 4


def batched_config(out, algo: str = "sac", **fields):
    """``tiny_config`` collecting from ``WORLDS`` worlds, with crowdnav's batched collection (no single-env train_freq)."""
    batched = {"num_envs": WORLDS, "algo_kwargs": {}}
    if algo in ("sac", "td3", "ddpg"):
        batched["updates_per_step"] = 0.5  # 2 gradient steps after each step of the 4 worlds
    elif algo == "ppo":
        batched.update(n_steps=16, algo_kwargs={"n_epochs": 1})  # 64 env steps per rollout
    elif algo == "a2c":
        batched["n_steps"] = 4
    return tiny_config(out, algo=algo, **{**batched, **fields})


class Stopped(Exception):
    """Stands for a kill right after a checkpoint (as in test_resume_exact.py)."""


def _log(folder) -> pd.DataFrame:
    return pd.read_csv(folder / "episodes.csv").drop(columns=["seconds"])


def _episodes(result) -> list[tuple]:
    return [(r.episode, r.seed, r.outcome, r.reward, r.length, r.timesteps) for r in result.records]


def _weights(result) -> list[bytes]:
    return [p.detach().numpy().tobytes() for p in result.model.policy.parameters()]


def _info(folder) -> dict:
    return json.loads((folder / "policy.json").read_text())


def test_each_world_plays_the_single_env_episode_of_the_seed_the_counter_gave_it_autoresets_included():
    from crowdnav.envs import CrowdNavEnv

    options = {"modalities": ["goal", "lidar"], "overrides": {"humans.count": 3, "max_steps": 25}, "sensors": {"lidar": {"beams": 16}}}
    counter = EpisodeSeedCounter(2, first_episode=5)
    worlds = CrowdNavSB3VecEnv.make("open_space", 3, episode_seeds=counter, **options)
    worlds.seed(0)  # as SB3 does: ignored, the counter seeds every episode
    replicas = [CrowdNavEnv("open_space", **options) for _ in range(3)]
    batch = worlds.reset()
    rng, ended = np.random.default_rng(0), []
    for i, replica in enumerate(replicas):
        observation, _ = replica.reset(seed=train_seed(2, 5 + i))
        assert all(observation[k].tobytes() == batch[k][i].tobytes() for k in observation)
    for _ in range(60):
        actions = rng.uniform(-1, 1, (3, 2)).astype(np.float32)
        worlds.step_async(actions)
        batch, rewards, dones, infos = worlds.step_wait()
        for i, replica in enumerate(replicas):
            observation, reward, terminated, truncated, _ = replica.step(actions[i])
            assert np.float32(reward) == rewards[i] and (terminated or truncated) == dones[i]
            if dones[i]:
                assert infos[i]["episode_seed"] == train_seed(2, infos[i]["episode_index"])
                ended.append(infos[i]["episode_index"])
                observation, _ = replica.reset(seed=train_seed(2, counter.episode_of[i]))
            assert all(observation[k].tobytes() == batch[k][i].tobytes() for k in observation)
    # numbered in start order: 5, 6, 7 first, then one number per autoreset
    assert sorted(ended) == sorted(set(ended)) and set(ended) <= set(range(5, counter.next_episode)) and len(ended) >= 6
    assert counter.next_episode == 5 + 3 + len(ended)
    worlds.close()


@pytest.mark.parametrize("algo", ["sac", "ppo"])
def test_the_same_seed_gives_the_same_episodes_and_final_weights(tmp_path, algo):
    first = train(batched_config(tmp_path / "first", algo, episodes=10))
    again = train(batched_config(tmp_path / "again", algo, episodes=10))
    assert first.model.n_envs == WORLDS and first.model._n_updates > 0
    pd.testing.assert_frame_equal(_log(tmp_path / "first"), _log(tmp_path / "again"))
    assert _weights(first) == _weights(again)
    other = train(batched_config(tmp_path / "other", algo, episodes=10, seed=1))
    assert set(_log(tmp_path / "other")["seed"]).isdisjoint(_log(tmp_path / "first")["seed"]) and _weights(other) != _weights(first)


@pytest.mark.parametrize("algo", ["sac", "td3", "ddpg", "a2c", "ppo"])
def test_every_algorithm_trains_batched_on_grids_and_lidar(tmp_path, algo):
    result = train(batched_config(tmp_path, algo, modalities=["leog", "lidar", "goal"], episodes=6))
    assert result.episodes == 6 and result.model.n_envs == WORLDS and result.model._n_updates > 0
    assert result.timesteps >= sum(record.length for record in result.records)  # the worlds still playing count too
    if algo in ("sac", "td3", "ddpg"):  # the grids stored at 1 bit per cell, one column per world
        assert result.model.replay_buffer.observations["leog"].shape[1:] == (WORLDS, 30 * 30 // 8 + 1)


def test_every_episode_has_a_training_seed_although_sb3_seeds_the_vector_env(tmp_path, monkeypatch):
    seeded = []
    original = CrowdNavSB3VecEnv.seed

    def spy(self, seed=None):
        seeded.append(seed)
        return original(self, seed)

    monkeypatch.setattr(CrowdNavSB3VecEnv, "seed", spy)
    train(batched_config(tmp_path, episodes=12))
    assert seeded == [0]  # SB3 passed the algorithm's seed: without the run's numbering the worlds would replay test seeds 0..3
    seeds = _log(tmp_path)["seed"]
    assert (seeds >= TRAIN_SEED_BASE).all()
    # episodes are numbered as they start: the 4 first ones, then one per autoreset, at most 3 still running at the end
    started = {train_seed(0, index) for index in range(12 + WORLDS - 1)}
    assert set(seeds) <= started and {train_seed(0, index) for index in range(WORLDS)} <= set(seeds)


def test_each_episode_is_logged_once_with_its_own_seed_and_the_budget_is_exact(tmp_path):
    # 3 humans, 60 steps: worlds that time out together end in the same step, so budgets fall mid-step
    for episodes in (5, 6, 7):
        result = train(batched_config(tmp_path / str(episodes), "ppo", episodes=episodes))
        log = _log(tmp_path / str(episodes))
        assert list(log["episode"]) == list(range(episodes)) and result.episodes == episodes == len(result.records)
        assert log["seed"].is_unique
        assert checkpoint_info(tmp_path / str(episodes))["episodes"] == episodes
        assert sorted(policy_snapshots(tmp_path / str(episodes))) == sorted({*range(2, episodes + 1, 2), episodes})


@pytest.mark.parametrize("algo", ["sac", "ppo"])
def test_a_finished_batched_run_resumed_with_a_larger_budget_logs_new_episodes_with_new_seeds(tmp_path, algo):
    first = train(batched_config(tmp_path, algo, episodes=6))
    assert not (checkpoint_dir(tmp_path) / ROLLOUT_ARRAYS).exists()  # it ended inside a step: its worlds are not continued
    started = checkpoint_info(tmp_path)["next_episode"]
    assert started > 6  # episodes still running (or ended past the budget) when it stopped
    more = train(batched_config(tmp_path, algo, episodes=12), resume=True)
    log = _log(tmp_path)
    assert list(log["episode"]) == list(range(12)) and log["seed"].is_unique
    assert [r.seed for r in first.records] == list(log["seed"][:6])
    assert {r.seed for r in more.records} >= {train_seed(0, started)}
    assert all(r.seed >= train_seed(0, started) for r in more.records)  # never an episode the first session started
    if algo == "sac":  # the abandoned episodes end in the buffer: no n-step return runs on into the new ones
        buffer = more.model.replay_buffer
        row = first.timesteps // WORLDS - 2  # the step that reached the budget was not stored
        assert buffer.dones[row].all() and buffer.timeouts[row].any()


@pytest.mark.parametrize(("algo", "fields"), [
    ("sac", {}),
    pytest.param("sac", {"algo_kwargs": {"train_freq": 2, "gradient_steps": -1}},  # rollouts of 2 steps of every world, 8 updates after each
                 marks=pytest.mark.slow),  # 6 s; the plain sac case stays in the default suite
    ("td3", {}),
    ("ppo", {}),
    ("a2c", {}),
], ids=["sac", "sac-train_freq2", "td3", "ppo", "a2c"])
def test_a_batched_run_stopped_after_a_checkpoint_and_resumed_trains_bit_for_bit_like_the_uninterrupted_run(tmp_path, algo, fields):
    whole = train(batched_config(tmp_path / "whole", algo, episodes=12, **fields))
    config = batched_config(tmp_path / "stopped", algo, episodes=12, **fields)
    stopped_at = []

    def stop(episodes):
        # the first checkpoint that leaves worlds mid-episode (often all 4 time out together): the resume must continue them
        with np.load(checkpoint_dir(tmp_path / "stopped") / ROLLOUT_ARRAYS, allow_pickle=False) as saved:
            mid_episode = (saved["worlds/episode_lengths"] > 0).any()
            assert "worlds/0/world/episode/state/positions" in saved.files  # stored as states (tests/agents/test_resume_states.py)
        if mid_episode:
            stopped_at.append(episodes)
            raise Stopped

    with pytest.raises(Stopped):
        train(config, on_checkpoint=stop)
    assert 0 < stopped_at[0] < 12
    resumed = train(config, resume=True)
    assert resumed.records and _episodes(resumed) == _episodes(whole)[stopped_at[0]:]
    pd.testing.assert_frame_equal(_log(tmp_path / "stopped"), _log(tmp_path / "whole"))
    assert _weights(resumed) == _weights(whole)
    assert resumed.model._n_updates == whole.model._n_updates


@pytest.mark.parametrize("algo", ["sac", "ppo"])
def test_a_step_budget_saves_snapshots_every_so_many_env_steps_and_stops_at_the_budget(tmp_path, algo):
    result = train(batched_config(tmp_path, algo, episodes=1, timesteps=250, checkpoint_every_steps=64))
    assert 250 <= result.timesteps < 250 + WORLDS  # the step that reaches the budget is the last one
    assert result.episodes > 1  # the episode budget is ignored
    snapshots = policy_snapshots(tmp_path, unit="steps")
    assert sorted(snapshots) == [64, 128, 192]
    assert [p.name for p in snapshots.values()] == ["steps_000000064", "steps_000000128", "steps_000000192"]
    # each the policy that acted in the step reaching its point
    assert [_info(folder)["timesteps"] for folder in snapshots.values()] == [64, 128, 192]
    assert checkpoint_info(tmp_path)["timesteps"] == result.timesteps
    assert not (tmp_path / "snapshots" / "episode_00002").exists()


def test_a_step_budget_without_step_checkpoints_checkpoints_every_checkpoint_every_episodes_and_shows_steps(tmp_path, capsys):
    result = train(batched_config(tmp_path, episodes=1, timesteps=240, progress=True))
    assert result.timesteps == 240 and "240/240" in capsys.readouterr().err  # the bar counts env steps
    assert sorted(policy_snapshots(tmp_path)) == sorted({*range(2, result.episodes + 1, 2), result.episodes})
    assert not policy_snapshots(tmp_path, unit="steps")


def test_a_step_budget_run_stopped_after_a_checkpoint_resumes_exactly(tmp_path):
    fields = {"episodes": 1, "timesteps": 320, "checkpoint_every_steps": 64}
    whole = train(batched_config(tmp_path / "whole", **fields))
    config = batched_config(tmp_path / "stopped", **fields)

    def stop(episodes):
        raise Stopped

    with pytest.raises(Stopped):
        train(config, on_checkpoint=stop)
    assert sorted(policy_snapshots(tmp_path / "stopped", unit="steps")) == [64]
    resumed = train(config, resume=True)
    pd.testing.assert_frame_equal(_log(tmp_path / "stopped"), _log(tmp_path / "whole"))
    assert _weights(resumed) == _weights(whole)
    assert sorted(policy_snapshots(tmp_path / "stopped", unit="steps")) == sorted(policy_snapshots(tmp_path / "whole", unit="steps"))


def test_reward_scale_multiplies_what_the_algorithm_learns_from_and_not_the_logged_returns(tmp_path):
    # no gradient step within the run (learning_starts beyond it): both runs take the same random actions
    plain = train(batched_config(tmp_path / "plain", episodes=6, learning_starts=10_000))
    scaled = train(batched_config(tmp_path / "scaled", episodes=6, learning_starts=10_000, reward_scale=3.0))
    pd.testing.assert_frame_equal(_log(tmp_path / "plain"), _log(tmp_path / "scaled"))
    stored = plain.model.replay_buffer.pos
    assert stored > 100 and scaled.model.replay_buffer.pos == stored
    rewards = plain.model.replay_buffer.rewards[:stored]
    assert np.abs(rewards).max() > 0
    np.testing.assert_allclose(scaled.model.replay_buffer.rewards[:stored], 3.0 * rewards, rtol=1e-6)


def test_frozen_precomputed_encoder_gives_the_worlds_the_single_envs_latents_and_trains(tmp_path, encoder_file):
    from crowdnav.agents import load_policy
    from crowdnav.agents.sb3.factory import load_leog_weights, make_env, make_vec_env

    fields = {"modalities": ["leog", "goal"], "scenario": "room_furniture", "encoder": {"mode": "frozen", "weights": str(encoder_file)}}
    config = config_from_mapping(batched_config(tmp_path / "run", **fields))
    encoder, _ = load_leog_weights(config)
    worlds = make_vec_env(config, encoder)
    single = make_env(config.model_copy(update={"num_envs": 1}), encoder)
    latent = TINY_EXTRACTOR["leog_latent"]
    assert worlds.observation_space == single.observation_space and worlds.observation_space["leog"].shape == (latent,)
    batch = worlds.reset()
    for world in range(WORLDS):  # world i plays episode i: the single env's i-th episode, latent and all
        observation, _ = single.reset()
        for key in observation:
            np.testing.assert_allclose(batch[key][world], observation[key], rtol=1e-5, atol=1e-6, err_msg=key)
    worlds.close()
    single.close()

    result = train(batched_config(tmp_path / "run", episodes=8, **fields))
    assert result.model.observation_space["leog"].shape == (latent,) and result.model._n_updates > 0
    assert result.model.replay_buffer.observations["leog"].shape[-1] == latent
    assert load_policy(tmp_path / "run").encoder is not None

    def stop(episodes):  # the checkpoint carries the worlds, encoder and all
        raise Stopped

    with pytest.raises(Stopped):
        train(batched_config(tmp_path / "stopped", episodes=8, **fields), on_checkpoint=stop)
    resumed = train(batched_config(tmp_path / "stopped", episodes=8, **fields), resume=True)
    pd.testing.assert_frame_equal(_log(tmp_path / "stopped"), _log(tmp_path / "run"))
    assert _weights(resumed) == _weights(result)


def test_resuming_with_another_number_of_worlds_is_refused(tmp_path):
    train(batched_config(tmp_path / "batched", episodes=2))
    with pytest.raises(ConfigError, match=r"trained with num_envs 4, the config asks for 3"):
        train(batched_config(tmp_path / "batched", episodes=4, num_envs=3), resume=True)
    with pytest.raises(ConfigError, match=r"trained with num_envs 4, the config asks for 1"):
        train(tiny_config(tmp_path / "batched", episodes=4), resume=True)
    train(tiny_config(tmp_path / "single", episodes=2))
    with pytest.raises(ConfigError, match=r"trained with num_envs 1, the config asks for 4"):
        train(batched_config(tmp_path / "single", episodes=4), resume=True)


@pytest.mark.parametrize(("worlds", "ratio", "train_freq", "expected"), [
    (4, 0.125, None, 1),   # 0.5 rounds half up (Python's round would give 0, then the floor of 1 by luck)
    (12, 0.125, None, 2),  # 1.5 -> 2 (round-half-even would also give 2)
    (20, 0.125, None, 3),  # 2.5 -> 3 (round-half-even: 2, a lower ratio than asked)
    (4, 0.5, 3, 6),        # a rollout of 3 steps of all worlds: 3 x 4 x 0.5 updates after it
])
def test_off_policy_batched_gradient_steps_are_the_update_to_data_ratio_times_the_env_steps_of_a_rollout(
        tmp_path, worlds, ratio, train_freq, expected):
    from crowdnav.agents.sb3.factory import make_model, make_vec_env

    fields = {"num_envs": worlds, "updates_per_step": ratio, "algo_kwargs": {} if train_freq is None else {"train_freq": train_freq}}
    config = config_from_mapping(tiny_config(tmp_path, algo="sac", **fields))
    model = make_model(config, make_vec_env(config))
    assert model.gradient_steps == expected
    assert model.train_freq.frequency == (train_freq or 1)


def test_a_run_refuses_to_start_more_training_episodes_than_its_seed_band_holds():
    from crowdnav.agents.training.seeding import MAX_TRAIN_EPISODES, dataset_seed

    counter = EpisodeSeedCounter(0, first_episode=MAX_TRAIN_EPISODES - 1)
    assert counter([0]) == [train_seed(0, MAX_TRAIN_EPISODES - 1)]
    assert train_seed(0, MAX_TRAIN_EPISODES) == dataset_seed(0, 0)  # why: the next seed is a grid collection's
    with pytest.raises(RuntimeError, match="at most 500,000 training episodes"):
        counter([1])


def test_a_linear_learning_rate_schedule_decays_to_zero_over_the_budget_and_survives_a_checkpoint(tmp_path):
    from crowdnav.agents.runs.checkpoint import load_model

    result = train(batched_config(tmp_path / "run", algo="ppo", learning_rate=1e-3, learning_rate_schedule="linear",
                                  timesteps=256, episodes=1000))
    model = result.model
    assert model.lr_schedule(1.0) == pytest.approx(1e-3) and model.lr_schedule(0.25) == pytest.approx(2.5e-4)
    # the last update ran near the end of the budget, at a small fraction of the initial rate
    assert model.policy.optimizer.param_groups[0]["lr"] < 0.5e-3
    assert load_model(checkpoint_dir(tmp_path / "run")).lr_schedule(0.5) == pytest.approx(5e-4)


@pytest.mark.parametrize("scenario", library_names())
def test_batched_training_runs_in_every_library_scenario_with_the_humans_modality(tmp_path, scenario):
    config = {"scenario": scenario, "algo": "ppo", "modalities": ["humans", "closest_obstacle", "goal"], "num_envs": 4,
              "n_steps": 16, "timesteps": 128, "out": str(tmp_path), "progress": False, "net_arch": [16]}
    result = train(config)
    assert result.timesteps == 128
    logged = _log(tmp_path)
    assert (logged["seed"] >= TRAIN_SEED_BASE).all() and logged["seed"].is_unique
