"""What the crowd's groups do: where members start, their first goals, and what they do at a goal.

The simulator calls these with itself (``sim``: its scenario, groups, placements and generator,
what :class:`GroupWorld` declares):
:func:`place_groups` and :func:`first_goals` at reset; after each step :func:`goal_checks` (who
arrived or stalled: one kernel for one world and for a batch's rows, a leading world axis) and,
where they have something to do, :func:`apply_goal_rules`, on the state it is given (the simulator's
own, or one world's row of a batch: a :class:`crowdnav.sim.state.SimState`, changed in place; its
draws come from that world's generator). Groups are visited in file order, and a file
without ``humans.groups`` is one group: it draws the same random numbers in the same order as
before groups existed, so its episodes did not change. Loops run over groups (a scenario's
constant), never over humans.

A group with ``walk_together`` (Moussaïd et al. 2010, PLoS ONE 5(4): e10047; the forces are
:func:`crowdnav.sim.forces.group_force`) starts on a small circle like a standing one, shares
one goal, has arrived when its walking members' centre of mass is within the goal tolerance
(plus its circle radius under geodesic routing: :func:`arrivals`), and takes its next goal as a
whole, also when one member stalled.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol

import numpy as np

from crowdnav.sim import forces as sf
from crowdnav.worlds.placement import GAP, JITTER_REACH, PlacementError

if TYPE_CHECKING:
    from crowdnav.scenario.schema import HumanGroup, Scenario
    from crowdnav.sim.robots import Team
    from crowdnav.sim.state import SimState, StateFields
    from crowdnav.worlds.placement import GroupPlacement, Placement
    from crowdnav.worlds.placement_regions import CandidateSet


class GroupWorld(Protocol):
    """What the groups' placement and goal rules read of a simulator (:class:`crowdnav.Simulator`; a batch world's slot)."""

    @property
    def scenario(self) -> Scenario: ...
    @property
    def groups(self) -> list[HumanGroup]: ...
    @property
    def placement(self) -> Placement: ...
    @property
    def team(self) -> Team | None: ...
    @property
    def rng(self) -> np.random.Generator: ...
    @property
    def together(self) -> np.ndarray | None: ...
    @property
    def stall_window(self) -> int: ...
    @property
    def rules_when_stopped(self) -> np.ndarray | None: ...
    @property
    def rules_every_step(self) -> bool: ...


def place_groups(sim: GroupWorld, start: np.ndarray, goal: complex | np.ndarray, counts: list[int]) -> list[np.ndarray]:
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
        if group.walk_together:  # one centre away from the robots and the groups before; members on a circle around it
            away = np.concatenate([start, humans_placed])
            near = np.full(len(away), ring + 2 * radius + margin)
            near[:robots] = robot_radius + ring + radius + margin
            centre = places.spawn.draw(rng, 1, away_from=away, min_distance=near)[0]
            phase = rng.uniform(0, 2 * math.pi)
            members = centre + ring * np.exp(1j * (phase + 2 * math.pi * np.arange(count) / count))
        elif group.standing:  # keep the robot's goal reachable: no circle around it
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

def first_goals(sim: GroupWorld, spawn: list[np.ndarray]) -> list[np.ndarray]:
    """Every member's first goal, group by group (standing members: where they stand)."""
    goals = []
    for group, places, members in zip(sim.groups, sim.placement.groups, spawn, strict=True):
        if len(members) == 0 or group.standing:
            goals.append(members.copy())  # standing members' goal is where they stand
        elif group.walk_together:  # one goal for the group: the mirror of its centre, or one draw
            if group.goal_rule == "mirror":
                goal = 2 * mirror_center(group, sim.scenario) - members.mean()
            else:
                goal = _goal_candidates(places).draw(sim.rng, 1)[0]
            goals.append(np.full(len(members), goal, dtype=complex))
        elif group.goal_rule == "mirror":
            goals.append(2 * mirror_center(group, sim.scenario) - members)
        else:
            goals.append(_goal_candidates(places).draw(sim.rng, len(members), replace=len(members) > len(_goal_candidates(places))))
    return goals


