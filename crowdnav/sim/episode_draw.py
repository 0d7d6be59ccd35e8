"""The draws that start an episode: one world's first :class:`crowdnav.sim.state.SimState`.

:func:`draw_state` is what :meth:`crowdnav.Simulator.draw_episode` draws from the episode's
generator, in a fixed order (the crowd's size per group, the robot's start, goal and heading,
a ``robots:`` scenario's other robots, then each group's places, goals and speeds), so the same
seed gives the same episode bit for bit. The simulator then takes the state as its own.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, cast

import numpy as np

from crowdnav.sim.groups import GroupWorld, first_goals, place_groups
from crowdnav.sim.robots import first_heading
from crowdnav.sim.state import SimState
from crowdnav.worlds.placement import JITTER_REACH

if TYPE_CHECKING:
    from crowdnav.scenario.schema import HumanGroup


def draw_state(sim: GroupWorld, rng: np.random.Generator) -> SimState:
    """A new episode's state of ``sim``'s scenario (what the groups read of it), drawn from ``rng`` (the episode's generator)."""
    robot, placement = sim.scenario.robot, sim.placement
    counts = [int(rng.integers(group.min_count, group.max_count + 1)) for group in sim.groups]
    n = sum(counts)
    start = placement.robot_start.draw(rng, 1, allowed=cast(np.ndarray, placement.start_goal_ok.any(1)))
    reachable = None
    if placement.start_component is not None:  # walls split the free space: a goal on the start's side
        nearest = int(np.argmin(np.abs(placement.robot_start.points - start[0])))
        reachable = placement.goal_component == placement.start_component[nearest]
    goal = placement.robot_goal.draw(
        rng, 1, allowed=reachable, away_from=start, min_distance=robot.min_start_goal_distance + JITTER_REACH
    )[0]
    heading = first_heading(robot, rng, complex(start[0]), complex(goal))
    # the other robots after the ego robot's draws, so a one-robot scenario draws what it always drew
    starts, goals = sim.team.draw(rng, complex(start[0]), complex(goal)) if sim.team is not None else (start, goal)
    # groups in file order, each away from the robots and the groups before it; then goals, then speeds
    # (one group draws exactly what the crowd drew before groups existed: same seed, same episode)
    spawn = place_groups(sim, starts, goals, counts)
    standing = np.repeat([group.standing for group in sim.groups], counts).astype(bool)
    human_goals = np.concatenate([np.zeros(0, dtype=complex), *first_goals(sim, spawn)])
    normals = sim.scenario.humans.speed_normals
    preferred_speed = np.concatenate([np.zeros(0), *(_preferred_speeds(rng, group, count, normal)
                                                     for group, count, normal in zip(sim.groups, counts, normals, strict=True))])
    max_speed = preferred_speed * sim.scenario.humans.social_force.max_speed_factor
    positions = np.concatenate([start, *spawn])
    return SimState(
        positions=positions,
        velocities=np.zeros(n + 1, dtype=complex),
        robot_goal=complex(goal),
        robot_heading=heading,
        step_count=0,
        human_group=np.repeat(np.arange(len(counts)), counts),
        human_goals=human_goals,
        human_preferred_speed=preferred_speed,
        human_max_speed=max_speed,
        # standing members have no speed; a cap of 1 keeps the shared command formula free of 0 / 0
        command_cap=np.where(standing, 1.0, max_speed) if standing.any() else max_speed,
        human_stopped=standing.copy(),
        human_arrived=np.zeros(n, dtype=bool),
        human_respawns=np.zeros(n, dtype=np.int64),
        human_stall_mark=np.abs(human_goals - positions[1:]),  # the first stall window counts from the start
        human_stalls=np.zeros(n, dtype=np.int64),
    )


def _preferred_speeds(rng: np.random.Generator, group: HumanGroup, count: int, normal: tuple[float, float] | None) -> np.ndarray:
    """``count`` preferred speeds (m/s) of ``group``'s members: drawn from its range (uniform, or ``normal`` = (mean, sd)
    clipped to it: a crowd preset's, :attr:`crowdnav.scenario.schema.Humans.speed_normals`), 0 for a standing group."""
    if group.standing:
        return np.zeros(count)
    assert group.preferred_speed is not None  # a walking group always has its range (Humans.crowd fills it in)
    if normal is not None:
        return np.clip(rng.normal(*normal, size=count), *group.preferred_speed)
    return rng.uniform(*group.preferred_speed, size=count)
