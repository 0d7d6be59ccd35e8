"""Collision-free placement of starts and goals without rejection sampling.

At load time each region becomes a set of candidate positions: a hexagonal lattice whose
points are free of static obstacles and far enough apart that two agents placed on
different points (with their random jitter) can never overlap. A reset then only draws
distinct lattice points, so it costs the same at any density, and a region that cannot
hold the requested crowd is reported when the scenario loads instead of looping forever.

Four modules: this one assembles a scenario's sets (:func:`build_placement`: each robot's
start and goal, each group's spawns and goals); :mod:`crowdnav.worlds.placement_regions` declares the sets and turns one
region into a :class:`CandidateSet` and draws from it; :mod:`crowdnav.worlds.placement_checks` holds
the load-time capacity and reachability checks; :mod:`crowdnav.worlds.placement_team` the fine sets of
several robots and the check that they all fit together. The names users import live on here.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import shapely
from shapely.geometry import Polygon as ShapelyPolygon
from shapely.geometry import box
from shapely.geometry.base import BaseGeometry

from crowdnav.scenario.schema import HumanGroup, Robot, Scenario
from crowdnav.worlds.obstacles import GeometryError, StaticObstacles
from crowdnav.worlds.placement_checks import (
    check_capacity,
    check_human_reachability,
    check_ring_start_goal,
    component_of,
    far_pairs,
    free_components,
    inside_floor,
    ring_mirror_free,
)
from crowdnav.worlds.placement_regions import GAP as GAP  # the public names live on here
from crowdnav.worlds.placement_regions import JITTER as JITTER
from crowdnav.worlds.placement_regions import JITTER_REACH as JITTER_REACH
from crowdnav.worlds.placement_regions import MAX_CANDIDATES as MAX_CANDIDATES
from crowdnav.worlds.placement_regions import CandidateSet as CandidateSet
from crowdnav.worlds.placement_regions import GroupPlacement as GroupPlacement
from crowdnav.worlds.placement_regions import Placement as Placement
from crowdnav.worlds.placement_regions import PlacementError as PlacementError
from crowdnav.worlds.placement_regions import clear_of, merge_candidates, region_candidates
from crowdnav.worlds.placement_team import check_team, team_fallback


def build_placement(scenario: Scenario, obstacles: StaticObstacles) -> Placement:
    humans, world = scenario.humans, scenario.world
    world_box = box(world.min[0], world.min[1], world.max[0], world.max[1])
    occupied = obstacles.union
    robots = [_robot_placement(robot, path, world_box, occupied)
              for robot, path in zip(scenario.robot_specs, scenario.robot_paths, strict=True)]
    for robot, places in zip(scenario.robot_specs[1:], robots[1:], strict=True):
        places.fallback = team_fallback(robot, places, world_box, occupied)
    if len(robots) > 1:
        check_team(scenario, robots)
    groups = [_group_placement(scenario, path, group, world_box, occupied) for path, group in humans.crowd]
    first = robots[0]
    check_capacity(scenario, first.robot_start, first.robot_goal, groups, robots[1:])
    first.groups, first.other_robots = groups, robots[1:]
    return first


def _robot_placement(robot: Robot, path: str, world_box: ShapelyPolygon, occupied: BaseGeometry) -> Placement:
    """One robot's candidate sets (``groups`` left empty), its errors named at ``path`` (``robot`` or ``robots.<i>``)."""
    robot_start = region_candidates(robot.start, f"{path}.start", robot.radius, world_box, occupied)
    robot_goal = region_candidates(robot.goal, f"{path}.goal", robot.radius, world_box, occupied)
    slack = 2 * JITTER_REACH
    start_goal_ok, largest = far_pairs(robot_start.points, robot_goal.points, robot.min_start_goal_distance + slack)
    if robot_start.ring_center is not None or robot_goal.ring_center is not None:
        start_goal_ok = np.ones_like(start_goal_ok)  # rotated rings: any start, checked for every rotation below
        check_ring_start_goal(robot_start, robot_goal, robot.min_start_goal_distance, path)
    if not start_goal_ok.any():
        if largest < 1e-9:
            message = f"{path}.start and {path}.goal only offer the same position; expected a goal away from the start"
        else:
            message = (
                f"no start in {path}.start is {robot.min_start_goal_distance:g} m from a goal in {path}.goal "
                f"(largest distance available: {largest:.2f} m); expected a smaller distance or regions further apart"
            )
        raise GeometryError(f"{path}.min_start_goal_distance", message)
    start_component = goal_component = None
    if robot_start.ring_center is None and robot_goal.ring_center is None:
        # only pairs the robot's disc can travel between: walls and furniture may close the way
        components = free_components(world_box, occupied, robot.radius)
        start_component, goal_component = component_of(robot_start.points, components), component_of(robot_goal.points, components)
        same = start_component[:, None] == goal_component[None, :]
        if start_goal_ok.any() and not (start_goal_ok & same).any():
            raise GeometryError(f"{path}.goal", f"no goal in {path}.goal can be reached from a start in {path}.start: walls or furniture "
                                f"close the way for a robot of radius {robot.radius:g} m; expected start and goal regions in one "
                                "connected free space")
        start_goal_ok &= same
        beyond_goal, _ = far_pairs(robot_start.points, robot_goal.points, robot.goal_radius + slack)
        if (start_goal_ok & ~beyond_goal).any():  # an episode could start inside its goal
            raise GeometryError(
                f"{path}.goal_radius",
                f"a start in {path}.start can lie within the goal radius ({robot.goal_radius:g} m) of a goal in {path}.goal, so an "
                f"episode could end as a success before the robot moves; expected {path}.min_start_goal_distance above the goal "
                "radius, or a smaller goal radius",
            )
    split = start_component is not None and goal_component is not None and len(set(start_component.tolist()) | set(goal_component.tolist())) > 1
    components_kept = (start_component, goal_component) if split else (None, None)
    return Placement(robot_start, robot_goal, [], start_goal_ok, *components_kept)


