"""Time each modality's batched ``observe_batch`` over K worlds against K calls of ``observe``.

K simulators of one scenario are run a random number of steps with a random robot, stacked
into one :class:`~crowdnav.batch.state.BatchState`, and each modality observes them both ways
(the outputs are checked to be identical first). Figures are the median over ``--repeats`` of
the microseconds per world.

    .venv/bin/python benchmarks/bench_sensors_batch.py
    .venv/bin/python benchmarks/bench_sensors_batch.py --scenario cafe --humans 8 --worlds 256
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from crowdnav import Simulator
from crowdnav.batch.state import BatchState
from crowdnav.sensors import build_modalities

ALL = ["goal", "velocity", "closest_obstacle", "lidar", "leog"]


def make_worlds(scenario: str, humans: int, worlds: int, seed: int) -> list[Simulator]:
    """``worlds`` simulators with ``humans`` humans each, every one reset and stepped 0-30 random actions."""
    world = Simulator(scenario, overrides={"humans.count": humans}).world
    rng = np.random.default_rng(seed)
    sims = []
    for k in range(worlds):
        sim = Simulator(world)
        sim.reset(seed=seed + k)
        for _ in range(int(rng.integers(0, 31))):
            events = sim.step(rng.uniform(-1.0, 1.0, 2))
            if events.terminated or events.truncated:
                break
        sims.append(sim)
    return sims


def median_seconds(function, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="room_furniture")
    parser.add_argument("--humans", type=int, default=10)
    parser.add_argument("--worlds", type=int, default=64)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    sims = make_worlds(args.scenario, args.humans, args.worlds, args.seed)
    state = BatchState.stack(sims)
    world = sims[0].world
    modalities = build_modalities(ALL, world, world.scenario.sensors)
    worlds = len(sims)
    print(f"{args.scenario}, {args.humans} humans, K = {worlds} worlds, median of {args.repeats} repeats")
    print(f"{'modality':<18}{'observe x K (us/world)':>24}{'observe_batch (us/world)':>26}{'speed-up':>10}")
    for name, modality in modalities.items():
        batch = modality.observe_batch(state)  # warm the caches; and check the rows once
        assert all(batch[k].tobytes() == modality.observe(sim).tobytes() for k, sim in enumerate(sims)), name
        single = median_seconds(lambda modality=modality: [modality.observe(sim) for sim in sims], args.repeats)
        batched = median_seconds(lambda modality=modality: modality.observe_batch(state), args.repeats)
        print(f"{name:<18}{1e6 * single / worlds:>24.2f}{1e6 * batched / worlds:>26.2f}{single / batched:>9.1f}x")
    stacking = median_seconds(lambda: BatchState.stack(sims), args.repeats)
    print(f"(BatchState.stack of the {worlds} simulators, not part of the above: {1e6 * stacking / worlds:.2f} us/world)")


if __name__ == "__main__":
    main()
