"""Load time of the most expensive geometry the scenario loader accepts (docs/scenarios.md#geometry-limits).

Each family grows until the complexity checks of :mod:`crowdnav.worlds.obstacles` refuse it; the last
accepted size is the worst case a file from a stranger can make every env and worker pay.

    python benchmarks/bench_geometry_load.py
"""

from __future__ import annotations

import time

import numpy as np

from crowdnav import ScenarioError
from crowdnav.worlds.compiled import load_world

BASE = {"description": "geometry load benchmark", "robot": {"max_speed": 1.0}, "humans": {"count": 0}}
CORNERS = {"start": {"type": "points", "points": [[0.5, 0.5]]}, "goal": {"type": "points", "points": [[99.5, 9.5]]}}


def zigzag_floor(n: int) -> dict:
    """A floor whose lower edge is a zigzag of n - 2 teeth 1 m tall (buffering it costs most per vertex)."""
    xs = np.linspace(1, 99, n - 2)
    ys = np.where(np.arange(n - 2) % 2 == 0, 1.0, 2.0)
    points = [[float(x), float(y)] for x, y in zip(xs, ys, strict=True)] + [[99.0, 9.0], [1.0, 9.0]]
    return {**BASE, "world": {"min": [0, 0], "max": [100, 10], "points": points},
            "robot": {**BASE["robot"], "start": {"type": "rectangle", "min": [5, 5], "max": [6, 6]},
                      "goal": {"type": "rectangle", "min": [90, 5], "max": [91, 6]}}}


def crossing_walls(n: int) -> dict:
    """n six-point walls scattered so that they cross each other (their union costs most per wall)."""
    rng = np.random.default_rng(0)
    walls = []
    for _ in range(n):
        x0, y0 = rng.uniform(2, 98, size=2)
        points = np.clip(np.column_stack([x0 + rng.uniform(-15, 15, 6), y0 + rng.uniform(-15, 15, 6)]), 1, 99)
        walls.append({"points": points.tolist(), "thickness": 0.1})
    return {**BASE, "world": {"min": [0, 0], "max": [100, 100]}, "walls": walls,
            "robot": {**BASE["robot"], "start": CORNERS["start"], "goal": {"type": "points", "points": [[99.5, 99.5]]}}}


def overlapping_discs(n: int) -> dict:
    rng = np.random.default_rng(0)
    furniture = [{"type": "circle", "center": rng.uniform(2, 98, size=2).tolist(), "radius": float(rng.uniform(0.1, 1.0))} for _ in range(n)]
    return {**BASE, "world": {"min": [0, 0], "max": [100, 100]}, "furniture": furniture,
            "robot": {**BASE["robot"], "start": CORNERS["start"], "goal": {"type": "points", "points": [[99.5, 99.5]]}}}


def main() -> None:
    for name, family, sizes in (("zigzag floor", zigzag_floor, range(200, 6000, 100)),
                                ("crossing walls", crossing_walls, range(10, 600, 10)),
                                ("overlapping discs", overlapping_discs, range(100, 2100, 100))):
        worst = None
        for n in sizes:
            started = time.perf_counter()
            try:
                load_world(family(n))
            except ScenarioError as error:
                refused = time.perf_counter() - started
                print(f"{name}: {n} refused in {refused:.2f} s ({str(error).split(': ', 2)[-1][:90]}...)")
                break
            worst = (n, time.perf_counter() - started)
        if worst:
            print(f"{name}: largest accepted {worst[0]} loads in {worst[1]:.2f} s")
        for n in (10_000, 2_000):  # the sizes of issue 31's reports, refused up front
            started = time.perf_counter()
            try:
                load_world(family(n))
                print(f"{name}: {n} accepted in {time.perf_counter() - started:.2f} s")
            except ScenarioError:
                print(f"{name}: {n} refused in {time.perf_counter() - started:.2f} s")


if __name__ == "__main__":
    main()
