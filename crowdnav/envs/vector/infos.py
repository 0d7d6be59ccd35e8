"""The native vector env's infos, in Gymnasium's vector convention (a key's values in an array, ``_key``
marking the worlds that have it): the reward terms, the outcomes and collisions of a step, and the
split of a step's infos between the worlds that run on and those a same-step autoreset restarts.

:class:`crowdnav.envs.vector.env.CrowdNavVectorEnv` documents what each key holds; these are its parts.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from crowdnav.batch.simulator import StepResult
from crowdnav.envs.engines.per_world import EveryStep
from crowdnav.envs.engines.protocol import WorldEngine
from crowdnav.envs.reward import REWARD_TERMS
from crowdnav.sim.events import Collision

MASKED_TERMS = tuple((term, f"_{term}") for term in REWARD_TERMS)
"""Each reward term's key and its mask's, made once (not an f-string per term per step)."""


def reward_term_infos(infos: dict[str, Any], terms: dict[str, np.ndarray], stepping: np.ndarray, every: bool) -> None:
    """``infos["reward_terms"]``: each term's (num_envs,) values (``terms``' values for the stepping worlds, 0 elsewhere;
    ``every``: all worlds stepped, and each term's values are ``terms``' own arrays, new ones every step)."""
    out: dict[str, np.ndarray] = {}
    for term, mask in MASKED_TERMS:
        if every:
            values = terms[term]
        else:
            values = np.zeros(len(stepping))
            values[stepping] = terms[term]
        out[term], out[mask] = values, stepping.copy()
    infos["reward_terms"], infos["_reward_terms"] = out, stepping.copy()


def every_infos(infos: dict[str, Any], stepped: EveryStep, stepping: np.ndarray) -> None:
    """:func:`reward_term_infos` then :func:`end_infos` (the same keys in the same order, the same values) when every
    world of one robot stepped (``stepping`` all True): from :meth:`TeamWorlds.step_every`'s arrays, without recomputing them."""
    out: dict[str, np.ndarray] = {}
    for term, mask in MASKED_TERMS:
        out[term], out[mask] = stepped.terms[term], stepping.copy()
    infos["reward_terms"], infos["_reward_terms"] = out, stepping.copy()
    infos["outcome"], infos["_outcome"] = stepped.outcome, stepping.copy()
    infos["is_success"], infos["_is_success"] = stepped.success, stepping.copy()
    infos["human_stalls"], infos["_human_stalls"] = stepped.stalls, stepping.copy()
    if stepped.collisions:  # rare: end_infos' own code for them
        collision_infos(infos, stepped.collisions, stepped.outcome == "collision")


def end_infos(
    infos: dict[str, Any],
    engine: WorldEngine,
    result: StepResult,
    outcome: np.ndarray,
    stepping: np.ndarray,
    add_info: Callable[[dict[str, Any], dict[str, Any], int], Any],
    every: bool = False,
) -> None:
    """``outcome`` / ``is_success`` of every world that stepped, as CrowdNavEnv's info: "truncated" / False unless it terminated;
    ``human_stalls``, the collisions' ``collision_kind`` / ``collision_partner`` and, with several robots, ``other_robots``
    (through ``add_info``, the vector env's ``_add_info``); ``every``: all worlds stepped."""
    infos["outcome"], infos["_outcome"] = outcome, stepping.copy()
    infos["is_success"], infos["_is_success"] = outcome == "success", stepping.copy()
    stalls = engine.stalls()
    for i, robots in engine.other_robots(stepping).items():  # per world: its robots' outcomes, as SyncVectorEnv lays out a dict
        add_info(infos, {"other_robots": robots}, i)
    infos["human_stalls"], infos["_human_stalls"] = stalls if every else np.where(stepping, stalls, 0), stepping.copy()
    if result.collisions:
        collision_infos(infos, result.collisions, outcome == "collision")  # the collisions of worlds that stepped


def collision_infos(infos: dict[str, Any], collisions: dict[int, Collision], collided: np.ndarray) -> None:
    """``collision_kind`` / ``collision_partner`` of the worlds in ``collided`` (their outcome is "collision") from ``collisions``."""
    if collided.any():
        b = len(collided)
        kind, partner = np.full(b, None, dtype=object), np.full(b, None, dtype=object)
        for i in np.flatnonzero(collided):  # per collision event
            hit = collisions[int(i)]
            kind[i], partner[i] = hit.kind, hit.partner
        infos["collision_kind"], infos["_collision_kind"] = kind, collided
        infos["collision_partner"], infos["_collision_partner"] = partner, collided.copy()


def same_step_infos(infos: dict[str, Any], ended: np.ndarray, observations: dict[str, np.ndarray]) -> dict[str, Any]:
    """A same-step autoreset's infos, as ``SyncVectorEnv`` lays them out: the top-level infos keep the worlds still
    running, ``final_info`` holds the ended worlds' infos (vectorized), ``final_obs`` their last ``observations`` (one
    dict each). Call it before the ended worlds are reset."""
    final_obs = np.full(len(ended), None, dtype=object)
    for i in np.flatnonzero(ended):  # per ended episode: its last observation, unbatched (Gymnasium's convention)
        final_obs[i] = {key: values[i].copy() for key, values in observations.items()}
    out = restricted(infos, ~ended)
    out["final_obs"], out["_final_obs"] = final_obs, ended.copy()
    out["final_info"], out["_final_info"] = restricted(infos, ended), ended.copy()
    return out


def restricted(infos: dict[str, Any], keep: np.ndarray) -> dict[str, Any]:
    """Vector ``infos`` for the worlds in ``keep`` only: other entries cleared, keys no kept world has dropped."""
    out: dict[str, Any] = {}
    for key, value in infos.items():
        if key.startswith("_"):
            continue
        mask = infos[f"_{key}"] & keep
        if not mask.any():
            continue
        if isinstance(value, dict):
            value = restricted(value, keep)
        else:
            value = value.copy()
            value[~mask] = None if value.dtype == object else 0
        out[key], out[f"_{key}"] = value, mask
    return out
