"""Every algorithm trains end to end on every modality set through the shared extractor."""

from __future__ import annotations

import numpy as np
import pytest
from crowdnav.agents import train
from crowdnav.agents.networks.extractor import MultiModalExtractor

from crowdnav.sim.simulator import OUTCOMES
from tests.agents.agents_tiny import tiny_config

MODALITY_SETS = {"lidar+goal": ["lidar", "goal"], "leog+goal": ["leog", "goal"], "leog+lidar+goal": ["leog", "lidar", "goal"]}


@pytest.mark.parametrize("modalities", list(MODALITY_SETS.values()), ids=list(MODALITY_SETS))
@pytest.mark.parametrize("algo", ["sac", "td3", "ddpg", "a2c"])
def test_algorithm_trains_end_to_end_on_modality_set(tmp_path, algo, modalities):
    result = train(tiny_config(tmp_path, algo=algo, modalities=modalities, episodes=3))
    model = result.model
    assert result.episodes == 3 and len(result.records) == 3
    assert result.timesteps == sum(record.length for record in result.records) > 30
    assert all(record.outcome in OUTCOMES for record in result.records)
    extractor = model.policy.features_extractor if algo == "a2c" else model.actor.features_extractor
    assert isinstance(extractor, MultiModalExtractor) and set(extractor.branches) == set(modalities)
    assert model._n_updates > 0  # gradient steps happened, not only data collection
    observation = {key: space.sample() for key, space in model.observation_space.spaces.items()}
    action, _ = model.predict(observation, deterministic=True)
    assert action.shape == (2,) and np.all(np.abs(action) <= 1.0)


def test_ppo_trains_too(tmp_path):
    result = train(tiny_config(tmp_path, algo="ppo", modalities=["leog", "goal"], episodes=2))
    assert result.episodes == 2 and result.model._n_updates > 0


def test_training_stops_after_the_requested_episodes_and_logs_each(tmp_path):
    result = train(tiny_config(tmp_path, episodes=5, max_steps=20))
    lines = (tmp_path / "episodes.csv").read_text().splitlines()
    assert lines[0].startswith("episode,seed,outcome") and len(lines) == 6
    assert [int(line.split(",")[0]) for line in lines[1:]] == [0, 1, 2, 3, 4]
    assert result.success_rate == sum(r.outcome == "success" for r in result.records) / 5
    assert sorted(p.name for p in (tmp_path / "snapshots").iterdir()) == ["episode_00002", "episode_00004", "episode_00005"]


def test_packed_replay_buffer_gives_back_the_grids_at_one_bit_per_cell(tmp_path):
    import torch
    from crowdnav.agents.sb3.replay_buffer import PackedGridReplayBuffer

    result = train(tiny_config(tmp_path, modalities=["leog", "goal"], episodes=1, max_steps=20, scenario="room_furniture"))
    buffer = result.model.replay_buffer
    assert isinstance(buffer, PackedGridReplayBuffer)
    assert buffer.observations["leog"].shape[-1] == 30 * 30 // 8 + 1  # 113 bytes instead of 900
    env = result.model.get_env()
    observations = [env.reset()]
    for _ in range(5):
        observations.append(env.step(np.zeros((1, 2), dtype=np.float32))[0])
    fresh = PackedGridReplayBuffer(10, env.observation_space, env.action_space, device="cpu")
    for before, after in zip(observations, observations[1:], strict=False):
        fresh.add(before, after, np.zeros((1, 2)), np.zeros(1), np.zeros(1), [{}])
    samples = fresh._get_samples(np.arange(5))
    expected = np.concatenate([o["leog"] for o in observations[:5]])
    assert 0 < (expected > 0).mean() < 1  # walls and furniture in view, so the comparison means something
    assert samples.observations["leog"].dtype == torch.uint8
    np.testing.assert_array_equal(samples.observations["leog"].numpy(), expected)
    np.testing.assert_array_equal(samples.next_observations["leog"].numpy(), np.concatenate([o["leog"] for o in observations[1:]]))
    np.testing.assert_array_equal(samples.observations["goal"].numpy(), np.concatenate([o["goal"] for o in observations[:5]]))


def test_policy_and_algorithm_options_reach_sb3_and_clashes_are_errors(tmp_path):
    from crowdnav.agents import ConfigError

    config = tiny_config(tmp_path, modalities=["leog", "goal"], episodes=1, max_steps=20,
                         policy_kwargs={"share_features_extractor": True}, algo_kwargs={"train_freq": 4, "tau": 0.02})
    model = train(config).model
    assert model.critic.features_extractor is model.actor.features_extractor and model.tau == 0.02
    with pytest.raises(ConfigError, match="net_arch are set by crowdnav"):
        train(tiny_config(tmp_path / "a", policy_kwargs={"net_arch": [8]}))
    with pytest.raises(ConfigError, match="algo_kwargs / policy_kwargs for sac: .*unexpected keyword argument 'taus'"):
        train(tiny_config(tmp_path / "b", algo_kwargs={"taus": 1}))


def test_progress_bar_and_tensorboard_option(tmp_path, capsys, monkeypatch):
    import importlib.util

    from crowdnav.agents import ConfigError

    from crowdnav.cli import main

    train(tiny_config(tmp_path, episodes=2, max_steps=10, progress=True))
    assert "2/2" in capsys.readouterr().err  # tqdm's bar on stderr: episodes done / total
    assert main(["train", "--tensorboard", "--print-config"]) == 0 and "tensorboard: true" in capsys.readouterr().out
    if importlib.util.find_spec("tensorboard") is not None:  # the dev extra installs it
        train(tiny_config(tmp_path / "tb", episodes=1, max_steps=10, tensorboard=True))
        assert any((tmp_path / "tb" / "tensorboard").iterdir())
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *args: None if name == "tensorboard" else real(name, *args))
    with pytest.raises(ConfigError, match=r'pip install -e "\.\[tensorboard\]" in crowdnav\'s clone$'):
        train(tiny_config(tmp_path / "tb2", episodes=1, tensorboard=True))



