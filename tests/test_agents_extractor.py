"""The multi-modal extractor and its parts: RBF layer, LEOG CNN/decoder, branch sizes, grid scaling."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from gymnasium import spaces
from torch import nn

from agents.encoders import LeogAutoencoder, LeogEncoder, LidarEncoder, leog_architecture
from agents.extractor import ENCODERS, MultiModalExtractor, register_encoder
from agents.rbf import GaussianRBF
from crowdnav.envs import CrowdNavEnv

ALL = ["goal", "closest_obstacle", "lidar", "leog", "velocity"]


def batch(observations: list[dict[str, np.ndarray]]) -> dict[str, torch.Tensor]:
    return {key: torch.as_tensor(np.stack([o[key] for o in observations])).float() for key in observations[0]}


def test_rbf_output_has_scaled_inputs_then_one_bump_per_centre():
    rbf = GaussianRBF(low=np.array([0.0, -1.0]), high=np.array([10.0, 1.0]), centres=5)
    assert rbf.out_features == 2 * (5 + 1)
    x = torch.tensor([[0.0, 0.25], [10.0, -1.0]])
    out = rbf(x)
    assert out.shape == (2, 12)
    np.testing.assert_allclose(out[:, :2].numpy(), [[-1.0, 0.25], [1.0, -1.0]], atol=1e-6)  # scaled to [-1, 1]
    bumps = out[:, 2:].reshape(2, 2, 5)
    # centres at -1, -0.5, 0, 0.5, 1: value 0 of a [0, 10] input sits on the first, 10 on the last;
    # 0.25 of [-1, 1] lies half a spacing from the centres 0 and 0.5
    assert bumps[0, 0, 0] == pytest.approx(1.0) and bumps[1, 0, 4] == pytest.approx(1.0)
    assert bumps[0, 1, 2] == pytest.approx(np.exp(-0.5 * 0.25)) and bumps[0, 1, 3] == pytest.approx(np.exp(-0.5 * 0.25))
    assert torch.all((bumps > 0) & (bumps <= 1))


def test_rbf_without_centres_only_scales_and_trainable_rbf_has_parameters():
    scale_only = GaussianRBF(np.zeros(3), np.full(3, 4.0), centres=0)
    assert scale_only.out_features == 3
    np.testing.assert_allclose(scale_only(torch.full((1, 3), 2.0)).numpy(), 0.0, atol=1e-6)
    trainable = GaussianRBF(np.zeros(2), np.ones(2), centres=8, trainable=True)
    assert {name for name, _ in trainable.named_parameters()} == {"centre", "log_width"}
    with pytest.raises(ValueError, match="low < high"):
        GaussianRBF(np.ones(2), np.ones(2))


def test_extractor_latent_is_the_concatenation_of_every_branch():
    env = CrowdNavEnv("room_furniture", modalities=ALL)
    config = {"lidar_hidden": [32], "lowdim_hidden": [8], "rbf_centres": 4, "leog_latent": 24, "leog_head": [16]}
    extractor = MultiModalExtractor(env.observation_space, config)
    assert extractor.branch_sizes == {"closest_obstacle": 8, "goal": 8, "leog": 16, "lidar": 32, "velocity": 8}
    assert extractor.features_dim == 72
    observations = [env.reset(seed=seed)[0] for seed in range(3)]
    assert extractor(batch(observations)).shape == (3, 72)
    # no hidden layers: the RBF output itself (3 values x (4 centres + the scaled value))
    bare = MultiModalExtractor(spaces.Dict({"goal": env.observation_space["goal"]}), {"lowdim_hidden": [], "rbf_centres": 4})
    assert bare.features_dim == 15


def test_leog_branch_sees_the_same_binary_grid_whether_or_not_sb3_divided_by_255():
    env = CrowdNavEnv("room_furniture", modalities=["leog"])
    extractor = MultiModalExtractor(env.observation_space)
    grid = torch.as_tensor(env.reset(seed=1)[0]["leog"][None]).float()
    assert grid.max() == 255
    torch.testing.assert_close(extractor({"leog": grid}), extractor({"leog": grid / 255.0}))


def test_lidar_convolution_option_wraps_around_and_feeds_the_fully_connected_layers():
    encoder = LidarEncoder(np.zeros(360), np.ones(360), hidden=[16], conv_channels=[4, 8])
    assert encoder.out_features == 16
    assert encoder(torch.rand(2, 360)).shape == (2, 16)
    assert encoder.conv[0].padding_mode == "circular"


@pytest.mark.parametrize("side", [60, 37, 30])
def test_autoencoder_reconstructs_grids_of_the_input_shape(side):
    architecture = leog_architecture((1, side, side), [8, 16, 16], [4, 3, 3], [4, 2, 1], 32)
    grids = torch.zeros(2, 1, side, side)
    assert LeogAutoencoder(architecture)(grids).shape == grids.shape
    latent = LeogEncoder(architecture)(grids)
    assert latent.shape == (2, 32) and torch.all(latent.abs() <= 1)


def test_convolutions_too_large_for_the_grid_are_a_clear_error():
    with pytest.raises(ValueError, match="do not fit a 8x8 grid"):
        LeogEncoder(leog_architecture((1, 8, 8), [8, 16], [4, 3], [4, 2], 16))


def test_registered_encoder_replaces_the_built_in_branch():
    def goal_branch(space, config):
        return nn.Sequential(nn.Linear(space.shape[0], 5), nn.Tanh()), 5

    register_encoder("goal", goal_branch)
    try:
        extractor = MultiModalExtractor(spaces.Dict({"goal": spaces.Box(-1, 1, (3,), np.float32)}))
    finally:
        del ENCODERS["goal"]
    assert extractor.features_dim == 5 and isinstance(extractor.branches["goal"][1], nn.Tanh)


def test_frozen_mode_turns_off_gradients_of_the_cnn_only():
    env = CrowdNavEnv("room_furniture", modalities=["leog", "goal"])
    extractor = MultiModalExtractor(env.observation_space, leog_mode="frozen")
    assert not any(p.requires_grad for p in extractor.leog_encoders[0].parameters())
    assert all(p.requires_grad for p in extractor.branches["goal"].parameters())
