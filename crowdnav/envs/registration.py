"""Gymnasium ids: ``crowdnav/<CamelName>-v0`` per library scenario, ``crowdnav/Scenario-v0`` for any file.

``gymnasium.make(id, max_episode_steps=N)`` wraps the env in Gymnasium's ``TimeLimit``, which
truncates after the env's step returned; :class:`crowdnav.envs.single.CrowdNavEnv` therefore puts
``outcome`` (``"truncated"`` unless the step terminated) and ``is_success`` in every step's info,
so the truncating step carries them too. ``gymnasium.make_vec(id, ..., vectorization_mode=
"vector_entry_point", max_episode_steps=N)`` builds :func:`vector_env`, which sets the scenario's
own time limit to N (when shorter), so the vector env truncates and reports the outcome itself.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from crowdnav.scenario.library import camel_name, library_names

NAMESPACE = "crowdnav"
SCENARIO_FILE_ID = f"{NAMESPACE}/Scenario-v0"
"""Id for any scenario: ``gymnasium.make("crowdnav/Scenario-v0", scenario="path/to/file.yaml")``."""
_ENTRY_POINT = "crowdnav.envs.single:CrowdNavEnv"
_VECTOR_ENTRY_POINT = "crowdnav.envs.registration:vector_env"  # make_vec(..., vectorization_mode="vector_entry_point")


def env_id(name: str) -> str:
    """``room_furniture`` -> ``crowdnav/RoomFurniture-v0``."""
    return f"{NAMESPACE}/{camel_name(name)}-v0"


def vector_env(scenario: Any = None, num_envs: int = 1, *, max_episode_steps: int | None = None, **options: Any) -> Any:
    """:class:`crowdnav.envs.vector.env.CrowdNavVectorEnv`; ``max_episode_steps`` (Gymnasium's name) caps the scenario's ``max_steps``.

    Like ``TimeLimit``, it only ever shortens episodes: a cap above the scenario's ``max_steps``
    changes nothing. ``options``: the keyword arguments of CrowdNavVectorEnv.
    """
    from crowdnav.envs.vector.env import CrowdNavVectorEnv

    if max_episode_steps is not None and (isinstance(max_episode_steps, bool) or not isinstance(max_episode_steps, int)
                                          or max_episode_steps < 1):
        raise ValueError(f"max_episode_steps must be a positive integer, got {max_episode_steps!r}")
    env = CrowdNavVectorEnv(scenario, num_envs, **options)
    if max_episode_steps is None or max_episode_steps >= env.scenario.max_steps:
        return env
    env.close()  # built again with the shorter limit: the scenario is validated once more, with it
    overrides = {**dict(options.pop("overrides", None) or {}), "max_steps": max_episode_steps}
    return CrowdNavVectorEnv(scenario, num_envs, overrides=overrides, **options)


def register_envs() -> list[str]:
    """Register every library scenario and the file id (idempotent); returns the library ids."""
    ids = []
    for name in library_names():
        ids.append(env_id(name))
        if ids[-1] not in gym.registry:
            gym.register(id=ids[-1], entry_point=_ENTRY_POINT, vector_entry_point=_VECTOR_ENTRY_POINT, kwargs={"scenario": name})
    if SCENARIO_FILE_ID not in gym.registry:
        gym.register(id=SCENARIO_FILE_ID, entry_point=_ENTRY_POINT, vector_entry_point=_VECTOR_ENTRY_POINT)  # CrowdNavEnv asks for scenario=
    return ids
