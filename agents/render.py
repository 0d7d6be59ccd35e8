"""Videos of a named policy: a scripted one, or a trained agent's checkpoint (what ``crowdnav render`` runs).

The environment core renders any ``act(env, observation)`` callable
(:func:`crowdnav.rendering.episodes.render_episodes`); loading a checkpoint is the agents'
business, so it happens here, and torch is imported only when a checkpoint is loaded.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from crowdnav.errors import CrowdNavError
from crowdnav.policies import SCRIPTED_POLICIES
from crowdnav.rendering.episodes import Act, render_episodes, scripted_act


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
        from crowdnav.agents.checkpoint import load_policy

        trained = load_policy(path)
    except Exception as error:  # a checkpoint can fail in many ways; report one clear line
        raise PolicyLoadError(f"cannot load checkpoint {path}: {type(error).__name__}: {error}") from None
    options = {k: v for k, v in trained.env_options.items() if k not in ("scenario", "render_mode", "render_options")}
    return (lambda env, observation: trained(observation)), options


def render_policy(scenario: str, policy: str = "social-force", *, seed: int = 0, **options: Any) -> list[Path]:
    """:func:`render_episodes` of a scripted policy's name or a checkpoint path; ``options`` as there."""
    act, env_options = resolve_policy(policy, seed)
    label = policy if policy in SCRIPTED_POLICIES else Path(policy).stem
    return render_episodes(scenario, act, label=label, env_options=env_options, seed=seed, **options)
