"""The engine protocol: what :class:`crowdnav.envs.vector.env.CrowdNavVectorEnv` asks of the worlds it holds.

The vector env keeps Gymnasium's conventions (autoreset modes, seeding, reset masks, the infos' layout, the residual
plan); everything about the worlds themselves, their episodes, rewards and observations, is its engine's. Two
engines implement :class:`WorldEngine`, and the vector env reads neither's insides:

* :class:`crowdnav.envs.engines.stacked.StackedWorlds`: the worlds stacked in one
  :class:`crowdnav.batch.simulator.BatchSimulator` (array work over the world axis, the reward's kernels batched);
  several robots per world: :class:`crowdnav.envs.engines.stacked_team.StackedTeamWorlds` (the other robots stacked too);
* :class:`crowdnav.envs.engines.per_world.TeamWorlds`: one single env per world stepped in one call (one world, crowds too
  large to stack, other robots driven by ORCA or a callable).

Either plays world ``i`` as the single env plays it after ``reset(seed=s_i)``, bit for bit, and gives a world's
state as data (:meth:`WorldEngine.snapshot`, :mod:`crowdnav.envs.engines.world_state`) that either loads into any of its
worlds. Which one a vector env uses is :func:`crowdnav.envs.vector.env.stacks`' choice, made once.

:class:`RobotsEngine` is the same for the robots-only env, every robot of a ``robots:`` scenario driven by the caller
(:mod:`crowdnav.envs.engines.robots`): :class:`crowdnav.envs.engines.stacked_robots.StackedRobots` stacked,
:class:`crowdnav.envs.engines.robots.SingleRobots` one env per world; a step's per-robot results are a :class:`RobotsStep`,
where everyone is a :class:`RobotsFrame`; a world's state is a :class:`crowdnav.envs.engines.world_state.WorldState` too
(:mod:`crowdnav.envs.engines.robots_state`), loading into either.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from crowdnav.batch.simulator import StepResult
    from crowdnav.envs.engines.world_state import WorldState
    from crowdnav.planning.shield import Shield
    from crowdnav.sensors import Modality
    from crowdnav.sim.events import Collision
    from crowdnav.sim.robots import TeamState
    from crowdnav.sim.simulator import Simulator

Judged = tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]
"""(outcome, rewards, terms): every world's outcome (object; "truncated" where a stepping world runs on, None where it did
not step), every world's reward (0 where it did not step) and the stepping worlds' value of each reward term."""


class WorldEngine(Protocol):
    """``num_worlds`` worlds of one compiled scenario, reset by seed and stepped together (see the module docstring)."""

    num_worlds: int
    modalities: dict[str, Modality]
    """The observation's modalities by key (several robots: the first robot's own)."""

    def reset(self, worlds: Sequence[int] | np.ndarray, seeds: Sequence[int | None] | np.ndarray) -> None:
        """Start a new episode in each of ``worlds`` (``seeds[k]`` for ``worlds[k]``; None continues its generator)."""

    def step(self, actions: np.ndarray, active: np.ndarray | None = None) -> StepResult:
        """Step every world (or those of the bool mask ``active``) with its row of ``actions`` ((num_worlds, 2))."""

    def judged(self, result: StepResult, stepping: np.ndarray, every: bool) -> Judged:
        """The outcomes and rewards of the last :meth:`step` (``stepping``: the worlds that stepped; ``every``: all of them)."""

    def settle(self) -> None:
        """After worlds were stepped without :meth:`judged` (a resume's replay): the reward's memory of the last step made current."""

    def observe(self, out: Mapping[str, np.ndarray]) -> None:
        """Every world's observation written into ``out`` (per key, a (num_worlds, ...) array)."""

    def shielded(self, shield: Shield, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every world's action through the shield (as the single env's, bit for bit), and which worlds' it replaced."""

    def stalls(self) -> np.ndarray:
        """(num_worlds,) int64: how many times a human stalled this episode, per world."""

    def other_robots(self, stepping: np.ndarray) -> dict[int, dict[str, str | None]]:
        """World -> its other robots' outcomes (``info["other_robots"]``), for the stepping worlds that have other robots."""

    def social_force(self) -> np.ndarray:
        """(num_worlds,) complex: the humans' social-force repulsion on each world's (first) robot."""

    def row(self, name: str, world: int) -> np.ndarray:
        """A copy of ``world``'s array ``name`` (``positions``, ``velocities``: the robot then the humans; ``human_goals``,
        ``human_respawns``)."""

    def robot_goal(self, world: int) -> complex:
        """``world``'s (first) robot's goal."""

    def frame(self, world: int) -> dict[str, np.ndarray]:
        """``world`` now as :func:`world_frame` gives a simulator's (what evaluation records per step)."""

    def simulator(self, world: int) -> Simulator:
        """A snapshot of ``world`` as a :class:`crowdnav.Simulator` (a copy: stepping it leaves the world as it is)."""

    def simulators(self) -> list[Simulator]:
        """Each world's simulator to read, never to step: the live one where a world is one, else a snapshot."""

    def snapshot(self, world: int) -> WorldState:
        """Everything ``world``'s future depends on given the actions, copied (:class:`crowdnav.envs.engines.world_state.WorldState`)."""

    def load(self, world: int, state: WorldState) -> None:
        """Make ``state`` (a :meth:`snapshot` of a world of this scenario and options, either engine's) ``world``'s: it plays on
        as the captured world would, bit for bit. A ValueError in one line names what differs (scenario, settings, robots, version)."""


@dataclass
class RobotsStep:
    """What one step did to every robot of every world (W worlds, R robots; zeros / None / False where a world did not step)."""

    stepped: np.ndarray
    """(W, R) bool: the robots that acted (in the world when the step began): the env's ``infos[name]["active"]``."""
    rewards: np.ndarray
    """(W, R) float64: each stepped robot's reward (0 for the others)."""
    terms: dict[str, np.ndarray]
    """Reward term -> (W, R) float64 (``infos[name]["reward_terms"]`` of the stepped robots)."""
    outcome: np.ndarray
    """(W, R) object: a stepped robot's outcome (``success``, ``collision``, ``out_of_bounds``, ``truncated``; None: runs on)."""
    collisions: dict[tuple[int, int], Collision]
    """(world, robot) -> the contact of a robot whose outcome is ``collision``."""
    truncated: np.ndarray
    """(W,) bool: the time limit ended the world's episode (some robot was still running)."""
    over: np.ndarray
    """(W,) bool: the world's episode ended (every robot ended, or the time limit)."""


@dataclass
class RobotsFrame:
    """Where every robot and human of every world is now (W worlds, R robots, N: the largest crowd), what evaluation's
    metrics record per step; zeros for a world never reset."""

    robots: np.ndarray
    """(W, R) complex128: each robot's centre (a robot that left: where it is parked)."""
    goals: np.ndarray
    """(W, R) complex128: each robot's goal."""
    social_force: np.ndarray
    """(W, R) float64: the magnitude of the humans' social force on each robot (``abs(view.robot_social_force)``)."""
    humans: np.ndarray
    """(W, N) complex128: each human's centre, in the simulator's order; NaN past a world's crowd."""
    crowd: np.ndarray
    """(W,) int64: each world's number of humans."""
    stalls: np.ndarray
    """(W,) int64: how many times a human stalled this episode, per world."""


class RobotsEngine(Protocol):
    """``num_worlds`` worlds of a ``robots:`` scenario, every robot driven by the caller (:mod:`crowdnav.envs.engines.robots`)."""

    num_worlds: int
    robot_names: list[str]
    """Every robot's agent name, the scenario's order."""
    observation_size: int
    """D: the length of a robot's flat observation (every robot's is the same)."""

    def reset(self, worlds: Sequence[int] | np.ndarray, seeds: Sequence[int | None]) -> None:
        """Start a new episode in each of ``worlds`` (``seeds[k]`` for ``worlds[k]``; None continues its generator)."""

    def step(self, actions: np.ndarray, active: np.ndarray | None = None) -> RobotsStep:
        """Step the worlds of the bool mask ``active`` (None: all) with their (W, R, 2) ``actions`` rows; a robot that left
        ignores its action (it is not checked), a robot in the world needs 2 finite values (clipped to [-1, 1])."""

    def observe(self) -> np.ndarray:
        """(W, R, D) float32: each robot's flat observation now (all zero for a robot that had left when the last step began)."""

    def frame(self) -> RobotsFrame:
        """Every robot and human of every world now (:class:`RobotsFrame`)."""

    def radii(self, world: int) -> tuple[np.ndarray, np.ndarray]:
        """``world``'s body radii (m): its robots' (R,) and its humans' (n,), the simulator's order."""

    def snapshot(self, world: int) -> WorldState:
        """Everything ``world``'s future depends on given the actions, with every robot's last observation, copied
        (:mod:`crowdnav.envs.engines.robots_state`): it loads into a world of either robots engine."""

    def load(self, world: int, state: WorldState) -> None:
        """Make ``state`` (a :meth:`snapshot`, either robots engine's) ``world``'s: it plays on bit for bit, :meth:`observe`
        giving the stored observation until the world steps or resets. A ValueError in one line names what differs."""

    def close(self) -> None:
        """Release what the worlds hold."""


def world_frame(sim: Any) -> dict[str, np.ndarray]:
    """Positions, velocities and goals of the robot (index 0) and the humans, copied (complex, (n + 1,)); each human's respawns (n,).

    Several robots (``robots:``): the other robots follow the humans (n + R,); NaN once a robot has left the world.
    """
    if sim.team is None:
        return {"positions": sim.positions.copy(), "velocities": sim.velocities.copy(),
                "goals": np.concatenate([[sim.robot_goal], sim.human_goals]), "respawns": sim.human_respawns.copy()}
    own = {"positions": sim.positions, "velocities": sim.velocities, "goals": np.concatenate([[sim.robot_goal], sim.human_goals]),
           "respawns": sim.human_respawns.copy()}
    return with_team(own, sim.team.state)


def with_team(frame: Mapping[str, np.ndarray], team: TeamState) -> dict[str, np.ndarray]:
    """``frame`` (the robot and the humans) with the other robots of ``team`` after the humans; NaN for a robot that left."""
    gone = np.where(team.active[1:], 0j, complex(np.nan, np.nan))
    return {"positions": np.concatenate([frame["positions"], team.positions + gone]),
            "velocities": np.concatenate([frame["velocities"], team.velocities + gone]),
            "goals": np.concatenate([frame["goals"], team.goals]), "respawns": frame["respawns"]}