def goal_checks(state: StateFields[Any, Any, Any], sim: GroupWorld, rows: np.ndarray | None = None) -> GoalChecks:
    """A step's arrival and stall checks, written once for one world and K: ``state`` one world's (``rows`` None) or K
    worlds' (:class:`crowdnav.batch.stacked_state.StackedState`), checked in its ``rows`` (a leading world axis).

    Writes ``human_arrived`` (the arrivals of humans not stopped: :func:`arrivals`) and, where a stall
    check is due (every ``sim.stall_window`` steps), ``human_stall_mark``; returns what the goal rules
    (:func:`apply_goal_rules`) read and where they have something to do. ``sim``: the simulator (a
    batch: any world's, they share the scenario and its tables).
    """
    if rows is None:
        humans, goals, group, stopped, steps = state.positions[1:], state.human_goals, state.human_group, state.human_stopped, state.step_count
    else:
        humans, goals, group = state.positions[rows, 1:], state.human_goals[rows], state.human_group[rows]
        stopped, steps = state.human_stopped[rows], state.step_count[rows]
    where = ... if rows is None else rows
    distance = np.abs(goals - humans)
    arrived = arrivals(distance, humans, goals, group, stopped, sim)
    if rows is None:  # one world: straight into its array
        walked_in = np.logical_and(arrived, ~stopped, out=state.human_arrived)
    else:
        walked_in = state.human_arrived[rows] = arrived & ~stopped
    rules = _any(arrived)  # nobody at a goal: the rules have nothing to do but stalls (most steps)
    if rules is True or (rules is not False and rules.any()):
        rules = _any(walked_in)
        acting = sim.rules_when_stopped
        if acting is not None:  # stopped members at their goals whose group's rule still acts (rule_tables)
            rules = rules | _any(arrived & stopped & acting[group])
    stalled, window = None, sim.stall_window
    due = window and steps % window == 0  # a bool, or (K,) bools
    if due is True or (isinstance(due, np.ndarray) and due.any()):
        mark = state.human_stall_mark[where]
        stalled = stalled_humans(distance, mark, stopped | walked_in, sim.scenario.humans.stall.progress)
        if due is True:
            state.human_stall_mark[where] = distance
        else:  # only the worlds whose check is due
            stalled &= due[:, None]
            state.human_stall_mark[where] = np.where(due[:, None], distance, mark)
        rules = rules | _any(stalled)
    if sim.rules_every_step:
        rules = True if rows is None else np.ones(len(rows), dtype=bool)
    return GoalChecks(arrived, stalled, rules)


def _any(flags: np.ndarray) -> Any:
    """Whether any of the last axis is set: one world's bool (a count: cheaper than numpy's any), or K worlds' (K,) bools."""
    return bool(np.count_nonzero(flags)) if flags.ndim == 1 else flags.any(1)


class GoalChecks(NamedTuple):
    """What :func:`goal_checks` found: per human (..., n), per world (...) (the leading world axis of the rows checked, if any)."""

    arrived: np.ndarray
    """(..., n) bool: the humans at their goals (:func:`arrivals`; stopped ones too, as the goal rules read them)."""
    stalled: np.ndarray | None
    """(..., n) bool: the humans a due stall check found stalled (:func:`stalled_humans`); None: no check was due."""
    rules: Any
    """One world's bool, or (K,) bools: the worlds where :func:`apply_goal_rules` has something to do (elsewhere it changes nothing)."""


def rule_tables(groups: list[HumanGroup], places: bool) -> tuple[np.ndarray | None, bool]:
    """Where the goal rules act besides the arrivals of walking humans and the stalls: ``(when_stopped, every_step)``.

    ``when_stopped``: (G,) bool, the walking groups whose rule acts on a member at its goal even
    when it is stopped (``on_goal`` new_goal or respawn: a recorded person, a human a multi-agent env
    stopped); None where no group does. ``every_step``: a walking group stops at its goal (its rule
    zeroes every stopped human's velocity) and a crowd model ``places`` its humans (their velocities are
    the recording's, not 0).
    """
    walking = [not group.standing and group.max_count > 0 for group in groups]
    table = np.array([walk and group.on_goal != "stop" for walk, group in zip(walking, groups, strict=True)], dtype=bool)
    stops = any(walk and group.on_goal == "stop" for walk, group in zip(walking, groups, strict=True))
    return (table if table.any() else None), places and stops


def apply_goal_rules(state: SimState, sim: GroupWorld, arrived: np.ndarray, stalled: np.ndarray | None) -> bool:
    """After a step: humans of ``state`` at their goals follow their group's ``on_goal`` and ``goal_rule``; stalled ones take a new goal.

    ``arrived`` and ``stalled``: that world's (n,) :class:`GoalChecks` (``stalled`` None: no check
    was due). ``state`` is changed in place (``human_stopped``, ``human_goals``, ``human_stalls``,
    the stall marks of new goals, and for respawns ``positions``, ``velocities``, ``human_respawns``);
    draws come from ``sim.rng``. A stalled human takes a new goal by its group's ``goal_rule``
    (sample: drawn from the goal regions; mirror: the mirror image, so it turns back), whatever its
    ``on_goal``. Returns whether anyone respawned (moved): the caller then measures the new geometry.
    """
    if stalled is not None and stalled.any():
        state.human_stalls[stalled] += 1
    else:
        stalled = None
    single, moved = len(sim.groups) == 1, False
    for g, (group, places) in enumerate(zip(sim.groups, sim.placement.groups, strict=True)):
        if group.standing or group.max_count == 0:
            continue
        mine = arrived if single else arrived & (state.human_group == g)
        stuck_here = _NONE if stalled is None else np.flatnonzero(stalled if single else stalled & (state.human_group == g))
        if group.on_goal == "stop":
            state.human_stopped |= mine
            state.velocities[1:][state.human_stopped] = 0.0
            index = stuck_here
        else:
            index = np.flatnonzero(mine) if mine.any() else _NONE
            if group.on_goal == "respawn" and len(index):
                index = _respawn(state, sim, index, group, places)
                moved = moved or len(index) > 0
            if len(stuck_here):  # never arrived ones: the two sets are apart
                index = np.union1d(index, stuck_here)
        if group.walk_together and len(index):  # one arrived (all did) or stalled: the group's walking members take one goal
            index = np.flatnonzero((state.human_group == g) & ~state.human_stopped)
        if len(index) == 0:
            continue
        if group.goal_rule == "mirror":
            state.human_goals[index] = 2 * mirror_center(group, sim.scenario) - state.human_goals[index]
        elif group.walk_together:
            state.human_goals[index] = _goal_candidates(places).draw(sim.rng, 1)[0]
        else:
            state.human_goals[index] = _goal_candidates(places).draw(sim.rng, len(index), replace=True)
        state.human_stall_mark[index] = np.inf  # a new goal: the next check only starts its window
    return moved


