"""A world of the robots-only engines as data: what :class:`crowdnav.envs.engines.protocol.RobotsEngine` ``snapshot`` gives and ``load`` takes.

It is a :class:`crowdnav.envs.engines.world_state.WorldState` as the robots-only PettingZoo env holds its world after a step:
the simulator's episode with the robots that ended out of the world, every robot's reward memory, the tracker's
state. Its env part (:class:`crowdnav.envs.engines.world_state.EnvState`) is that env's: whether the episode runs, no other
robots' outcomes (the env reports none), and as ``observation`` every robot's last flat observation by its name (zero
for a robot that had left). The observation is stored, not made again at load: a robot that ended at the last step
shows in the others' observations of that step, and it is out of the world in the state.

Either engine's state loads into either (:class:`crowdnav.envs.engines.stacked_robots.StackedRobots`,
:class:`crowdnav.envs.engines.robots.SingleRobots`; tests/core/test_robots_engine_snapshot.py); a single or vector
env's state (the first robot's observation by modality) is refused, and the world key is checked as everywhere
(:func:`crowdnav.envs.engines.world_state.check_state`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from crowdnav.envs.engines.world_state import EnvState, WorldKey, WorldState, check_state
from crowdnav.sim.episode_state import EpisodeState
from crowdnav.sim.robots import TeamState, retire_in


def robots_state(base: WorldState, running: bool, observations: np.ndarray, names: Sequence[str]) -> WorldState:
    """``base`` (a world's state, its rewards every robot's) with the robots-only env's part: ``running`` and the (R, D)
    ``observations`` of the robots ``names`` (copied). The rewards become Python floats: both engines' states alike."""
    observation = {name: np.array(row, dtype=np.float32) for name, row in zip(names, observations, strict=True)}
    return dataclasses.replace(base, rewards=tuple(float(value) for value in base.rewards), env=EnvState(bool(running), {}, observation))


def robots_rows(state: object, key: WorldKey, names: Sequence[str], size: int) -> tuple[WorldState, np.ndarray]:
    """``state`` checked to load into a robots engine's world with ``key`` (robots ``names``, observations of ``size``
    float32), and its robots' (R, D) observations; else a ValueError in one line."""
    state = check_state(state, key)
    observation = None if state.env is None else state.env.observation
    if observation is None or observation.keys() != set(names) or any(
            not isinstance(row, np.ndarray) or row.shape != (size,) or row.dtype != np.float32 for row in observation.values()):
        raise ValueError("a world state without every robot's flat observation (a single or vector env's) cannot load into a robots "
                         "engine: take it with the robots engine's snapshot")
    if len(state.rewards) != len(names):
        raise ValueError(f"a world state with {len(state.rewards)} reward memories cannot load into a world of {len(names)} robots")
    return state, np.stack([observation[name] for name in names])


def retired(episode: EpisodeState, team: TeamState, first: bool) -> EpisodeState:
    """``episode`` (a copy) with ``team`` (its robots after the first, those leaving already out) and, ``first``, the first
    robot out of the world too, as :func:`crowdnav.sim.robots.retire_robots` leaves it (parked, still, its place kept)."""
    if first:
        retire_in(team, episode.state, [0])
    return dataclasses.replace(episode, team=team)
