"""Demonstrations of the social-force robot: seeds, what is collected, cloning, the replay buffer, the switch."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from crowdnav.agents.imitation import demonstrations as demos
from crowdnav.agents.imitation.demonstrations import (
    REPORT_FILE,
    add_to_replay_buffer,
    agent_view,
    behaviour_cloning,
    collect_demonstrations,
    warm_start,
)
from crowdnav.agents.sb3.factory import env_options, make_env, make_model, make_vec_env
from crowdnav.agents.sb3.vec_env import CrowdNavSB3VecEnv
from crowdnav.agents.training.config import config_from_mapping
from crowdnav.agents.training.run import train
from crowdnav.agents.training.seeding import (
    DATASET_SEED_OFFSET,
    DEMONSTRATION_EPISODES,
    DEMONSTRATION_SEED_OFFSET,
    MAX_TRAIN_EPISODES,
    TRAIN_SEED_BASE,
    dataset_seed,
    demonstration_seed,
    train_seed,
)

from tests.agents.agents_tiny import tiny_config

pytestmark = pytest.mark.usefixtures("one_torch_thread")  # tests/conftest.py


def config(tmp_path, algo="sac", **fields):
    return config_from_mapping(tiny_config(tmp_path / algo, algo=algo, **{"num_envs": 3, **fields}))


@pytest.fixture(scope="module")
def lidar_demonstrations(tmp_path_factory):
    cfg = config(tmp_path_factory.mktemp("demos"))
    return cfg, collect_demonstrations(cfg, 4)


# ------------------------------------------------------------------------------------------------ seeds


def test_demonstration_seeds_never_meet_test_dataset_or_training_seeds():
    for seed in range(4):
        first, last = demonstration_seed(seed, 0), demonstration_seed(seed, DEMONSTRATION_EPISODES - 1)
        assert first >= TRAIN_SEED_BASE  # test seeds lie below
        for other in range(4):  # every run's training episodes and its grid collections' quarter lie elsewhere
            trained = (train_seed(other, 0), train_seed(other, MAX_TRAIN_EPISODES - 1))
            collected = (dataset_seed(other, 0), dataset_seed(other, DEMONSTRATION_SEED_OFFSET - DATASET_SEED_OFFSET - 1))
            for low, high in (trained, collected):
                assert last < low or first > high
    with pytest.raises(ValueError, match="outside the band"):
        demonstration_seed(0, DEMONSTRATION_EPISODES)


def test_collection_plays_the_demonstration_seeds_and_does_not_depend_on_the_worlds(lidar_demonstrations, tmp_path):
    cfg, collected = lidar_demonstrations
    assert sorted(collected.outcomes) == [0, 1, 2, 3] and set(collected.driver.values()) == {"social-force"}
    alone = collect_demonstrations(cfg, 4, worlds=1)
    for key in collected.observations:
        np.testing.assert_array_equal(alone.observations[key], collected.observations[key])
    np.testing.assert_array_equal(alone.actions, collected.actions)
    later = collect_demonstrations(cfg, 1, first_episode=2)  # episode 2 alone is episode 2 of the four
    np.testing.assert_array_equal(later.actions, collected.actions[collected.episode == 2])


# ---------------------------------------------------------------------------------- what is collected


def replay_in_the_agents_env(cfg, collected, agent_env: CrowdNavSB3VecEnv):
    """Replay every demonstration episode's actions in a one-world env that observes like the agent's; check each step."""
    for episode in collected.outcomes:
        rows = np.flatnonzero(collected.episode == episode)
        env = CrowdNavSB3VecEnv.make(cfg.scenario, 1, demonstration_seed(cfg.seed, episode), agent_env.scales,
                                     encoder=agent_env.encoder, **{k: v for k, v in env_options(cfg).items() if k != "scenario"})
        observation = env.reset()
        for step, row in enumerate(rows):
            for key in observation:
                np.testing.assert_allclose(collected.observations[key][row], observation[key][0], atol=1e-6, err_msg=f"{key} {step}")
            observation, reward, done, info = env.step(collected.actions[row][None])
            assert reward[0] == pytest.approx(collected.rewards[row])
            assert bool(done[0]) == bool(collected.dones[row]) == (row == rows[-1])
            after = info[0]["terminal_observation"] if done[0] else {key: values[0] for key, values in observation.items()}
            for key in after:
                np.testing.assert_allclose(collected.next_observations[key][row], after[key], atol=1e-6)
        env.close()


def test_observations_are_the_agents_normalised_ones_and_actions_what_the_env_takes(lidar_demonstrations):
    cfg, collected = lidar_demonstrations
    agent_env = make_vec_env(cfg)
    scales, encoder = agent_view(agent_env)
    assert encoder is None and set(scales) == {"lidar", "goal"}
    raw_goal_high = make_env(cfg.model_copy(update={"normalize_observations": False})).observation_space["goal"].high[0]
    assert collected.observations["goal"][:, 0].max() <= 2.0 < raw_goal_high  # goal distance in world diagonals, not metres
    assert collected.actions.dtype == np.float32 and collected.actions.shape[1:] == (2,)
    assert all(agent_env.action_space.contains(action) for action in collected.actions)
    np.testing.assert_array_equal(collected.actions, collected.expert_actions)
    replay_in_the_agents_env(cfg, collected, agent_env)


def test_frozen_leog_demonstrations_hold_the_encoders_latent(tmp_path):
    from crowdnav.agents.networks.encoders import LeogEncoder, leog_architecture

    cfg = config(tmp_path, modalities=["leog", "goal"])
    torch.manual_seed(0)
    encoder = LeogEncoder(leog_architecture((1, 30, 30), [4, 8], [4, 3], [4, 2], latent=8))
    agent_env = make_vec_env(cfg, encoder)
    collected = collect_demonstrations(cfg, 2, scales=agent_env.scales, encoder=agent_env.encoder)
    assert collected.observations["leog"].shape[1:] == (8,) and collected.observations["leog"].dtype == np.float32
    replay_in_the_agents_env(cfg, collected, agent_env)


def test_the_single_env_path_reads_the_same_scaling(tmp_path):
    cfg = config(tmp_path, algo="ppo", num_envs=1)
    model = make_model(cfg, make_env(cfg))
    scales, encoder = agent_view(model.get_env())
    assert encoder is None
    for key, (offset, scale) in demos.declared_scales(cfg).items():
        np.testing.assert_array_equal(scales[key][0], offset)
        np.testing.assert_array_equal(scales[key][1], scale)


# ----------------------------------------------------------------------------------------------- cloning


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
def test_behaviour_cloning_reduces_the_action_error_on_the_demonstrations(lidar_demonstrations, tmp_path, algo):
    _, collected = lidar_demonstrations
    cfg = config(tmp_path, algo=algo)  # the same environment
    model = make_model(cfg, make_vec_env(cfg))
    report = behaviour_cloning(model, collected, epochs=60, batch_size=64, learning_rate=3e-3, gamma=0.95, seed=0)
    assert report["action_mse_after"] < 0.5 * report["action_mse_before"]
    assert report["value_mse_after"] < report["value_mse_before"]
    if algo == "ppo":
        np.testing.assert_allclose(model.policy.log_std.detach().exp().numpy(), 0.3, rtol=1e-6)
    else:  # the targets start where the trained networks are
        for net, target in ((model.critic, model.critic_target), *(((model.actor, model.actor_target),) if algo == "td3" else ())):
            for a, b in zip(net.state_dict().values(), target.state_dict().values(), strict=True):
                torch.testing.assert_close(a, b)


def test_the_replay_buffer_holds_the_demonstrations_one_run_per_column(lidar_demonstrations, tmp_path):
    cfg, collected = lidar_demonstrations
    model = make_model(cfg, make_vec_env(cfg))
    added = add_to_replay_buffer(model, collected, reward_scale=2.0)
    buffer, columns = model.replay_buffer, model.replay_buffer.n_envs
    rows = len(collected) // columns
    assert columns == 3 and added == rows * columns and buffer.pos == rows
    for column in range(columns):
        index = column * rows + np.arange(rows)
        np.testing.assert_array_equal(buffer.actions[:rows, column], collected.actions[index])
        np.testing.assert_allclose(buffer.rewards[:rows, column], 2.0 * collected.rewards[index])
        np.testing.assert_allclose(buffer.observations["goal"][:rows, column], collected.observations["goal"][index])
        # the run's last transition ends it (a time-limit cut when its episode goes on): no n-step window leaves it
        assert buffer.dones[rows - 1, column] and (buffer.timeouts[rows - 1, column] or collected.terminated[index[-1]])
        np.testing.assert_array_equal(buffer.dones[: rows - 1, column], collected.dones[index[:-1]])
    assert buffer.sample(8).rewards.shape == (8, 1)


def test_warm_start_fills_the_buffer_only_when_asked_and_writes_its_report(tmp_path):
    for into in (True, False):
        cfg = config(tmp_path / str(into), demonstrations={"episodes": 2, "epochs": 2, "into_replay_buffer": into})
        (tmp_path / str(into) / "sac").mkdir(parents=True)
        model = make_model(cfg, make_vec_env(cfg))
        report = warm_start(model, cfg)
        assert (report["replay_buffer"] > 0) == into and model.replay_buffer.pos == report["replay_buffer"] // 3
        assert json.loads((tmp_path / str(into) / "sac" / REPORT_FILE).read_text()) == report
        assert report["episodes"] == 2 and report["rounds"][0]["action_mse_after"] < report["rounds"][0]["action_mse_before"]


def test_a_training_run_keeps_the_demonstrations_in_its_buffer(tmp_path):
    result = train(tiny_config(tmp_path / "run", num_envs=2, episodes=2, demonstrations={"episodes": 2, "epochs": 2}))
    report = json.loads((tmp_path / "run" / REPORT_FILE).read_text())
    stored_by_training = result.model.replay_buffer.pos * 2 - report["replay_buffer"]  # the step that hit the budget is not stored
    assert report["replay_buffer"] > 0 and result.timesteps - 2 <= stored_by_training <= result.timesteps


def test_dagger_rounds_label_the_clones_own_episodes(tmp_path):
    cfg = config(tmp_path, algo="ppo", demonstrations={"episodes": 2, "epochs": 2, "dagger_rounds": 1})
    (tmp_path / "ppo").mkdir()
    report = warm_start(make_model(cfg, make_vec_env(cfg)), cfg)
    assert report["episodes"] == 4 and [r["driver"] for r in report["rounds"]] == ["social-force", "clone"]
    assert report["replay_buffer"] == 0  # on-policy: no buffer


# ----------------------------------------------------------------------------------------------- the switch


def parameters(model):
    return {name: value.clone() for name, value in model.policy.state_dict().items()}


def test_off_by_default_changes_nothing(tmp_path, monkeypatch):
    cfg = config(tmp_path)
    assert cfg.demonstrations.episodes == 0
    model = make_model(cfg, make_vec_env(cfg))
    before, rng = parameters(model), torch.get_rng_state()
    monkeypatch.setattr(demos, "collect_demonstrations", lambda *a, **k: pytest.fail("collected while off"))
    assert warm_start(model, cfg) is None
    assert torch.equal(rng, torch.get_rng_state()) and model.replay_buffer.pos == 0
    for name, value in parameters(model).items():
        assert torch.equal(value, before[name]), name
    # a whole run with the section written out at 0 is the run without it, weight for weight
    plain = train(tiny_config(tmp_path / "plain", num_envs=2, episodes=2))
    zero = train(tiny_config(tmp_path / "zero", num_envs=2, episodes=2, demonstrations={"episodes": 0, "epochs": 3}))
    for name, value in parameters(plain.model).items():
        assert torch.equal(value, parameters(zero.model)[name]), name
    assert not (tmp_path / "zero" / REPORT_FILE).exists()


def test_a_resumed_run_does_not_clone_again(tmp_path, monkeypatch):
    fields = {"num_envs": 2, "demonstrations": {"episodes": 2, "epochs": 2}}
    first = train(tiny_config(tmp_path / "run", algo="ppo", episodes=2, **fields))
    report = (tmp_path / "run" / REPORT_FILE).read_text()
    assert json.loads(report)["episodes"] == 2 and first.episodes == 2
    monkeypatch.setattr(demos, "collect_demonstrations", lambda *a, **k: pytest.fail("cloned again on resume"))
    resumed = train(tiny_config(tmp_path / "run", algo="ppo", episodes=4, **fields), resume=True)
    assert resumed.episodes == 4 and (tmp_path / "run" / REPORT_FILE).read_text() == report
