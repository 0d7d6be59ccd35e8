"""How the simulator's cost grows with the crowd: 5 to 1,000 humans, all pairs against the neighbour grid.

    python benchmarks/bench_crowd.py [--counts 5 10 20 50 100 200 500 1000] [--seconds 2] [--repeats 3]
                                     [--plot docs/figures/crowd_scaling.png]

The world is a 60 m x 60 m hall with 16 pillars, humans walking between random goals anywhere in
it (density 0.28 per square metre at 1,000), the robot driving a fixed action. Each measurement
runs ``--seconds`` of steps after a reset (episodes are long here, so no reset falls inside) and
the median over ``--repeats`` seeds is reported, in both geometries: all pairs (the default
below ``Simulator.grid_from`` humans) and the neighbour grid (the default from it on). With
``--plot``, steps/s against crowd size on log-log axes (needs matplotlib: the ``train`` extra).
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
from pathlib import Path

import numpy as np

from crowdnav import Simulator
from crowdnav.files import replacing

HALL = {
    "description": "a 60 m x 60 m hall with 16 pillars",
    "world": {"min": [-30, -30], "max": [30, 30]},
    "furniture": [{"type": "rectangle", "center": [x, y], "size": [0.8, 0.8]} for x in (-18, -6, 6, 18) for y in (-18, -6, 6, 18)],
    "robot": {"start": {"type": "rectangle", "min": [-29, -29], "max": [-27, -27]},
              "goal": {"type": "rectangle", "min": [27, 27], "max": [29, 29]}},
    "humans": {"count": 10, "spawn": [{"type": "rectangle", "min": [-29.5, -29.5], "max": [29.5, 29.5]}],
               "goal": [{"type": "rectangle", "min": [-29, -29], "max": [29, 29]}]},
    "max_steps": 100_000,
}


def steps_per_second(count: int, grid: bool, seed: int, seconds: float) -> float:
    sim = Simulator(HALL, overrides={"humans.count": count})
    sim.grid_from = 0 if grid else 10**9
    sim.reset(seed=seed)
    action = np.array([0.3, 0.1])
    for _ in range(3):
        sim.step(action)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for _ in range(10):
            sim.step(action)
        steps += 10
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--counts", type=int, nargs="+", default=[5, 10, 20, 50, 100, 200, 500, 1000])
    parser.add_argument("--seconds", type=float, default=2.0, help="timed seconds per measurement")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--plot", default=None, help="write a log-log plot of steps/s against crowd size here")
    args = parser.parse_args()
    print(f"# 60 m x 60 m hall, 16 pillars; {args.seconds:g} s x {args.repeats} seeds per point; "
          f"Python {platform.python_version()}, numpy {np.__version__}; grid from {Simulator.grid_from} humans by default")
    print(f"{'humans':>6} {'all pairs':>12} {'grid':>12}  steps/s (median)")
    rows = []
    for count in args.counts:
        rates = [statistics.median(steps_per_second(count, grid, seed, args.seconds) for seed in range(args.repeats))
                 for grid in (False, True)]
        rows.append((count, *rates))
        print(f"{count:>6} {rates[0]:>12,.0f} {rates[1]:>12,.0f}", flush=True)
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        counts, dense, grid = zip(*rows, strict=True)
        figure, axes = plt.subplots(figsize=(5.5, 3.6), dpi=110)
        axes.loglog(counts, dense, "o-", label="all pairs")
        axes.loglog(counts, grid, "s--", label="neighbour grid")
        axes.axvline(Simulator.grid_from, color="grey", lw=0.8, ls=":")
        axes.text(Simulator.grid_from * 1.05, max(max(dense), max(grid)) * 0.6, "default switch", fontsize=8, color="grey")
        axes.set(xlabel="humans", ylabel="simulator steps/s", title="Simulator cost against crowd size (60 m hall)")
        axes.grid(True, which="both", alpha=0.3)
        axes.legend()
        figure.tight_layout()
        with replacing(Path(args.plot), suffix=Path(args.plot).suffix) as temporary:  # the suffix tells matplotlib the format
            figure.savefig(temporary)
        print(f"wrote {args.plot}")


if __name__ == "__main__":
    main()
