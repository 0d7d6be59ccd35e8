"""Scenario shapes with several robots that crowd their regions (the fuzzer's shapes of issue 36), for
tests/core/test_robot_placement_fuzz.py: robots in one door, overlapping regions, robots next to
standing groups, tight regions, circle perimeters and single points, robots of several radii.

Each shape is a function of a seeded generator returning a scenario mapping, so a case is named by
(shape, index) and is the same on every machine.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

import numpy as np

WORLD = {"min": [-7.0, -5.0], "max": [7.0, 5.0]}
WEST_DOOR = {"type": "rectangle", "min": [-6.6, -1.5], "max": [-5.6, 1.5]}
EAST_DOOR = {"type": "rectangle", "min": [5.6, -1.5], "max": [6.6, 1.5]}


def _robot(rng: np.random.Generator, start: dict[str, Any], goal: dict[str, Any], radius: float | None = None) -> dict[str, Any]:
    radius = float(rng.choice([0.2, 0.3, 0.35, 0.45])) if radius is None else radius
    return {"radius": radius, "start": start, "goal": goal, "min_start_goal_distance": float(rng.uniform(0.5, 3.0)),
            "goal_radius": 0.3}


def _rectangle(rng: np.random.Generator, near: tuple[float, float], size: tuple[float, float]) -> dict[str, Any]:
    x = float(np.clip(near[0] + rng.uniform(-0.5, 0.5), -6.8, 6.8 - size[0]))
    y = float(np.clip(near[1] + rng.uniform(-0.5, 0.5), -4.8, 4.8 - size[1]))
    return {"type": "rectangle", "min": [round(x, 3), round(y, 3)], "max": [round(x + size[0], 3), round(y + size[1], 3)]}


def _document(robots: list[dict[str, Any]], humans: dict[str, Any] | None = None) -> dict[str, Any]:
    return {"description": "a fuzzed several-robots shape", "world": copy.deepcopy(WORLD), "robots": robots,
            "humans": humans or {"count": 0}, "furniture": [{"type": "rectangle", "center": [0.0, 2.5], "size": [0.6, 0.6]}]}


def one_door(rng: np.random.Generator) -> dict[str, Any]:
    """Two to four robots all starting in the west door (1 m x 3 m), all going to the east door."""
    count = int(rng.integers(2, 5))
    radius = float(rng.choice([0.25, 0.3, 0.35])) if rng.random() < 0.5 else None
    return _document([_robot(rng, WEST_DOOR, EAST_DOOR, radius) for _ in range(count)])


def overlapping(rng: np.random.Generator) -> dict[str, Any]:
    """Robots whose start regions (and goal regions) overlap, of random sizes around one point."""
    count = int(rng.integers(2, 5))
    robots = []
    for _ in range(count):
        start = _rectangle(rng, (-5.0, -1.0), (float(rng.uniform(0.2, 2.0)), float(rng.uniform(0.2, 2.0))))
        goal = _rectangle(rng, (4.0, -1.0), (float(rng.uniform(0.2, 2.0)), float(rng.uniform(0.2, 2.0))))
        robots.append(_robot(rng, start, goal))
    return _document(robots)


def tight(rng: np.random.Generator) -> dict[str, Any]:
    """Robots sharing small rectangles, single points or lists of points, circle perimeters and discs."""
    count = int(rng.integers(2, 4))
    kind = rng.choice(["rectangle", "points", "perimeter", "disc"])
    if kind == "rectangle":
        start = _rectangle(rng, (-4.0, 0.0), (float(rng.uniform(0.3, 1.6)), float(rng.uniform(0.3, 1.6))))
    elif kind == "points":
        k = int(rng.integers(1, 5))
        start = {"type": "points", "points": [[round(-4.0 + 0.8 * i * float(rng.uniform(0.6, 1.4)), 3), 0.0] for i in range(k)]}
    else:
        start = {"type": "circle", "center": [-4.0, 0.0], "radius": round(float(rng.uniform(0.2, 1.5)), 3), "perimeter": kind == "perimeter"}
    goals = [_rectangle(rng, (3.5 + rng.uniform(-1, 1), rng.uniform(-3, 3)), (1.2, 1.2)) for _ in range(count)]
    return _document([_robot(rng, start, goal) for goal in goals])


def with_standing(rng: np.random.Generator) -> dict[str, Any]:
    """Robots in overlapping regions next to standing groups and a walking crowd spawning on their starts."""
    doc = overlapping(rng)
    goals = [robot["goal"] for robot in doc["robots"]]
    groups = [{"name": "talkers", "count": int(rng.integers(2, 5)), "behaviour": "stand",
               "spawn": [_rectangle(rng, (-6.3, -4.3), (float(rng.uniform(3.0, 6.0)), float(rng.uniform(4.0, 9.0)))), goals[-1]]},
              {"name": "walkers", "count": int(rng.integers(0, 8)), "spawn": [_rectangle(rng, (-6.3, -4.3), (4.5, 8.5))], "goal_rule": "mirror",
               "mirror_center": [0.0, 0.0]}]
    doc["humans"] = {"radius": 0.3, "groups": groups}
    return doc


SHAPES: dict[str, Callable[[np.random.Generator], dict[str, Any]]] = {
    "one_door": one_door, "overlapping": overlapping, "tight": tight, "with_standing": with_standing,
}


def case(shape: str, index: int) -> dict[str, Any]:
    """The ``index``-th scenario of ``shape`` (the same on every machine)."""
    return SHAPES[shape](np.random.default_rng([36, list(SHAPES).index(shape), index]))
