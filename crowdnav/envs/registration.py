"""Gymnasium ids: ``crowdnav/<CamelName>-v0`` per library scenario, ``crowdnav/Scenario-v0`` for any file."""

from __future__ import annotations

import gymnasium as gym

from crowdnav.scenario.library import camel_name, library_names

NAMESPACE = "crowdnav"
SCENARIO_FILE_ID = f"{NAMESPACE}/Scenario-v0"
"""Id for any scenario: ``gymnasium.make("crowdnav/Scenario-v0", scenario="path/to/file.yaml")``."""
_ENTRY_POINT = "crowdnav.envs.single:CrowdNavEnv"
_VECTOR_ENTRY_POINT = "crowdnav.envs.vector:CrowdNavVectorEnv"  # make_vec(..., vectorization_mode="vector_entry_point")


def env_id(name: str) -> str:
    """``room_furniture`` -> ``crowdnav/RoomFurniture-v0``."""
    return f"{NAMESPACE}/{camel_name(name)}-v0"


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
