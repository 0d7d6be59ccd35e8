"""Simulator throughput: steps/s for crowds of 5-100 humans in the furniture room, resets included.

    python benchmarks/bench_sim.py [--steps 20000] [--repeats 5] [--counts 5 10 20 50 100]

The robot takes uniformly random actions (pre-drawn, so the policy costs nothing); an episode
that ends (collision, goal, time limit) is reset inside the timed loop. Reports the median over
repeats, plus the median reset time. No sensors: see bench_env.py for the full environment.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time

import numpy as np

from crowdnav import Simulator


def steps_per_second(sim: Simulator, steps: int, seed: int) -> tuple[float, int]:
    actions = np.random.default_rng(seed).uniform(-1, 1, size=(steps, 2))
    sim.reset(seed=seed)
    resets = 0
    start = time.perf_counter()
    for action in actions:
        events = sim.step(action)
        if events.terminated or events.truncated:
            sim.reset()
            resets += 1
    return steps / (time.perf_counter() - start), resets


def reset_seconds(sim: Simulator, count: int) -> float:
    start = time.perf_counter()
    for seed in range(count):
        sim.reset(seed=seed)
    return (time.perf_counter() - start) / count


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", default="room_furniture")
    parser.add_argument("--steps", type=int, default=20000, help="timed steps per repeat")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--counts", type=int, nargs="+", default=[5, 10, 20, 50, 100])
    args = parser.parse_args()
    print(f"# {args.scenario}, {args.steps} steps x {args.repeats} repeats, Python {platform.python_version()}, numpy {np.__version__}")
    print(f"{'humans':>6} {'steps/s (median)':>17} {'min':>9} {'max':>9} {'resets/repeat':>14} {'reset ms (median)':>18}")
    for count in args.counts:
        sim = Simulator(args.scenario, overrides={"humans.count": count})
        rates, resets = zip(*(steps_per_second(sim, args.steps, seed) for seed in range(args.repeats)), strict=False)
        reset_ms = statistics.median(reset_seconds(sim, 200) for _ in range(args.repeats)) * 1e3
        print(
            f"{count:>6} {statistics.median(rates):>17,.0f} {min(rates):>9,.0f} {max(rates):>9,.0f} "
            f"{statistics.median(resets):>14.0f} {reset_ms:>18.3f}"
        )


if __name__ == "__main__":
    main()