def _circle_centres(region: Any, where: str, group: HumanGroup, ring: float, radius: float, world_box: ShapelyPolygon,
                    occupied: BaseGeometry) -> CandidateSet:
    """Centres in ``region`` of a circle of members (radius ``ring``) clear of obstacles and walls; when one member would fit
    but the whole circle does not, the error says the group is too big for its region, with its size."""
    try:
        return region_candidates(region, where, ring + radius, world_box, occupied)
    except GeometryError:
        region_candidates(region, where, radius, world_box, occupied)  # no room for one member either: that error stands
        what = "standing circle" if group.standing else "walking group"
        raise GeometryError(where, f"the {what} of {group.max_count} members does not fit its region: its circle is "
                            f"{2 * (ring + radius):.2f} m across (radius {ring:.2f} m plus the members' {radius:g} m), and no centre "
                            "in the region keeps it clear of the walls and obstacles; expected fewer members or a larger region") from None


def _group_placement(scenario: Scenario, path: str, group: HumanGroup, world_box: ShapelyPolygon, occupied: BaseGeometry) -> GroupPlacement:
    """Candidate sets of one group: member spawns and goals (walking) or circle centres (standing)."""
    humans, slack = scenario.humans, 2 * JITTER_REACH
    empty = CandidateSet(np.zeros(0, dtype=complex), 0.0)
    if group.max_count == 0:
        return GroupPlacement(path, empty, None)
    ring = 0.0
    if group.on_circle:  # a standing circle, or a group that walks together: members start around one drawn centre
        ring = group.circle_radius_for(humans.radius)
        # the circle is one disc of radius ring + radius for obstacles; its members stay in the world too
        spawn_sets = [_circle_centres(r, f"{path}.spawn.{i}", group, ring, humans.radius, world_box, occupied)
                      for i, r in enumerate(group.spawn)]
        centres = merge_candidates(spawn_sets, spacing=0.0)
        inside = shapely.contains_xy(world_box.buffer(-ring - JITTER_REACH), centres.points.real, centres.points.imag)
        if not inside.any():
            what = "standing circle" if group.standing else "walking group's starting circle"
            raise GeometryError(f"{path}.spawn", f"no centre leaves the {what} (radius {ring:.2f} m) inside the world; "
                                "expected a region further from the world's edge")
        spawn = CandidateSet(centres.points[inside], centres.jitter, centres.ring_center)
        if group.standing:
            return GroupPlacement(path, spawn, None, ring)
    else:
        spawn_sets = [region_candidates(r, f"{path}.spawn.{i}", humans.radius, world_box, occupied) for i, r in enumerate(group.spawn)]
        spawn = merge_candidates(spawn_sets, spacing=2 * humans.radius + GAP + slack)
    goal = None
    if group.goal_rule == "mirror":
        center = complex(*(group.mirror_center or scenario.world_center))
        clearance = humans.radius + GAP + slack / 2
        if spawn.ring_center is not None and not ring_mirror_free(spawn, center, clearance, world_box, occupied):
            # some rotations of the ring would mirror onto goals outside the floor or in an obstacle:
            # the ring stays still, so that the mirrored points dropped below stay dropped
            spawn = CandidateSet(spawn.points, spawn.jitter)
        mirrored = 2 * center - spawn.points
        free = clear_of(mirrored, clearance, occupied) & inside_floor(mirrored, world_box, spawn.jitter)
        if not free.any():
            where = f"{path}.mirror_center" if group.mirror_center is not None else f"{path}.goal_rule"
            raise GeometryError(
                where,
                f"mirroring the spawn points through ({center.real:g}, {center.imag:g}) puts every goal outside the world or in an "
                "obstacle; expected a mirror centre between the spawn regions and free space",
            )
        spawn = CandidateSet(spawn.points[free], spawn.jitter, spawn.ring_center)
    else:
        goal_sets = [region_candidates(r, f"{path}.goal.{i}", humans.radius, world_box, occupied) for i, r in enumerate(group.goal)]
        goal = merge_candidates(goal_sets, spacing=0.0)
        check_human_reachability(path, humans.radius, world_box, occupied, spawn_sets, goal_sets)
    return GroupPlacement(path, spawn, goal, ring)
