"""Tiny training settings shared by the agents tests: small networks, short episodes, small grids."""

from __future__ import annotations

from typing import Any

import numpy as np

from crowdnav.registry import is_off_policy

TINY_EXTRACTOR = {"leog_channels": [4, 8], "leog_kernels": [4, 3], "leog_strides": [4, 2], "leog_latent": 8,
                  "lidar_hidden": [16], "rbf_centres": 4, "lowdim_hidden": [8]}
"""A 2-layer CNN that fits the 30x30 test grids, and small fully connected layers."""

SMALL_LEOG = {"leog": {"size": 3.0, "resolution": 0.1}, "lidar": {"beams": 32}}
"""30x30 grids and 32 beams instead of 60x60 and 360."""


def tiny_config(out, *, algo: str = "sac", modalities=("lidar", "goal"), episodes: int = 3, max_steps: int = 60,
                **fields: Any) -> dict[str, Any]:
    """A training config of at most ``episodes * max_steps`` steps with tiny networks.

    Off-policy algorithms take one gradient step every 4 env steps, on-policy ones update
    every 16 (A2C) or 32 (PPO) steps: enough updates to exercise the whole training path.
    One env (``num_envs: 1``) unless the test asks for more: most tests check the single-env
    path (episode seeds in order, rewound resumes); batched tests pass ``num_envs``.
    """
    config: dict[str, Any] = {
        "scenario": "open_space", "modalities": list(modalities), "algo": algo, "episodes": episodes, "seed": 0,
        "out": str(out), "overrides": {"max_steps": max_steps, "humans.count": 3}, "sensors": SMALL_LEOG,
        "net_arch": [16], "extractor": dict(TINY_EXTRACTOR), "progress": False, "checkpoint_every": 2,
        "num_envs": 1,
    }
    if is_off_policy(algo):
        config.update(batch_size=16, buffer_size=2_000, learning_starts=30, algo_kwargs={"train_freq": 4})
    elif algo == "a2c":
        config.update(algo_kwargs={"n_steps": 16})
    elif algo == "ppo":
        config.update(batch_size=16, algo_kwargs={"n_steps": 32, "n_epochs": 1})
    config.update(fields)
    return config


def recorded_observations(policy: Any, steps: int = 40, seed: int = 0) -> dict[str, np.ndarray]:
    """Raw observations ``policy`` meets acting in its own env from ``seed`` (episodes restart as they end), stacked per key."""
    env = policy.make_env()
    observation, _ = env.reset(seed=seed)
    seen = [observation]
    for _ in range(steps):
        observation, _, terminated, truncated, _ = env.step(policy(observation))
        if terminated or truncated:
            observation, _ = env.reset()
        seen.append(observation)
    env.close()
    return {key: np.stack([o[key] for o in seen]) for key in seen[0]}
