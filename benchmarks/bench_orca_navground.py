"""crowdnav's ORCA crowd against navground's (its ORCA is C++), interleaved in one process: simulator steps per second.

    python benchmarks/bench_orca_navground.py [--counts 10 100 1000] [--repeats 15] [--steps 30] [--worlds 8]

Needs pyrvo and navground (``pip install navground``: a bench-only dependency, not one of crowdnav's).
The scene for ``n`` agents: humans of radius 0.3 m on a circle (radius ``max(4, 0.8 n / 2 pi)`` m,
random places on its perimeter, drawn by crowdnav's placement), each crossing to the antipode at
its preferred speed (0.8-1.2 m/s) and stopping there; no obstacles; 0.2 s time step; ORCA's
parameters crowdnav's defaults (time horizon 5 s, 2 s for obstacles, 10 neighbours within 10 m,
0.01 m safety margin), given to navground's ``ORCABehavior`` (its ``horizon`` 10 m) and a
``BoundedStateEstimation`` of 10 m. navground's agents start from crowdnav's reset state (same positions, goals, speeds), so the
two simulators play the same scene. crowdnav's robot stands in a corner, far from the crowd, which
does not see it (``see_robot`` off).

One repeat times, in turn, ``--steps`` steps of each contender from the same fresh episode (seed =
repeat; 30 steps by default, while every agent still walks: at 10 agents the fastest arrives after
34 steps, and navground skips the ORCA of an agent whose task is done, which crowdnav does not):
``Simulator.step`` (the whole step: robot, integration, contacts, goal rules, with the ORCA
commands), its ORCA commands alone (the time spent in the crowd model's ``commands``, inside those
steps), ``BatchSimulator.step`` over ``--worlds`` worlds (world-steps per second; the batched
simulator takes crowds under 200 humans), and navground's ``World.update`` (the whole step: state
estimation, ORCA, kinematics, collisions, tasks). Building a world and resetting are not timed.
Medians over the repeats; the ratios are crowdnav / navground (above 1: crowdnav is faster).
"""

from __future__ import annotations

import argparse
import math
import platform
import statistics
import time
from importlib.metadata import version
from typing import Any

import numpy as np

from crowdnav import Simulator
from crowdnav.batch.simulator import BatchSimulator
from crowdnav.worlds.compiled import load_world

RADIUS = 0.3
DT = 0.2
SPACING = 0.8
"""Metres of the circle's perimeter per agent (on average)."""


def overrides(n: int) -> dict:
    """The circle-crossing scene for ``n`` humans: a circle large enough for them, the robot out of their way."""
    ring = max(4.0, SPACING * n / (2 * math.pi))
    corner = ring + 2.5
    return {"humans.count": n, "humans.model": "orca", "humans.radius": RADIUS, "humans.preferred_speed": [0.8, 1.2],
            "humans.spawn": [{"type": "circle", "center": [0, 0], "radius": ring, "perimeter": True}],
            "world.min": [-corner - 1, -corner - 1], "world.max": [corner + 1, corner + 1], "time_step": DT,
            "robot.start": {"type": "points", "points": [[corner, corner]]},
            "robot.goal": {"type": "points", "points": [[corner - 1.0, corner]]}, "max_steps": 100_000}


def navground_world(simulator: Simulator) -> Any:
    """navground's world with the humans of ``simulator``'s current state (positions, goals, speeds) and its ORCA parameters."""
    from navground import core
    from navground import sim as nav

    params, tolerance = simulator.scenario.humans.orca, simulator.scenario.humans.social_force.goal_tolerance
    world = nav.World()
    for position, goal, speed, top in zip(simulator.human_positions, simulator.human_goals, simulator.human_preferred_speed,
                                          simulator.human_max_speed, strict=True):
        behavior = core.behaviors.ORCABehavior()
        behavior.optimal_speed = float(speed)
        behavior.horizon = params.neighbour_distance  # navground's default 5 m would see fewer neighbours
        behavior.time_horizon = params.time_horizon
        behavior.static_time_horizon = params.time_horizon_obstacles
        behavior.max_number_of_neighbors = params.max_neighbours
        behavior.safety_margin = params.safety_margin
        agent = nav.Agent(radius=RADIUS, behavior=behavior, kinematics=core.kinematics.OmnidirectionalKinematics(float(top)),
                          task=nav.tasks.WaypointsTask([np.array([goal.real, goal.imag])], loop=False, tolerance=tolerance),
                          state_estimations=[nav.state_estimations.BoundedStateEstimation(range=params.neighbour_distance)])
        agent.position = np.array([position.real, position.imag])
        world.add_agent(agent)
    return world


