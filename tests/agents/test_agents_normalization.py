"""Observation normalisation: the wrapper, the training switch, and checkpoints that apply what the model saw."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from crowdnav.agents import ConfigError, load_policy, train
from crowdnav.agents.sb3.factory import make_env, observation_normalization
from crowdnav.agents.training.config import config_from_mapping
from crowdnav.agents.training.wrappers import NormalizeObservation, normalize_observation, observation_scales

from crowdnav.envs import CrowdNavEnv
from crowdnav.sim.simulator import OUTCOMES
from tests.agents.agents_tiny import tiny_config

FLOAT_KEYS = ["goal", "closest_obstacle", "lidar", "velocity"]
ALL_KEYS = ["goal", "closest_obstacle", "lidar", "leog", "velocity"]


def raw_observations(env_options: dict, seed: int = 7, steps: int = 8) -> list[dict[str, np.ndarray]]:
    """Raw CrowdNavEnv observations of a few random steps."""
    env = CrowdNavEnv(**env_options)
    rng = np.random.default_rng(seed)
    observation, _ = env.reset(seed=seed)
    observations = [observation]
    for _ in range(steps):
        observation, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, size=2).astype(np.float32))
        observations.append(observation)
        if terminated or truncated:
            break
    env.close()
    return observations


@pytest.fixture(scope="module")
def normalized_run(tmp_path_factory):
    """A tiny SAC run with the default (normalised) observations, and its in-memory model."""
    out = tmp_path_factory.mktemp("normalized")
    result = train(tiny_config(out, modalities=FLOAT_KEYS, episodes=2))
    return out, result.model


@pytest.fixture(scope="module")
def raw_run(tmp_path_factory):
    """The same run with normalize_observations off."""
    out = tmp_path_factory.mktemp("raw")
    result = train(tiny_config(out, modalities=FLOAT_KEYS, episodes=2, normalize_observations=False))
    return out, result.model


# ------------------------------------------------------------------------- the wrapper


def test_wrapper_space_contains_its_observations_and_passes_the_gymnasium_checker():
    from gymnasium.utils.env_checker import check_env

    env = NormalizeObservation(CrowdNavEnv("room_furniture", modalities=ALL_KEYS))
    assert env.observation_space["leog"] == env.env.observation_space["leog"]  # the uint8 grid is left alone
    assert all(env.observation_space[key].dtype == np.float32 for key in FLOAT_KEYS)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*different from the unwrapped version.*")
        check_env(env, skip_render_check=True)
    rng = np.random.default_rng(1)
    for episode in range(2):
        observation, _ = env.reset(seed=episode)
        for _ in range(40):
            assert env.observation_space.contains(observation)
            observation, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, size=2).astype(np.float32))
            if terminated or truncated:
                break


def test_wrapper_divides_by_the_declared_scales_and_passes_the_grid_through():
    raw_env = CrowdNavEnv("room_furniture", modalities=ALL_KEYS)
    env = NormalizeObservation(CrowdNavEnv("room_furniture", modalities=ALL_KEYS))
    raw, _ = raw_env.reset(seed=3)
    normalized, _ = env.reset(seed=3)
    scenario = raw_env.scenario
    assert set(env.scales) == set(FLOAT_KEYS)
    np.testing.assert_allclose(normalized["goal"][0], raw["goal"][0] / scenario.world_diagonal, rtol=1e-6)
    np.testing.assert_allclose(normalized["goal"][1:], raw["goal"][1:])  # sin and cos stay as they are
    np.testing.assert_allclose(normalized["closest_obstacle"][0], raw["closest_obstacle"][0] / scenario.sensors.closest_obstacle.max_range,
                               rtol=1e-6)
    np.testing.assert_array_equal(normalized["lidar"], raw["lidar"])
    np.testing.assert_array_equal(normalized["leog"], raw["leog"])
    assert normalized["leog"].dtype == np.uint8


def test_wrapper_works_on_a_registered_gym_make_env_for_plain_sb3():
    import gymnasium as gym
    from stable_baselines3.common.env_checker import check_env

    inner = gym.make("crowdnav/OpenSpace-v0", modalities=["goal", "velocity"])
    assert set(observation_scales(inner)) == {"goal", "velocity"}
    env = NormalizeObservation(inner)
    assert observation_scales(env) == {} and NormalizeObservation(env).scales == {}  # wrapping twice scales once
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*different from the unwrapped version.*")
        check_env(env, warn=False)


# ------------------------------------------------------------------------- the training switch


def test_make_env_normalizes_by_default_and_switching_it_off_gives_the_raw_observations():
    options = {"scenario": "open_space", "modalities": FLOAT_KEYS}
    raw, _ = CrowdNavEnv(**options).reset(seed=11)
    on = make_env(config_from_mapping(options))
    off = make_env(config_from_mapping({**options, "normalize_observations": False}))
    assert observation_normalization(off) is None and observation_normalization(on) is not None
    assert off.observation_space == CrowdNavEnv(**options).observation_space
    normalized, _ = on.reset(seed=5)  # EpisodeSeeds: the first training seed, whatever is passed
    unscaled, _ = off.reset(seed=5)
    for key in FLOAT_KEYS:
        assert on.observation_space[key].contains(normalized[key])
    np.testing.assert_allclose(normalized["goal"][0] * on.unwrapped.scenario.world_diagonal, unscaled["goal"][0], rtol=1e-5)
    assert unscaled["goal"][0] > 1.0 and normalized["goal"][0] <= 1.0 and raw["goal"][0] > 1.0


def test_frozen_latent_wrapper_on_top_of_the_normalisation_still_encodes_the_raw_grid():
    import torch
    from crowdnav.agents.networks.encoders import LeogEncoder, leog_architecture
    from crowdnav.agents.training.wrappers import LeogLatentWrapper, encode_grids

    env = NormalizeObservation(CrowdNavEnv("room_furniture", modalities=["leog", "goal"], sensors={"leog": {"size": 3.0}}))
    torch.manual_seed(0)
    encoder = LeogEncoder(leog_architecture((1, 30, 30), [4, 8], [4, 3], [4, 2], latent=8))
    wrapped = LeogLatentWrapper(env, encoder)
    observation, _ = wrapped.reset(seed=2)
    grid = env.unwrapped.core.modalities["leog"].observe(env.unwrapped.simulator)
    np.testing.assert_allclose(observation["leog"], encode_grids(encoder, grid[None])[0], atol=1e-6)
    assert wrapped.observation_space["goal"].high[0] == pytest.approx(2.0)  # normalised underneath
    assert observation_scales(wrapped) == {}  # neither the latent nor the goal is scaled a second time


# ------------------------------------------------------------------------- checkpoints


def test_model_trained_with_normalisation_saves_and_load_policy_reproduces_its_actions(normalized_run):
    out, model = normalized_run
    info = json.loads((out / "checkpoint" / "policy.json").read_text())
    assert set(info["observation_normalization"]) == set(FLOAT_KEYS) and info["config"]["normalize_observations"] is True
    assert model.observation_space["goal"].high[0] == pytest.approx(2.0)  # the model saw goal distances in diagonals
    policy = load_policy(out)
    assert "normalize_observations" not in policy.env_options  # still exactly CrowdNavEnv's keyword arguments
    observations = raw_observations(policy.env_options)
    for observation in observations:
        expected, _ = model.predict(normalize_observation(observation, policy.scales), deterministic=True)
        np.testing.assert_allclose(policy(observation), expected, atol=1e-6)
    batch = {key: np.stack([o[key] for o in observations]) for key in FLOAT_KEYS}
    np.testing.assert_allclose(policy(batch), [policy(o) for o in observations], atol=1e-6)
    env = policy.make_env()
    observation, _ = env.reset(seed=4)
    np.testing.assert_allclose(policy.preprocess(observation)["goal"][0], observation["goal"][0] / env.scenario.world_diagonal, rtol=1e-6)


def test_evaluation_feeds_the_policy_normalised_observations(normalized_run):
    from crowdnav.evaluation.rollout import HeldOutEpisodes

    out, _ = normalized_run
    policy = load_policy(out)
    seen = []
    predict = policy.model.predict
    policy.model.predict = lambda observation, *args, **kwargs: (seen.append(observation), predict(observation, *args, **kwargs))[1]
    episodes = HeldOutEpisodes(policy.env_options, [0])
    rows = episodes.run(policy)
    episodes.close()
    assert rows[0]["outcome"] in OUTCOMES
    first = raw_observations(policy.env_options, seed=0, steps=0)[0]
    expected = normalize_observation({key: value[None] for key, value in first.items()}, policy.scales)
    for key in FLOAT_KEYS:
        np.testing.assert_allclose(seen[0][key], expected[key], rtol=1e-6)
    assert max(float(o["goal"][:, 0].max()) for o in seen) <= 2.0


def test_a_run_without_normalisation_stores_null_and_its_policy_sees_raw_observations(raw_run):
    out, model = raw_run
    info = json.loads((out / "checkpoint" / "policy.json").read_text())
    assert info["observation_normalization"] is None
    policy = load_policy(out)
    assert policy.scales is None and model.observation_space == policy.make_env().observation_space
    for observation in raw_observations(policy.env_options):
        expected, _ = model.predict(observation, deterministic=True)
        np.testing.assert_allclose(policy(observation), expected, atol=1e-6)


def test_an_old_policy_json_without_the_key_loads_and_resumes_unnormalised(tmp_path):
    out = tmp_path / "old"
    result = train(tiny_config(out, modalities=FLOAT_KEYS, episodes=2, max_steps=20, normalize_observations=False))
    for file in [out / "checkpoint" / "policy.json", *out.glob("snapshots/*/policy.json")]:  # as written before the option existed
        info = json.loads(file.read_text())
        del info["observation_normalization"], info["config"]["normalize_observations"]
        file.write_text(json.dumps(info))
    policy = load_policy(out)
    assert policy.scales is None
    for observation in raw_observations(policy.env_options):
        expected, _ = result.model.predict(observation, deterministic=True)
        np.testing.assert_allclose(policy(observation), expected, atol=1e-6)
    with pytest.warns(UserWarning, match="predates observation normalisation"):  # the config's default is on
        resumed = train(tiny_config(out, modalities=FLOAT_KEYS, episodes=3, max_steps=20), resume=True)
    assert resumed.episodes == 3 and resumed.model.observation_space == policy.make_env().observation_space
    assert json.loads((out / "checkpoint" / "policy.json").read_text())["observation_normalization"] is None


def test_resuming_with_the_other_setting_is_a_clear_error(tmp_path):
    train(tiny_config(tmp_path, episodes=1, max_steps=10))
    with pytest.raises(ConfigError, match="trained with normalize_observations: true, the config asks for false"):
        train(tiny_config(tmp_path, episodes=2, max_steps=10, normalize_observations=False), resume=True)


def test_crowdnavs_extractor_gives_the_same_latent_on_raw_and_scaled_observations():
    import torch
    from crowdnav.agents.networks.extractor import MultiModalExtractor

    from crowdnav.envs import CrowdNavEnv

    raw_env = CrowdNavEnv("room_furniture", modalities=["goal", "closest_obstacle", "lidar", "velocity"])
    scaled_env = NormalizeObservation(CrowdNavEnv("room_furniture", modalities=["goal", "closest_obstacle", "lidar", "velocity"]))
    torch.manual_seed(0)
    raw_extractor = MultiModalExtractor(raw_env.observation_space)
    scaled_extractor = MultiModalExtractor(scaled_env.observation_space)
    # the same weights; each keeps its own buffers (the RBF's input bounds, taken from its space)
    weights = dict(raw_extractor.named_parameters())
    scaled_extractor.load_state_dict({k: v for k, v in raw_extractor.state_dict().items() if k in weights}, strict=False)
    raw, _ = raw_env.reset(seed=3)
    scaled, _ = scaled_env.reset(seed=3)
    for _ in range(5):
        action = np.array([0.6, 0.2])
        with torch.no_grad():
            a = raw_extractor({k: torch.as_tensor(v[None]).float() for k, v in raw.items()})
            b = scaled_extractor({k: torch.as_tensor(v[None]).float() for k, v in scaled.items()})
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-5)
        raw, *_ = raw_env.step(action)
        scaled, *_ = scaled_env.step(action)
