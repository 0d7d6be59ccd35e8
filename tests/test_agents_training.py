"""Every algorithm trains end to end on every modality set through the shared extractor."""

from __future__ import annotations

import numpy as np
import pytest
from agents_tiny import tiny_config

from agents import train
from agents.extractor import MultiModalExtractor
from crowdnav.simulator import OUTCOMES

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

    from agents.replay_buffer import PackedGridReplayBuffer

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
    from agents import ConfigError

    config = tiny_config(tmp_path, modalities=["leog", "goal"], episodes=1, max_steps=20,
                         policy_kwargs={"share_features_extractor": True}, algo_kwargs={"train_freq": 4, "tau": 0.02})
    model = train(config).model
    assert model.critic.features_extractor is model.actor.features_extractor and model.tau == 0.02
    with pytest.raises(ConfigError, match="net_arch are set by crowdnav"):
        train(tiny_config(tmp_path / "a", policy_kwargs={"net_arch": [8]}))
    with pytest.raises(ConfigError, match="algo_kwargs / policy_kwargs for sac: .*unexpected keyword argument 'taus'"):
        train(tiny_config(tmp_path / "b", algo_kwargs={"taus": 1}))


def test_progress_bar_and_tensorboard_option(tmp_path, capsys):
    import importlib.util

    from agents import ConfigError

    train(tiny_config(tmp_path, episodes=2, max_steps=10, progress=True))
    assert "2/2" in capsys.readouterr().err  # tqdm's bar on stderr: episodes done / total
    if importlib.util.find_spec("tensorboard") is None:
        with pytest.raises(ConfigError, match="pip install tensorboard"):
            train(tiny_config(tmp_path / "tb", episodes=1, tensorboard=True))
    else:
        train(tiny_config(tmp_path / "tb", episodes=1, max_steps=10, tensorboard=True))
        assert any((tmp_path / "tb" / "tensorboard").iterdir())


def test_n_step_returns_reach_the_replay_buffer_and_are_refused_for_on_policy_algorithms(tmp_path):
    from agents import ConfigError

    model = train(tiny_config(tmp_path, episodes=1, max_steps=20, n_step_returns=5, gamma=0.95)).model
    assert (model.replay_buffer.n_steps, model.replay_buffer.gamma) == (5, 0.95)
    assert model.replay_buffer.sample(4).discounts is not None  # SAC bootstraps with gamma ** k, not gamma
    with pytest.raises(ConfigError, match="n_step_returns does not apply to a2c"):
        train(tiny_config(tmp_path / "a2c", algo="a2c", n_step_returns=5))