def time_crowdnav(simulator: Simulator, steps: int, seed: int) -> tuple[float, float]:
    """Seconds for ``steps`` simulator steps from a fresh episode, and the part of them spent in the ORCA model's commands."""
    simulator.reset(seed=seed)
    model = simulator.crowd.models["orca"]
    commands, spent = model.commands, [0.0]

    def timed(view):  # noqa: ANN001, ANN202  (the model's own signature)
        start = time.perf_counter()
        result = commands(view)
        spent[0] += time.perf_counter() - start
        return result

    model.commands = timed  # type: ignore[method-assign]
    action = np.zeros(2)
    try:
        start = time.perf_counter()
        for _ in range(steps):
            simulator.step(action)
        total = time.perf_counter() - start
    finally:
        del model.commands
    return total, spent[0]


def time_batch(batch: BatchSimulator, steps: int, seed: int) -> float:
    """Seconds for ``steps`` batched steps of all worlds from fresh episodes (seeds ``seed``, ``seed + 1``, ...)."""
    worlds = batch.num_worlds
    batch.reset(range(worlds), [seed * worlds + k for k in range(worlds)])
    actions = np.zeros((worlds, 2))
    start = time.perf_counter()
    for _ in range(steps):
        batch.step(actions)
    return time.perf_counter() - start


def time_navground(world: Any, steps: int) -> float:
    update = world.update
    start = time.perf_counter()
    for _ in range(steps):
        update(DT)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--counts", type=int, nargs="+", default=[10, 100, 1000])
    parser.add_argument("--steps", type=int, default=30, help="timed steps per contender and repeat (30: everyone still walks)")
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--worlds", type=int, default=8, help="worlds of the batched simulator")
    args = parser.parse_args()
    print(f"# circle crossing, {args.steps} steps x {args.repeats} repeats (interleaved), Python {platform.python_version()}, "
          f"numpy {np.__version__}, pyrvo {version('pyrvo')}, navground {version('navground')}; steps per second, median")
    print(f"{'agents':>6}  {'crowdnav step':>13} {'ORCA part':>9}  {'batch x' + str(args.worlds):>10}  {'navground':>9}  "
          f"{'step / nav':>10} {'batch / nav':>11}")
    for n in args.counts:
        world = load_world("circle_crossing", overrides(n))
        simulator = Simulator(world)
        batch = BatchSimulator(world, args.worlds) if n < simulator.grid_from else None
        single, orca, batched, theirs = [], [], [], []
        for seed in range(args.repeats):
            total, part = time_crowdnav(simulator, args.steps, seed)
            single.append(total)
            orca.append(part)
            if batch is not None:
                batched.append(time_batch(batch, args.steps, seed) / args.worlds)
            simulator.reset(seed=seed)  # the same episode's start, for navground
            theirs.append(time_navground(navground_world(simulator), args.steps))
        rate = {name: args.steps / statistics.median(times) for name, times in
                (("step", single), ("orca", orca), ("batch", batched or [math.inf]), ("nav", theirs))}
        batch_rate = f"{rate['batch']:>10,.0f}" if batch is not None else f"{'-':>10}"
        batch_ratio = f"{rate['batch'] / rate['nav']:>11.2f}" if batch is not None else f"{'-':>11}"
        print(f"{n:>6}  {rate['step']:>13,.0f} {rate['orca']:>9,.0f}  {batch_rate}  {rate['nav']:>9,.0f}  "
              f"{rate['step'] / rate['nav']:>10.2f} {batch_ratio}", flush=True)


if __name__ == "__main__":
    main()
