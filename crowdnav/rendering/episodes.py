"""Render whole episodes of a policy to video files (what ``crowdnav render`` runs)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from crowdnav.envs import CrowdNavEnv
from crowdnav.paths import inside
from crowdnav.policies import SCRIPTED_POLICIES
from crowdnav.rendering.video import VIDEO_FORMATS, VideoWriter

Act = Callable[[CrowdNavEnv, Mapping[str, np.ndarray]], np.ndarray]


class PolicyLoadError(ValueError):
    """A ``--policy`` value that is neither a scripted policy nor a loadable checkpoint."""


def resolve_policy(policy: str, seed: int) -> tuple[Act, dict[str, Any]]:
    """A scripted policy name or a checkpoint path -> (act(env, observation), env options it needs)."""
    if policy in SCRIPTED_POLICIES:
        scripted = SCRIPTED_POLICIES[policy](seed) if policy == "random" else SCRIPTED_POLICIES[policy]()
        return (lambda env, observation: scripted(env.simulator)), {}
    path = Path(policy)
    if not path.exists():
        raise PolicyLoadError(
            f"--policy {policy!r} is neither a scripted policy ({', '.join(SCRIPTED_POLICIES)}) nor an existing checkpoint path"
        )
    try:
        from crowdnav.agents import load_policy

        trained = load_policy(path)
    except Exception as error:  # a checkpoint can fail in many ways; report one clear line
        raise PolicyLoadError(f"cannot load checkpoint {path}: {type(error).__name__}: {error}") from None
    options = {k: v for k, v in trained.env_options.items() if k not in ("scenario", "render_mode", "render_options")}
    return (lambda env, observation: trained(observation)), options


def render_episodes(
    scenario: str,
    policy: str = "social-force",
    *,
    episodes: int = 3,
    seed: int = 0,
    out: str | Path = "videos",
    video_format: str = "mp4",
    overrides: Mapping[str, Any] | None = None,
    reward_weights: Mapping[str, Any] | None = None,
    render_options: Mapping[str, Any] | None = None,
    progress: bool = True,
) -> list[Path]:
    """Run ``episodes`` episodes (seeds ``seed``, ``seed + 1``, ...) and write one video each; returns the paths."""
    suffix = f".{video_format.lower().lstrip('.')}"
    if suffix not in VIDEO_FORMATS:
        raise ValueError(f"unsupported video format {video_format!r}; expected one of {', '.join(f[1:] for f in VIDEO_FORMATS)}")
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    act, env_options = resolve_policy(policy, seed)
    if overrides:
        env_options["overrides"] = {**env_options.get("overrides", {}), **overrides}
    if reward_weights:  # a preset and weights on top of a checkpoint's own (which win over overrides)
        env_options["reward_weights"] = {**env_options.get("reward_weights", {}), **reward_weights}
    env = CrowdNavEnv(scenario, render_mode="rgb_array", render_options=render_options, **env_options)
    label = Path(policy).stem if policy not in SCRIPTED_POLICIES else policy
    out = Path(out)
    paths = []
    bar = _progress(episodes * env.scenario.max_steps, progress)
    try:
        for episode in range(episodes):
            path = inside(out, f"{env.scenario.name}_{label}_seed{seed + episode}{suffix}")
            observation, _ = env.reset(seed=seed + episode)
            with VideoWriter(path, fps=env.metadata["render_fps"]) as writer:
                writer.append(env.render())
                done = False
                while not done:
                    observation, _, terminated, truncated, info = env.step(act(env, observation))
                    writer.append(env.render())
                    done = terminated or truncated
                    bar.update(1)
            bar.update(env.scenario.max_steps - env.simulator.step_count)  # an early end skips the rest
            bar.set_postfix_str(f"episode {episode + 1}/{episodes}: {info['outcome']}")
            paths.append(path)
    finally:
        bar.close()
        env.close()
    return paths


def _progress(total: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, unit="step", desc="rendering", disable=not enabled, leave=False)
