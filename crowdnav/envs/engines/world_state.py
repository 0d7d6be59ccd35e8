"""A world of an env as data: :class:`WorldState`, what the engines' ``snapshot(world)`` give and ``load(world, state)`` take.

A :class:`WorldState` holds everything that determines one world's future given the robot's actions, so that a
world loaded with it (the same world, another world of the same env, or a world of another env of the same
scenario and options, whichever engine holds it) plays on bit for bit as the captured world would have:

* ``episode``: the simulator's episode (:class:`crowdnav.sim.episode_state.EpisodeState`): its state (robot, humans,
  goals, groups, respawns, stalls, step count), its generator's state (the draws of the goal rules and of the next
  resets that continue it), a ``robots:`` scenario's other robots, each crowd model's episode state;
* ``rewards``: each robot's reward memory (the robot-goal distance at its last step: the progress term's potential);
* ``tracker``: the people tracker's tracks and draws of the world (``sensors.tracker``; None for ``perfect``);
* ``env``: what a single env keeps around its simulator (:class:`EnvState`: whether the episode runs, the other
  robots' outcomes so far, the last observation); None from the stacked engine, which keeps none of it (a world
  loaded into a single env then observes its state again and runs).

It is plain data (dataclasses of numpy arrays, Python and numpy numbers, texts, dicts, tuples): it pickles, it is
stored without pickle as arrays and JSON (:mod:`crowdnav.envs.engines.world_state_codec`: a training checkpoint's worlds),
and it shares nothing with the world it came from (snapshots are copies, and loading copies again). ``version`` is :data:`WORLD_STATE_VERSION`, and
a state loads only into a world of the same scenario with the same settings (options applied) and robot count
(:func:`check_state`: a ValueError in one line naming what differs).

**Gymnasium's state of a world** is not the engine's: whether a world's episode ended and waits for its
autoreset (``NEXT_STEP``) or for a reset mask (``DISABLED``, with the flags it repeats) is the vector env's
convention, so :meth:`crowdnav.envs.vector.env.CrowdNavVectorEnv.snapshot` wraps the engine's :class:`WorldState` in a
:class:`VectorWorldState` with those flags. The seeds of later episodes (the vector env's ``episode_seeds``,
e.g. training's episode counter) belong to whoever numbers the episodes, not to a world.

Not captured: the state of a user's own callable driving other robots (``other_robots=callable``; the named
scripted policies keep none that matters), and a single env's rendering history (``render_mode``), which draws
the world and does not change it.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from crowdnav.sim.episode_state import EpisodeState

if TYPE_CHECKING:
    from crowdnav.scenario.schema import Scenario

WORLD_STATE_VERSION = 1
"""The layout of :class:`WorldState`; a state of another version is refused in one line (raise it when the layout changes)."""
UNCHECKED_SECTIONS = frozenset({"name", "description"})
"""Scenario fields a state does not depend on (the name is compared on its own, to say so)."""


@dataclass(frozen=True, eq=False)
class EnvState:
    """What a single env (:class:`crowdnav.envs.single.CrowdNavEnv`) keeps around its simulator."""

    running: bool
    """The episode has not ended (a step is allowed)."""
    other_outcomes: dict[str, str | None]
    """Each other robot's outcome so far (``info["other_robots"]``), None while it runs."""
    observation: dict[str, np.ndarray]
    """The last observation (the first robot's), copied."""


@dataclass(frozen=True, eq=False)
class WorldState:
    """One world now (see the module docstring): pickle it, load it with an engine's or env's ``load``."""

    version: int
    scenario: str
    """The scenario's name."""
    settings: tuple[tuple[str, str], ...]
    """(field, digest) for each top-level scenario field (every option applied): a state loads where they are equal."""
    robots: int
    episode: EpisodeState
    rewards: tuple[float, ...]
    """Each robot's reward memory, the first robot's first: the robot-goal distance at its last step."""
    tracker: dict[str, Any] | None
    """:meth:`crowdnav.sensors.tracker.PeopleTracker.row_state` of the world; None without a tracker."""
    env: EnvState | None


@dataclass(frozen=True, eq=False)
class VectorWorldState:
    """One world of a :class:`crowdnav.envs.vector.env.CrowdNavVectorEnv`: its engine's :class:`WorldState` and Gymnasium's flags."""

    world: WorldState
    ended: bool
    """The episode ended at the last step and the world waits: for its autoreset (``NEXT_STEP``) or a reset mask (``DISABLED``)."""
    terminated: bool
    """``DISABLED``: the terminated flag a waiting world repeats."""
    truncated: bool
    """``DISABLED``: the truncated flag a waiting world repeats."""


@dataclass(frozen=True)
class WorldKey:
    """What a state must match to load into a world: see :func:`world_key`."""

    scenario: str
    settings: tuple[tuple[str, str], ...]
    robots: int


def world_key(scenario: Scenario) -> WorldKey:
    """The key of worlds of ``scenario`` (the compiled one, every option applied): its name, a digest of each field, its robots."""
    dumped = scenario.model_dump(mode="json")
    settings = tuple((field, hashlib.sha256(json.dumps(value, sort_keys=True).encode()).hexdigest()[:16])
                     for field, value in dumped.items() if field not in UNCHECKED_SECTIONS)
    return WorldKey(str(scenario.name), settings, len(scenario.robot_names))


def make_state(key: WorldKey, episode: EpisodeState, rewards: tuple[float, ...], tracker: dict[str, Any] | None,
               env: EnvState | None = None) -> WorldState:
    """A :class:`WorldState` of a world with ``key`` (its parts already copies)."""
    return WorldState(WORLD_STATE_VERSION, key.scenario, key.settings, key.robots, episode, rewards, tracker, env)


def check_state(state: object, key: WorldKey) -> WorldState:
    """``state`` if it loads into a world with ``key``; else a ValueError in one line naming what differs."""
    if not isinstance(state, WorldState):
        raise ValueError(f"expected a WorldState (an engine's or env's snapshot), got {type(state).__name__}")
    if state.version != WORLD_STATE_VERSION:
        raise ValueError(f"a world state of version {state.version} cannot load: this crowdnav's world states are version {WORLD_STATE_VERSION}")
    if state.robots != key.robots:
        raise ValueError(f"a world state of {state.robots} robot(s) cannot load into a world of {key.robots} (scenario {key.scenario!r})")
    if state.scenario != key.scenario:
        raise ValueError(f"a world state of scenario {state.scenario!r} cannot load into a world of scenario {key.scenario!r}")
    if state.settings != key.settings:
        ours, theirs = dict(key.settings), dict(state.settings)
        differ = sorted(field for field in ours.keys() | theirs.keys() if ours.get(field) != theirs.get(field))
        raise ValueError(f"a world state of scenario {key.scenario!r} with other settings cannot load: {', '.join(differ)} differ")
    return state