def test_n_step_returns_reach_the_replay_buffer_and_are_refused_for_on_policy_algorithms(tmp_path):
    from crowdnav.agents import ConfigError

    model = train(tiny_config(tmp_path, episodes=1, max_steps=20, n_step_returns=5, gamma=0.95)).model
    assert (model.replay_buffer.n_steps, model.replay_buffer.gamma) == (5, 0.95)
    assert model.replay_buffer.sample(4).discounts is not None  # SAC bootstraps with gamma ** k, not gamma
    with pytest.raises(ConfigError, match="n_step_returns does not apply to a2c"):
        train(tiny_config(tmp_path / "a2c", algo="a2c", n_step_returns=5))


# ------------------------------------------------ crowdnav's faster SAC/TD3/DDPG = SB3's own


@pytest.mark.parametrize("modalities", [["lidar", "goal"], ["leog", "goal", "velocity"]], ids=["lidar+goal", "leog+goal+velocity"])
@pytest.mark.parametrize("algo", ["sac", "td3", "ddpg"])
def test_fast_training_gives_the_networks_sb3s_own_classes_give_to_the_last_bit(tmp_path, algo, modalities):
    """Same seed: crowdnav's algorithms, extractor and replay-buffer fast paths = SB3's classes and the plain paths."""
    import torch
    from crowdnav.agents.sb3.algorithms import CrowdNavDDPG, CrowdNavSAC, CrowdNavTD3
    from crowdnav.agents.sb3.factory import make_env, make_model
    from crowdnav.agents.training.config import config_from_mapping
    from stable_baselines3 import DDPG, SAC, TD3

    states, classes = [], []
    for reference in (True, False):
        config = config_from_mapping(tiny_config(tmp_path, algo=algo, modalities=modalities, max_steps=40))
        model = make_model(config, make_env(config), reference=reference)
        model.learn(160)
        assert model._n_updates > 20
        states.append(model.policy.state_dict())
        classes.append(type(model))
    assert classes == [{"sac": SAC, "td3": TD3, "ddpg": DDPG}[algo], {"sac": CrowdNavSAC, "td3": CrowdNavTD3, "ddpg": CrowdNavDDPG}[algo]]
    assert states[0].keys() == states[1].keys()
    assert all(torch.equal(states[0][key], states[1][key]) for key in states[0])


def test_soft_update_equals_sb3s_polyak_update_to_the_last_bit():
    import torch
    from crowdnav.agents.sb3.algorithms import soft_update
    from stable_baselines3.common.utils import polyak_update

    generator = torch.Generator().manual_seed(0)
    params = [torch.randn(shape, generator=generator) for shape in [(64, 360), (64,), (3, 3, 2), ()]]
    targets = [torch.randn(p.shape, generator=generator) for p in params]
    expected = [t.clone() for t in targets]
    for tau in (0.005, 0.3, 1.0):
        polyak_update(params, expected, tau)
        soft_update(params, targets, tau)
        assert all(torch.equal(a, b) for a, b in zip(targets, expected, strict=True))
    with pytest.raises(ValueError, match="2 parameters but 1 target"):
        soft_update(params[:2], targets[:1], 0.1)


def test_fast_training_mode_sets_the_flags_sb3s_set_training_mode_sets(tmp_path):
    from crowdnav.agents.sb3.factory import make_env, make_model
    from crowdnav.agents.training.config import config_from_mapping
    from stable_baselines3.sac.policies import SACPolicy

    config = config_from_mapping(tiny_config(tmp_path))
    model = make_model(config, make_env(config))
    policy = model.policy
    for mode in (True, False, True):
        policy.set_training_mode(mode)
        flags = {name: module.training for name, module in policy.named_modules()}
        SACPolicy.set_training_mode(policy, not mode)  # SB3's recursive version, to the other mode and back
        SACPolicy.set_training_mode(policy, mode)
        assert flags == {name: module.training for name, module in policy.named_modules()}
        assert policy.actor.training is mode and policy.critic.features_extractor.training is mode
        assert policy.critic_target.training is False  # SB3 keeps the target network in eval mode
    with pytest.raises(ValueError, match="boolean"):
        policy.set_training_mode(1)


def test_sac_actor_written_out_gaussian_matches_sb3s_distribution(tmp_path):
    import torch
    from crowdnav.agents.sb3.factory import make_env, make_model
    from crowdnav.agents.training.config import config_from_mapping
    from stable_baselines3.sac.policies import Actor

    config = config_from_mapping(tiny_config(tmp_path, modalities=["leog", "goal"]))
    model = make_model(config, make_env(config))
    model.learn(60)
    observations = model.replay_buffer.sample(32).observations
    actor = model.actor
    results = []
    for method in (type(actor).action_log_prob, Actor.action_log_prob,
                   lambda a, o: type(a).forward(a, o), lambda a, o: Actor.forward(a, o),
                   lambda a, o: type(a).forward(a, o, True), lambda a, o: Actor.forward(a, o, True)):
        torch.manual_seed(7)
        results.append(method(actor, observations))
    for fast, sb3 in zip(results[::2], results[1::2], strict=True):
        fast, sb3 = (fast, sb3) if isinstance(fast, tuple) else ((fast,), (sb3,))
        assert all(torch.equal(a, b) for a, b in zip(fast, sb3, strict=True))
