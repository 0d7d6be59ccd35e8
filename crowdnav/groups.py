"""What the crowd's groups do: where members start, their first goals, and what they do at a goal.

The simulator calls these with itself (``sim``: its scenario, groups, placements and generator):
:func:`place_groups` and :func:`first_goals` at reset, :func:`apply_goal_rules` after each step,
on the state it is given (the simulator's own, or one world's row of a batch: a
:class:`crowdnav.sim_state.SimState`, changed in place). Groups are visited in file order, and a file
without ``humans.groups`` is one group: it draws the same random numbers in the same order as
before groups existed, so its episodes did not change. Loops run over groups (a scenario's
constant), never over humans.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from crowdnav.placement import GAP, JITTER_REACH, PlacementError

if TYPE_CHECKING:
    from crowdnav.sim_state import SimState


def place_groups(sim: Any, start: np.ndarray, goal: complex | np.ndarray, counts: list[int]) -> list[np.ndarray]:
    """Member positions of every group (complex arrays, file order), each away from the robots and the groups before it.

    ``start``: (R,) every robot's start; ``goal``: the robot's goal, or (R,) every robot's (``robots:``).
    """
    robot, radius, rng = sim.scenario.robot, sim.scenario.humans.radius, sim.rng
    team = sim.team
    # one robot: the float radius and the (1,) goal it always had (same bits); several: (R,) radii, near each start and goal
    robot_radius, robots = (robot.radius, 1) if team is None else (team.all_radii, team.count)
    margin = GAP + JITTER_REACH  # the new point's jitter; placed agents are where they are
    placed, out = [start], []
    for group, places, count in zip(sim.groups, sim.placement.groups, counts, strict=True):
        if count == 0:
            out.append(np.zeros(0, dtype=complex))
            continue
        humans_placed = np.concatenate(placed[1:]) if len(placed) > 1 else np.zeros(0, dtype=complex)
        ring = places.circle_radius
        if group.standing:  # keep the robot's goal reachable: no circle around it
            away = np.concatenate([start, [goal] if team is None else goal, humans_placed])
            near = np.full(len(away), ring + 2 * radius + margin)
            near[: 2 * robots] = robot_radius + ring + radius + margin if team is None else np.tile(robot_radius + ring + radius + margin, 2)
            centre = places.spawn.draw(rng, 1, away_from=away, min_distance=near)[0]
            phase = rng.uniform(0, 2 * math.pi)
            members = centre + ring * np.exp(1j * (phase + 2 * math.pi * np.arange(count) / count))
        else:
            away = np.concatenate([start, humans_placed])
            near = np.full(len(away), 2 * radius + margin)
            if team is None:
                near[0] = robot_radius + radius + margin
            else:
                near[:robots] = robot_radius + radius + margin
            members = places.spawn.draw(rng, count, away_from=away, min_distance=near)
        placed.append(members)
        out.append(members)
    return out

def first_goals(sim: Any, spawn: list[np.ndarray]) -> list[np.ndarray]:
    """Every member's first goal, group by group (standing members: where they stand)."""
    goals = []
    for group, places, members in zip(sim.groups, sim.placement.groups, spawn, strict=True):
        if len(members) == 0 or group.standing:
            goals.append(members.copy())  # standing members' goal is where they stand
        elif group.goal_rule == "mirror":
            goals.append(2 * mirror_center(group, sim.scenario) - members)
        else:
            goals.append(places.goal.draw(sim.rng, len(members), replace=len(members) > len(places.goal)))
    return goals


def apply_goal_rules(state: SimState, sim: Any) -> bool:
    """After a step: humans of ``state`` at their goals follow their group's ``on_goal`` and ``goal_rule``.

    ``state`` is changed in place (``human_arrived``, ``human_stopped``, ``human_goals``, and for
    respawns ``positions``, ``velocities``, ``human_respawns``); draws come from ``sim.rng``.
    Returns whether anyone respawned (moved): the caller then measures the new geometry.
    """
    arrived = np.abs(state.human_goals - state.positions[1:]) <= sim.scenario.humans.social_force.goal_tolerance
    np.logical_and(arrived, ~state.human_stopped, out=state.human_arrived)
    single, moved = len(sim.groups) == 1, False
    for g, (group, places) in enumerate(zip(sim.groups, sim.placement.groups, strict=True)):
        if group.standing or group.max_count == 0:
            continue
        mine = arrived if single else arrived & (state.human_group == g)
        if group.on_goal == "stop":
            state.human_stopped |= mine
            state.velocities[1:][state.human_stopped] = 0.0
            continue
        if not mine.any():
            continue
        index = np.flatnonzero(mine)
        if group.on_goal == "respawn":
            index = _respawn(state, sim, index, group, places)
            if len(index) == 0:
                continue
            moved = True
        if group.goal_rule == "mirror":
            state.human_goals[index] = 2 * mirror_center(group, sim.scenario) - state.human_goals[index]
        else:
            state.human_goals[index] = places.goal.draw(sim.rng, len(index), replace=True)
    return moved


def _respawn(state: SimState, sim: Any, index: np.ndarray, group: Any, places: Any) -> np.ndarray:
    """Move arrived members to free spawn points of their group; returns those that moved (the rest wait)."""
    radius, robot = sim.scenario.humans.radius, sim.scenario.robot
    others = np.delete(state.positions, index + 1)
    robot_radius = robot.radius
    team = getattr(sim, "team", None)
    if team is not None:  # keep clear of every robot
        others, robot_radius = np.concatenate([others, team.state.positions]), float(team.all_radii.max())
    reach = max(robot_radius, radius) + radius + GAP + JITTER_REACH
    for count in range(len(index), 0, -1):  # at most len(index) tries, usually one
        try:
            new = places.spawn.draw(sim.rng, count, away_from=others, min_distance=reach)
        except PlacementError:
            continue
        moved = index[:count]
        state.positions[moved + 1] = new
        state.velocities[moved + 1] = 0.0
        state.human_respawns[moved] += 1
        if group.goal_rule == "mirror":
            # the mirror rule flips the goal below, so store the spawn's mirror image twice-flipped
            state.human_goals[moved] = new
        return moved
    return index[:0]


def mirror_center(group: Any, scenario: Any) -> complex:
    """Centre of a group's mirror rule (default: the world's centre)."""
    return complex(*(group.mirror_center or scenario.world_center))