_NONE = np.zeros(0, dtype=np.intp)


def together_table(groups: list[HumanGroup]) -> np.ndarray | None:
    """(G,) bool: which groups walk together; None when none does (the crowd's step is then the one it always was)."""
    table = np.array([bool(getattr(group, "walk_together", False)) for group in groups], dtype=bool)
    return table if table.any() else None


def arrivals(distance: np.ndarray, humans: np.ndarray, goals: np.ndarray, group: np.ndarray, stopped: np.ndarray, sim: GroupWorld) -> np.ndarray:
    """The arrival kernel (any leading world axes, last axis the n humans): who is at its goal after this step.

    A human whose ``distance`` to its goal is within ``goal_tolerance`` (stopped ones too: the caller
    masks them); in a group that walks together, a walking member when the centre of mass of the
    group's walking members is within it of the group's goal (all of them arrive together), a
    stopped one never. With ``humans.routing: geodesic`` the group's circle radius is added to the
    tolerance: members gathered around a goal beside a wall or bench (where they cannot stand
    around it, so their centre stays off it) have arrived. ``sim``: the simulator (its scenario,
    placement and ``together`` table).
    """
    tolerance = sim.scenario.humans.social_force.goal_tolerance
    arrived: np.ndarray = distance <= tolerance
    table = sim.together
    if table is None:
        return arrived
    in_group = table[group]
    arrived &= ~(in_group & stopped)
    index, key, bins = sf.member_keys(in_group & ~stopped, group, len(table))
    if len(index):
        _, centres = sf.group_centroids(humans.reshape(-1)[index], key, bins)
        reach = tolerance if sim.scenario.humans.routing != "geodesic" else tolerance + _circle_radii(sim)[key % len(table)]
        arrived.reshape(-1)[index] = np.abs(goals.reshape(-1)[index] - centres[key]) <= reach
    return arrived


def _circle_radii(sim: GroupWorld) -> np.ndarray:
    """(G,) m: each group's circle radius, how far a gathered group's members stand from its centre."""
    return np.array([places.circle_radius for places in sim.placement.groups])


def stall_window(scenario: Scenario) -> int:
    """Steps between stall checks (``humans.stall.time`` rounded to whole steps, at least 1); 0: no stall checks."""
    time = scenario.humans.stall.time
    return 0 if time is None else max(1, round(time / scenario.time_step))


def stalled_humans(distance: np.ndarray, mark: np.ndarray, resting: np.ndarray, progress: float) -> np.ndarray:
    """The stall kernel (any leading world axes): humans not ``resting`` (stopped or just arrived) that came less than
    ``progress`` m closer to their goal since the last check (``mark``: their distance then, inf for a newer goal)."""
    stalled: np.ndarray = (mark - distance < progress) & ~resting
    return stalled


def _respawn(state: SimState, sim: GroupWorld, index: np.ndarray, group: HumanGroup, places: GroupPlacement) -> np.ndarray:
    """Move arrived members to free spawn points of their group; returns those that moved (the rest wait)."""
    radius, robot = sim.scenario.humans.radius, sim.scenario.robot
    others = np.delete(state.positions, index + 1)
    robot_radius = robot.radius
    team = sim.team
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


def _goal_candidates(places: GroupPlacement) -> CandidateSet:
    """A group's goal candidates (a group whose rule draws its goals has them: :mod:`crowdnav.worlds.placement`)."""
    assert places.goal is not None
    return places.goal


def mirror_center(group: HumanGroup, scenario: Scenario) -> complex:
    """Centre of a group's mirror rule (default: the world's centre)."""
    return complex(*(group.mirror_center or scenario.world_center))
