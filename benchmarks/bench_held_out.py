"""Held-out evaluation episodes: one batch (native vector env) against one env per seed, in one run.

    python benchmarks/bench_held_out.py [--scenario room_furniture] [--episodes 20] [--repeats 5]

A fixed, deterministic observation-reading policy (no network, so only the environments' cost is
compared) plays the same episodes both ways; the script checks that the outcomes are the same and
prints the median wall time of each way.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from crowdnav.evaluation.rollout import HeldOutEpisodes

MODALITIES = ["goal", "closest_obstacle", "lidar", "leog", "velocity"]


def policy(batch: dict[str, np.ndarray]) -> np.ndarray:
    """Towards the goal, away from the nearest obstacle (polar observations)."""
    goal, obstacle = batch["goal"], batch["closest_obstacle"]
    return np.stack([goal[:, 2] - 0.3 * obstacle[:, 2] / (obstacle[:, 0] + 0.5), goal[:, 1] - 0.3 * obstacle[:, 1]], axis=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="room_furniture")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    episodes = HeldOutEpisodes({"scenario": args.scenario, "modalities": MODALITIES}, seeds=range(1000, 1000 + args.episodes))
    times: dict[bool, list[float]] = {True: [], False: []}
    outcomes: dict[bool, list[str]] = {}
    for _ in range(args.repeats):
        for batched in (True, False):
            start = time.perf_counter()
            played = episodes.run(policy, batched=batched)
            times[batched].append(time.perf_counter() - start)
            outcomes[batched] = [e["outcome"] for e in played]
    assert outcomes[True] == outcomes[False], "the two ways played different episodes"
    one, batch = statistics.median(times[False]), statistics.median(times[True])
    counts = {outcome: outcomes[True].count(outcome) for outcome in sorted(set(outcomes[True]))}
    print(f"{args.scenario}, {args.episodes} episodes, all modalities; median of {args.repeats}; outcomes {counts}")
    print(f"  one env per seed  {one * 1000:8.1f} ms")
    print(f"  one batch         {batch * 1000:8.1f} ms   ({one / batch:.2f}x)")


if __name__ == "__main__":
    main()
