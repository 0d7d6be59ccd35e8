"""One simulator's episode as data: :class:`EpisodeState`, taken by :func:`capture` and given back by :func:`restore`.

Everything a :class:`crowdnav.Simulator`'s episode depends on, given the actions, besides its scenario: the
episode's :class:`crowdnav.sim.state.SimState`, the state of its generator (``bit_generator.state``: the draws of
its resets and goal rules), a ``robots:`` scenario's :class:`crowdnav.sim.robots.TeamState` and each crowd
model's episode state (:meth:`crowdnav.crowd.base.CrowdModel.episode_state`: a recording's window, who reacts).
The geometry is not in it: :meth:`crowdnav.Simulator.refresh` measures it again from the positions, bit for bit.
A simulator that restores it plays on as the captured one would, step for step. The envs' world states
(:mod:`crowdnav.envs.engines.world_state`) hold one; the batched simulator takes and gives one per world.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from crowdnav.crowd.views import world_view
from crowdnav.sim.robots import TeamState
from crowdnav.sim.state import SimState

if TYPE_CHECKING:
    from crowdnav.sim.simulator import Simulator


@dataclass(frozen=True, eq=False)
class EpisodeState:
    """One simulator's episode now (new arrays, shared with nothing): see the module docstring."""

    state: SimState
    """The episode's state (positions, goals, step count, ...)."""
    rng: dict[str, Any]
    """The episode generator's ``bit_generator.state``."""
    team: TeamState | None
    """The robots after the first (``robots:``); None for one robot."""
    crowd: dict[str, dict[str, Any]]
    """Crowd model name -> its episode state."""


def capture(sim: Simulator, state: SimState | None = None) -> EpisodeState:
    """``sim``'s episode now (``state``: the episode's state where ``sim`` does not hold it, a batch world's row), copied."""
    return EpisodeState((sim.state if state is None else state).copy(), copy.deepcopy(dict(sim.rng.bit_generator.state)),
                        None if sim.team is None else sim.team.state.copy(), sim.crowd.episode_state())


def restore(sim: Simulator, episode: EpisodeState) -> None:
    """Make ``episode`` (captured from a simulator of the same scenario) ``sim``'s episode, on copies: ``sim`` then plays on
    as the captured simulator would. Its generator object stays the same (its state is set), so whoever holds it sees the
    restored draws."""
    sim.rng.bit_generator.state = copy.deepcopy(episode.rng)
    if sim.team is not None:
        if episode.team is None:
            raise ValueError("a one-robot episode cannot load into a simulator of several robots")
        sim.team.state = episode.team.copy()  # before the geometry is measured: the robots push the humans
    sim.load_state(episode.state.copy())
    sim.crowd.resume(world_view(sim), episode.crowd)
