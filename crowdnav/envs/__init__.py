"""Environments: Gymnasium (robot only) and PettingZoo (robot and humans), sharing one core.

The modules here are the env core (``core``: options, one simulator, sensors, reward, checks; ``reward``), the
Gymnasium env (``single``), the PettingZoo env (``parallel``, with ``multi_agent``, ``human_observation`` and
``human_policy``) and the Gymnasium ids (``registration``). Two subpackages: :mod:`crowdnav.envs.engines` (the
engine protocol, its backends and a world's state as data) and :mod:`crowdnav.envs.vector` (the native vector env
and its action and info pipeline), the vector env above the engines. Importing this package registers the Gymnasium
ids (see :mod:`crowdnav.envs.registration`). :mod:`crowdnav.legacy_paths` keeps the flat paths of the modules that
moved into the subpackages importable (``crowdnav.envs.world_state``, ``crowdnav.envs.vector_stacked``, ...).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from types import ModuleType
from typing import Any

from crowdnav import legacy_paths
from crowdnav.envs.core import EnvCore, ScenarioSource
from crowdnav.envs.human_policy import SocialForcePolicy
from crowdnav.envs.multi_agent import HumanExit, HumanReward
from crowdnav.envs.parallel import CrowdNavParallelEnv
from crowdnav.envs.registration import SCENARIO_FILE_ID, env_id, register_envs
from crowdnav.envs.reward import REWARD_TERMS, Reward
from crowdnav.envs.single import CrowdNavEnv


def parallel_env(
    scenario: ScenarioSource,
    *,
    modalities: Sequence[str] | None = None,
    sensors: Mapping[str, Any] | None = None,
    reward_weights: Mapping[str, float] | None = None,
    overrides: Mapping[str, Any] | None = None,
    render_mode: str | None = None,
    render_options: Mapping[str, Any] | None = None,
    flat_observations: bool = False,
    human_reward: HumanReward | None = None,
    human_exit: HumanExit | None = None,
    fixed_agents: bool = False,
    humans_as_agents: bool = True,
) -> CrowdNavParallelEnv:
    """The PettingZoo ParallelEnv for ``scenario`` (library name or YAML path); options as in
    CrowdNavEnv, plus the multi-agent ones of :class:`CrowdNavParallelEnv`."""
    return CrowdNavParallelEnv(
        scenario, modalities=modalities, sensors=sensors, reward_weights=reward_weights,
        overrides=overrides, render_mode=render_mode, render_options=render_options, flat_observations=flat_observations,
        human_reward=human_reward, human_exit=human_exit, fixed_agents=fixed_agents, humans_as_agents=humans_as_agents,
    )


def env(scenario: ScenarioSource, **options: Any) -> Any:
    """The PettingZoo AEC env for ``scenario``: :func:`parallel_env` (same options) through
    PettingZoo's ``parallel_to_aec``, so agents act one after the other and the world steps
    once every agent alive has acted (the robot first, then the humans in order)."""
    from pettingzoo.utils.conversions import parallel_to_aec

    return parallel_to_aec(parallel_env(scenario, **options))


ENV_IDS = register_envs()
"""The Gymnasium ids of the library scenarios."""


def __getattr__(name: str) -> ModuleType:
    """An old module path of this package as an attribute (``crowdnav.envs.world_state``), imported on first use."""
    return legacy_paths.old_attribute(__name__, name)

__all__ = [
    "ENV_IDS",
    "REWARD_TERMS",
    "SCENARIO_FILE_ID",
    "CrowdNavEnv",
    "CrowdNavParallelEnv",
    "EnvCore",
    "Reward",
    "SocialForcePolicy",
    "env",
    "env_id",
    "parallel_env",
    "register_envs",
]
