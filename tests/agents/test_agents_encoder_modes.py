"""LEOG encoder modes: frozen keeps the pre-trained weights, finetune trains them, precompute feeds latents."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from crowdnav.agents import load_policy, train
from crowdnav.agents.sb3.factory import extractors
from crowdnav.agents.training.wrappers import LeogLatentWrapper, NormalizeObservation

from tests.agents.agents_tiny import TINY_EXTRACTOR, tiny_config


def saved_encoder_state(path) -> dict[str, torch.Tensor]:
    return torch.load(path, weights_only=True)["encoder"]


def leog_states(model) -> list[dict[str, torch.Tensor]]:
    """State dicts of the LEOG encoder in the actor's and critic's extractors (not the target copies)."""
    return [extractor.leog_encoders[0].state_dict() for extractor in (model.actor.features_extractor, model.critic.features_extractor)]


def equal(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_frozen_encoder_weights_are_unchanged_after_training(tmp_path, encoder_file):
    config = tiny_config(tmp_path, modalities=["leog", "goal"], encoder={"mode": "frozen", "weights": str(encoder_file), "precompute": False})
    result = train(config)
    assert result.model._n_updates > 0
    saved = saved_encoder_state(encoder_file)
    assert all(equal(state, saved) for state in leog_states(result.model))
    assert all(not p.requires_grad for e in extractors(result.model) for p in e.leog_encoders[0].parameters())


def test_finetuned_encoder_starts_pre_trained_and_changes_with_training(tmp_path, encoder_file):
    config = tiny_config(tmp_path, modalities=["leog", "goal"], encoder={"mode": "finetune", "weights": str(encoder_file)})
    result = train(config)
    saved = saved_encoder_state(encoder_file)
    actor_state, critic_state = leog_states(result.model)
    assert not equal(actor_state, saved) and not equal(critic_state, saved)
    # the critic's target copy moves slowly (polyak), so it is still close to the pre-trained start
    target = result.model.critic_target.features_extractor.leog_encoders[0].state_dict()
    assert all(torch.allclose(target[k], saved[k], atol=0.05) for k in saved)


def test_scratch_encoder_does_not_start_from_pre_trained_weights(tmp_path, encoder_file):
    result = train(tiny_config(tmp_path, modalities=["leog", "goal"], episodes=1))
    saved = saved_encoder_state(encoder_file)
    assert not any(equal(state, saved) for state in leog_states(result.model))


def test_precomputed_frozen_latent_replaces_the_grid_and_the_policy_applies_the_encoder(tmp_path, encoder_file):
    config = tiny_config(tmp_path, modalities=["leog", "goal"], encoder={"mode": "frozen", "weights": str(encoder_file)})
    result = train(config)
    model = result.model
    latent = TINY_EXTRACTOR["leog_latent"]
    assert model.observation_space["leog"].shape == (latent,) and model.observation_space["leog"].dtype == np.float32
    assert model.replay_buffer.observations["leog"].shape[-1] == latent  # small float vectors in the buffer
    policy = load_policy(tmp_path)
    assert policy.encoder is not None
    env = policy.make_env()
    observation, _ = env.reset(seed=3)
    # the training env's stack: normalisation (goal in diagonals, the grid untouched), then the latent of the raw grid
    normalized = NormalizeObservation(env)
    wrapped = LeogLatentWrapper(normalized, policy.encoder).observation(normalized.observation(observation))
    assert set(policy.scales) == {"goal"} and model.observation_space["goal"] == normalized.observation_space["goal"]
    expected, _ = model.predict(wrapped, deterministic=True)
    np.testing.assert_allclose(policy(observation), expected, atol=1e-6)


def test_frozen_mode_needs_weights_of_the_right_grid_shape(tmp_path, encoder_file):
    from crowdnav.agents import ConfigError

    with pytest.raises(ConfigError, match="encoder.weights"):
        train(tiny_config(tmp_path, modalities=["leog", "goal"], encoder={"mode": "frozen"}))
    config = tiny_config(tmp_path, modalities=["leog", "goal"], encoder={"mode": "finetune", "weights": str(encoder_file)})
    config["sensors"] = {"leog": {"size": 4.0, "resolution": 0.1}}
    with pytest.raises(ConfigError, match=r"expects grids of shape \(1, 30, 30\), but the environment's leog has shape \(1, 40, 40\)"):
        train(config)
    config["encoder"]["mode"] = "frozen"  # the precompute wrapper checks it too
    with pytest.raises(ConfigError, match=r"expects grids of shape \(1, 30, 30\)"):
        train(config)
