"""The multi-modal extractor and its parts: RBF layer, LEOG CNN/decoder, branch sizes, grid scaling."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from crowdnav.agents.networks.encoders import LeogAutoencoder, LeogEncoder, LidarEncoder, leog_architecture
from crowdnav.agents.networks.extractor import ENCODERS, MultiModalExtractor, register_encoder
from crowdnav.agents.networks.rbf import GaussianRBF
from gymnasium import spaces
from torch import nn

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


# ------------------------------------------------------------- fast paths = the plain formulas


@pytest.mark.parametrize("centres", [16, 5, 1])
@pytest.mark.parametrize("rows", [1, 7, 256])
@pytest.mark.parametrize("keep_input", [True, False])
def test_rbf_fast_path_gives_the_plain_formula_to_the_last_bit(centres, rows, keep_input):
    rbf = GaussianRBF(np.array([0.0, -1.0, -3.0]), np.array([2.0, 1.0, 5.0]), centres, keep_input=keep_input)
    x = torch.rand(rows, 3, generator=torch.Generator().manual_seed(rows)) * 10 - 4  # also outside the bounds
    assert torch.equal(rbf(x), rbf.reference_forward(x))
    # new centres and widths (e.g. load_state_dict) reach the fast path's precomputed constants
    rbf.load_state_dict({"centre": rbf.centre * 0.5, "log_width": rbf.log_width + 0.3, "_scale": rbf._scale, "_offset": rbf._offset,
                         "_finite": rbf._finite})
    assert torch.equal(rbf(x), rbf.reference_forward(x))
    rbf.reference = True
    assert torch.equal(rbf(x), rbf.reference_forward(x))


def test_rbf_gradients_with_respect_to_the_input_and_trainable_centres_still_flow():
    rbf = GaussianRBF(np.zeros(2), np.ones(2), centres=4)
    x = torch.rand(3, 2, requires_grad=True)
    rbf(x).sum().backward()  # the fast path's in-place ops would fail here: the plain formula is used
    assert x.grad is not None and x.grad.abs().sum() > 0
    trainable = GaussianRBF(np.zeros(2), np.ones(2), centres=4, trainable=True)
    trainable(torch.rand(3, 2)).sum().backward()
    assert trainable.centre.grad is not None


@pytest.mark.parametrize("dtype", [torch.uint8, torch.float32])
def test_binarize_equals_the_plain_comparison_and_reuses_its_result_for_the_same_unchanged_tensor(dtype):
    from crowdnav.agents.networks.extractor import binarize

    grid = (torch.rand(4, 1, 6, 6) > 0.7).to(dtype) * (255 if dtype == torch.uint8 else 1)
    binary = binarize(grid)
    assert binary.dtype == torch.float32 and torch.equal(binary, (grid > 0).float())
    assert binarize(grid) is binary  # the critic and target networks read the actor's result
    assert binarize(grid.clone()) is not binary  # another tensor: computed again
    grid[0] = 0  # changed in place: its version moved on
    assert torch.equal(binarize(grid), (grid > 0).float())


def test_extractor_on_sampled_tensors_equals_sb3_preprocessing_and_the_reference_path():
    from stable_baselines3.common.preprocessing import preprocess_obs

    env = CrowdNavEnv("room_furniture", modalities=ALL)
    config = {"lidar_hidden": [32], "lowdim_hidden": [8], "rbf_centres": 4, "leog_latent": 24, "leog_head": [16]}
    fast = MultiModalExtractor(env.observation_space, config)
    plain = MultiModalExtractor(env.observation_space, config, reference=True)
    plain.load_state_dict(fast.state_dict())
    observations = [env.reset(seed=seed)[0] for seed in range(3)]
    raw = {key: torch.as_tensor(np.stack([o[key] for o in observations])) for key in observations[0]}
    assert raw["leog"].dtype == torch.uint8 and raw["leog"].max() == 255
    expected = plain(preprocess_obs(raw, env.observation_space, normalize_images=True))  # what SB3 alone would compute
    assert torch.equal(fast(fast.prepare(raw, normalize_images=True)), expected)
    assert torch.equal(fast(preprocess_obs(raw, env.observation_space, normalize_images=True)), expected)
    assert torch.equal(fast(fast.prepare(raw, normalize_images=False)), expected)


def test_parameter_free_transforms_run_once_per_batch_and_are_shared_only_between_equal_constants():
    from crowdnav.agents.networks.encoders import LowDimEncoder

    scan = torch.rand(5, 8)
    first, same, other = (LidarEncoder(np.zeros(8), np.full(8, high), hidden=[4]) for high in (1.0, 1.0, 2.0))
    assert first.proximity(scan) is same.proximity(scan)  # the actor's, critic's and target's LIDAR branches
    torch.testing.assert_close(other.proximity(scan), (2.0 - scan) / 2.0)
    assert first.proximity(scan.clone()) is not first.proximity(scan)
    goal = torch.rand(5, 3)
    first, same, other = (LowDimEncoder(np.zeros(3), np.full(3, high), 4, [4]) for high in (1.0, 1.0, 3.0))
    assert first.rbf(goal) is same.rbf(goal)
    assert torch.equal(other.rbf(goal), other.rbf.reference_forward(goal)) and not torch.equal(other.rbf(goal), first.rbf(goal))
    with torch.inference_mode():  # no inference tensors kept for a later backward pass
        assert first.rbf(goal) is not first.rbf(goal)
