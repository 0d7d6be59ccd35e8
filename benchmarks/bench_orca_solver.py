"""crowdnav's ORCA solver against an earlier version of it, interleaved in one process: microseconds per step.

    git show COMMIT:crowdnav/sim/orca_solver.py > /tmp/orca_before.py   (crowdnav/orca.py in commits before sim/)
    python benchmarks/bench_orca_solver.py /tmp/orca_before.py [--counts 10 100 1000] [--repeats 9]

The earlier file's ``OrcaSolver`` serves one simulator, the installed one another, on the circle
crossing of ``bench_orca_navground.py`` (same seeds); they alternate repeat by repeat (which one
goes first alternates too). Prints microseconds per ``Simulator.step`` and per ORCA ``commands``
call (median over the repeats) and the ratio before / now (above 1: now is faster). Needs pyrvo.
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import sys
from pathlib import Path

import crowdnav.crowd.orca as crowd_orca
import crowdnav.sim.orca_solver
from crowdnav import Simulator

sys.path.insert(0, str(Path(__file__).parent))
from bench_orca_navground import overrides, time_crowdnav  # noqa: E402

STEPS = {10: 100, 100: 100}
"""Timed steps per repeat by crowd size (30 beyond)."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("before", type=Path, help="an earlier crowdnav/sim/orca_solver.py")
    parser.add_argument("--counts", type=int, nargs="+", default=[10, 100, 1000])
    parser.add_argument("--repeats", type=int, default=9)
    args = parser.parse_args()
    spec = importlib.util.spec_from_file_location("orca_before", args.before)
    assert spec is not None and spec.loader is not None, f"cannot load {args.before}"
    before = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(before)
    print(f"# circle crossing, {args.repeats} repeats (interleaved); microseconds, median")
    print(f"{'agents':>6}  {'step before':>11} {'step now':>9} {'ratio':>6}  {'ORCA before':>11} {'ORCA now':>9} {'ratio':>6}")
    for n in args.counts:
        simulators = {}
        for name, module in (("before", before), ("now", crowdnav.sim.orca_solver)):
            crowd_orca.OrcaSolver = module.OrcaSolver  # type: ignore[attr-defined]  # the solver the next reset builds
            simulators[name] = simulator = Simulator("circle_crossing", overrides=overrides(n))
            simulator.reset(seed=0)
        crowd_orca.OrcaSolver = crowdnav.sim.orca_solver.OrcaSolver  # type: ignore[attr-defined]
        steps = STEPS.get(n, 30)
        step: dict[str, list[float]] = {name: [] for name in simulators}
        orca: dict[str, list[float]] = {name: [] for name in simulators}
        for repeat in range(args.repeats):
            order = list(simulators.items())
            for name, simulator in order if repeat % 2 else order[::-1]:
                total, part = time_crowdnav(simulator, steps, repeat)
                step[name].append(total / steps * 1e6)
                orca[name].append(part / steps * 1e6)
        s = {name: statistics.median(times) for name, times in step.items()}
        o = {name: statistics.median(times) for name, times in orca.items()}
        print(f"{n:>6}  {s['before']:>11,.1f} {s['now']:>9,.1f} {s['before'] / s['now']:>6.2f}  "
              f"{o['before']:>11,.1f} {o['now']:>9,.1f} {o['before'] / o['now']:>6.2f}", flush=True)


if __name__ == "__main__":
    main()
