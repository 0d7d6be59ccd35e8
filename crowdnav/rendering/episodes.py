"""Render whole episodes of a policy to video files.

The policy is a plain callable ``act(env, observation) -> action``, or the name of a scripted
policy; a trained agent is rendered through :func:`crowdnav.agents.runs.render.render_policy`
(what ``crowdnav render`` runs), which loads the checkpoint and calls :func:`render_episodes`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from crowdnav.envs import CrowdNavEnv
from crowdnav.paths import inside
from crowdnav.planning.scripted import SCRIPTED_POLICIES
from crowdnav.rendering.video import VIDEO_FORMATS, VideoWriter

if TYPE_CHECKING:
    from tqdm import tqdm

Act = Callable[[CrowdNavEnv, Mapping[str, np.ndarray]], np.ndarray]


def scripted_act(name: str, seed: int = 0) -> Act:
    """The scripted policy ``name`` (:data:`crowdnav.planning.scripted.SCRIPTED_POLICIES`) as ``act(env, observation)``."""
    if name not in SCRIPTED_POLICIES:
        raise ValueError(f"unknown scripted policy {name!r}; expected one of: {', '.join(SCRIPTED_POLICIES)}")
    scripted = SCRIPTED_POLICIES[name](seed) if name == "random" else SCRIPTED_POLICIES[name]()
    return lambda env, observation: scripted(env.simulator)


def video_suffix(video_format: str, episodes: int) -> str:
    """The file suffix of ``video_format`` (``"mp4"`` -> ``".mp4"``), after checking it and the episode count (one-line errors)."""
    suffix = f".{video_format.lower().lstrip('.')}"
    if suffix not in VIDEO_FORMATS:
        raise ValueError(f"unsupported video format {video_format!r}; expected one of {', '.join(f[1:] for f in VIDEO_FORMATS)}")
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    return suffix


def render_episodes(
    scenario: str,
    policy: str | Act = "social-force",
    *,
    label: str | None = None,
    env_options: Mapping[str, Any] | None = None,
    episodes: int = 3,
    seed: int = 0,
    out: str | Path = "videos",
    video_format: str = "mp4",
    overrides: Mapping[str, Any] | None = None,
    reward_weights: Mapping[str, Any] | None = None,
    render_options: Mapping[str, Any] | None = None,
    progress: bool = True,
) -> list[Path]:
    """Run ``episodes`` episodes (seeds ``seed``, ``seed + 1``, ...) and write one video each; returns the paths.

    ``policy``: a scripted policy's name or ``act(env, observation) -> action``; ``label``
    names it in the file names (default: the scripted name, else ``policy``); ``env_options``:
    CrowdNavEnv keyword arguments the policy needs (e.g. a trained agent's modalities).
    """
    suffix = video_suffix(video_format, episodes)
    act = scripted_act(policy, seed) if isinstance(policy, str) else policy
    env_options = dict(env_options or {})
    if overrides:
        env_options["overrides"] = {**env_options.get("overrides", {}), **overrides}
    if reward_weights:  # a preset and weights on top of a checkpoint's own (which win over overrides)
        env_options["reward_weights"] = {**env_options.get("reward_weights", {}), **reward_weights}
    env = CrowdNavEnv(scenario, render_mode="rgb_array", render_options=render_options, **env_options)
    label = label or (policy if isinstance(policy, str) else "policy")
    out = Path(out)
    paths = []
    bar = _progress(episodes * env.scenario.max_steps, progress)
    try:
        for episode in range(episodes):
            path = inside(out, f"{env.scenario.name}_{label}_seed{seed + episode}{suffix}")
            observation, _ = env.reset(seed=seed + episode)
            # the writer drops its unfinished temporary if the episode raises; a file of that name stays as it was
            with VideoWriter(path, fps=env.metadata["render_fps"]) as writer:
                writer.append(_frame(env))
                done = False
                while not done:
                    observation, _, terminated, truncated, info = env.step(act(env, observation))
                    writer.append(_frame(env))
                    done = terminated or truncated
                    bar.update(1)
            bar.update(env.scenario.max_steps - env.simulator.step_count)  # an early end skips the rest
            bar.set_postfix_str(f"episode {episode + 1}/{episodes}: {info['outcome']}")
            # named by how the episode ended, so a folder of videos reads at a glance
            named = inside(out, f"{env.scenario.name}_{label}_seed{seed + episode}_{info['outcome']}{suffix}")
            path.replace(named)
            paths.append(named)
    finally:
        bar.close()
        env.close()
    return paths


def _frame(env: CrowdNavEnv) -> np.ndarray:
    frame = env.render()
    if frame is None:  # never in rgb_array mode, which render_episodes sets
        raise RuntimeError(f"the environment rendered no frame (render_mode {env.render_mode!r}); expected 'rgb_array'")
    return frame


def _progress(total: int, enabled: bool) -> tqdm:
    from tqdm import tqdm

    return tqdm(total=total, unit="step", desc="rendering", disable=not enabled, leave=False)
