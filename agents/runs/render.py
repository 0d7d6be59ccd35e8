"""Videos of a named policy: a scripted one, or a trained agent's checkpoint (what ``crowdnav render`` runs).

The environment core renders any ``act(env, observation)`` callable
(:func:`crowdnav.rendering.episodes.render_episodes`); loading a checkpoint is the agents'
business, so it happens here, and torch is imported only when a checkpoint is loaded.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from crowdnav.errors import CrowdNavError
from crowdnav.planning.scripted import SCRIPTED_POLICIES
from crowdnav.rendering.episodes import Act, render_episodes, scripted_act, video_suffix


class PolicyLoadError(CrowdNavError, ValueError):
    """A ``--policy`` value that is neither a scripted policy nor a loadable checkpoint."""


def resolve_policy(policy: str, seed: int) -> tuple[Act, dict[str, Any]]:
    """A scripted policy name or a checkpoint path -> (act(env, observation), env options it needs).

    Scripted names take either spelling, ``social-force`` or ``social_force`` (as ``baseline:social_force``
    reads in ``crowdnav evaluate``).
    """
    dashed = policy.replace("_", "-")
    if dashed in SCRIPTED_POLICIES and not Path(policy).exists():
        policy = dashed
    if policy in SCRIPTED_POLICIES:
        try:
            return scripted_act(policy, seed), {}
        except ValueError as error:  # e.g. the ORCA robot without its optional package: one line
            raise PolicyLoadError(str(error)) from None
    path = Path(policy)
    if not path.exists():
        raise PolicyLoadError(
            f"--policy {policy!r} is neither a scripted policy ({', '.join(SCRIPTED_POLICIES)}) nor an existing checkpoint path"
        )
    try:
        from crowdnav.agents.runs.checkpoint import load_policy

        trained = load_policy(path)
    except Exception as error:  # a checkpoint can fail in many ways; report one clear line
        raise PolicyLoadError(f"cannot load checkpoint {path}: {type(error).__name__}: {error}") from None
    options = {k: v for k, v in trained.env_options.items() if k not in ("scenario", "render_mode", "render_options")}
    if not trained.recurrent:
        return (lambda env, observation: trained(observation)), options
    memory: dict[str, Any] = {"state": None}

    def act(env: Any, observation: Mapping[str, np.ndarray]) -> np.ndarray:  # its state kept, forgotten when an episode begins
        start = np.array([env.simulator.step_count == 0])
        batch = {key: np.asarray(value)[None] for key, value in observation.items()}
        actions, memory["state"] = trained.predict(batch, memory["state"], start)
        return actions[0]

    return act, options


def render_policy(scenario: str, policy: str = "social-force", *, seed: int = 0, **options: Any) -> list[Path]:
    """:func:`render_episodes` of a scripted policy's name or a checkpoint path; ``options`` as there.

    A shared robot policy's checkpoint (``agents: robots``) drives every robot of its scenario
    (:func:`render_robots_policy`).
    """
    if _is_robots_checkpoint(policy):
        return render_robots_policy(scenario, policy, seed=seed, **options)
    act, env_options = resolve_policy(policy, seed)
    label = policy if policy in SCRIPTED_POLICIES else Path(policy).stem
    return render_episodes(scenario, act, label=label, env_options=env_options, seed=seed, **options)


def _is_robots_checkpoint(policy: str) -> bool:
    if policy in SCRIPTED_POLICIES or not Path(policy).exists():
        return False
    from crowdnav.agents.marl.robots import ROBOTS_KIND
    from crowdnav.agents.runs.checkpoint import read_policy_info

    try:
        return bool(read_policy_info(policy).get("agents") == ROBOTS_KIND)
    except (OSError, ValueError):  # not a checkpoint: resolve_policy says so in one line
        return False


def render_robots_policy(scenario: str, policy: str, *, seed: int = 0, episodes: int = 3, out: str | Path = "videos",
                         video_format: str = "mp4", progress: bool = True, render_options: Mapping[str, Any] | None = None,
                         **options: Any) -> list[Path]:
    """Videos of a shared robot policy (``agents: robots``) driving every robot; one file per episode (seeds ``seed``, ...).

    Each file is named by the scenario, the checkpoint, the seed and how many robots reached their
    goal (``..._seed7_2of3_arrived.mp4``). ``render_options`` as for :func:`render_episodes`. The
    policy plays the world it was trained in: scenario overrides and reward weights are refused in
    one line.
    """
    from crowdnav.paths import inside
    from crowdnav.rendering.video import VideoWriter

    suffix = video_suffix(video_format, episodes)
    unused = sorted(name for name, value in options.items() if value)
    if unused:
        raise PolicyLoadError(f"{policy} is a shared robot policy; it plays the world it was trained in, without {', '.join(unused)}")
    from crowdnav.agents.marl.env import robots_env
    from crowdnav.agents.marl.robots import load_robots_policy

    try:
        trained = load_robots_policy(policy)
    except Exception as error:  # a damaged checkpoint can fail in many ways; report one clear line
        message = str(error).splitlines()[0] if str(error) else ""
        raise PolicyLoadError(f"cannot load shared robot policy {policy}: {type(error).__name__}{': ' + message if message else ''}") from None
    if not _same_scenario(scenario, trained.env_options["scenario"]):
        raise PolicyLoadError(f"{policy} drives the robots of {trained.env_options['scenario']!r}, not {scenario!r}")

    env = robots_env({**trained.env_options, "render_mode": "rgb_array", "render_options": render_options})
    label, paths = Path(policy).stem, []
    fps = env.metadata["render_fps"]
    assert isinstance(fps, float)  # PettingZoo types its metadata as a dict of objects

    def frame() -> np.ndarray:
        image = env.render()
        if image is None:  # never in rgb_array mode
            raise RuntimeError("the robots env rendered no frame; expected render_mode 'rgb_array'")
        return image

    try:
        for episode in range(episodes):
            path = inside(Path(out), f"{env.scenario.name}_{label}_seed{seed + episode}{suffix}")
            observations, infos = env.reset(seed=seed + episode)
            outcomes: dict[str, str] = {}
            # the writer drops its unfinished temporary if the episode raises; a file of that name stays as it was
            with VideoWriter(path, fps=fps) as writer:
                writer.append(frame())
                while env.agents:
                    observations, _, terminations, truncations, infos = env.step(trained.act(observations, infos))
                    writer.append(frame())
                    for name, info in infos.items():  # the outcome of the step a robot ended (later steps: inactive)
                        if "outcome" in info:
                            outcomes.setdefault(name, info["outcome"])
                    if all(terminations.values()) or all(truncations.values()):
                        break
            reached = sum(outcome == "success" for outcome in outcomes.values())
            named = inside(Path(out), f"{env.scenario.name}_{label}_seed{seed + episode}_{reached}of{len(trained.robots)}_arrived{suffix}")
            path.replace(named)
            paths.append(named)
            if progress:
                print(f"{named.name}: " + ", ".join(f"{name} {outcomes.get(name, 'truncated')}" for name in trained.robots))
    finally:
        env.close()
    return paths


def _same_scenario(given: str, trained: str) -> bool:
    """Whether ``given`` names the scenario ``trained`` does: the same library name, or the same file written another way
    (``hall.yaml``, ``./hall.yaml`` and its absolute path)."""
    if given == trained:
        return True
    try:
        return os.path.samefile(given, trained)
    except OSError:  # a library name, or a path that is not there from here: not shown to be the same
        return False
