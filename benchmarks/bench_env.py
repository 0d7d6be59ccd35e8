"""Gymnasium env throughput: env steps/s with all modalities, resets included, and where the time goes.

    python benchmarks/bench_env.py [--scenario room_furniture] [--steps 10000] [--repeats 5] [--counts 5 10 20 50]
    python benchmarks/bench_env.py --floor [--scenarios room_furniture open_space] [--steps 3000] [--repeats 5] [--clock cpu]

One CrowdNavEnv (no wrappers, no vectorization) with every modality on (goal, closest obstacle,
360-beam LIDAR, 60x60 LEOG, velocity); the robot takes uniformly random actions (pre-drawn, so
the policy costs nothing); an episode that ends is reset inside the timed loop. Reports the
median over repeats.

The breakdown replays the same action sequence on the env's own simulator and times each part
separately, per env step: the simulator (step and resets), each sensor's observe(), the env's
action check + reward + info, and the rest (env total minus all those: Python call layers, the
observation dict, the observation each reset returns, which the breakdown does not make, and timing
noise).

``--floor``: the env side by side with its numpy floor (:mod:`bench_env_floor`): the same episodes'
work done directly on the env's own simulator, sensors and reward, without the env layer.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time

import numpy as np

from crowdnav.envs import CrowdNavEnv
from crowdnav.envs.core import checked_robot_action, step_info

ALL_MODALITIES = ["goal", "closest_obstacle", "lidar", "leog", "velocity", "humans"]


def env_seconds_per_step(env: CrowdNavEnv, actions: np.ndarray, seed: int) -> float:
    env.reset(seed=seed)
    step, reset = env.step, env.reset
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = step(action)
        if terminated or truncated:
            reset()
    return (time.perf_counter() - start) / len(actions)


def part_seconds_per_step(env: CrowdNavEnv, actions: np.ndarray, seed: int) -> dict[str, float]:
    """Same episode as env_seconds_per_step, each part timed on its own."""
    core = env.core
    sim, sensors, reward = core.simulator, core.modalities, core.reward
    totals = dict.fromkeys(["simulator", *sensors, "env: action+reward+info"], 0.0)
    clock = time.perf_counter
    sim.reset(seed=seed)
    reward.reset(sim)
    for action in actions:
        start = clock()
        checked = checked_robot_action(action)
        totals["env: action+reward+info"] -= start - clock()
        start = clock()
        events = sim.step(checked)
        totals["simulator"] += clock() - start
        for key, modality in sensors.items():
            start = clock()
            modality.observe(sim)
            totals[key] += clock() - start
        start = clock()
        step_info(events, reward(sim, events)[1])
        totals["env: action+reward+info"] += clock() - start
        if events.terminated or events.truncated:
            start = clock()
            sim.reset()
            reward.reset(sim)
            totals["simulator"] += clock() - start
    return {part: seconds / len(actions) for part, seconds in totals.items()}


def main() -> None:
    if "--floor" in sys.argv:  # the side-by-side with the floor has its own options
        from bench_env_floor import main as floor_main

        floor_main()
        return
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", default="room_furniture")
    parser.add_argument("--steps", type=int, default=10000, help="timed env steps per repeat")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--counts", type=int, nargs="+", default=[5, 10, 20, 50])
    args = parser.parse_args()
    print("$ python " + " ".join(sys.argv))
    print(
        f"# {args.scenario}, modalities {','.join(ALL_MODALITIES)} (LIDAR 360 beams, LEOG 60x60), "
        f"{args.steps} steps x {args.repeats} repeats, Python {platform.python_version()}, numpy {np.__version__}"
    )
    rows = []
    for count in args.counts:
        env = CrowdNavEnv(
            args.scenario,
            modalities=ALL_MODALITIES,
            sensors={"lidar": {"beams": 360}, "leog": {"size": 6.0, "resolution": 0.1}},
            overrides={"humans.count": count},
        )
        actions = [np.random.default_rng(seed).uniform(-1, 1, size=(args.steps, 2)).astype(np.float32) for seed in range(args.repeats)]
        per_step, parts = [], []
        for seed in range(args.repeats):  # interleaved, so both see the same machine load
            per_step.append(env_seconds_per_step(env, actions[seed], seed))
            parts.append(part_seconds_per_step(env, actions[seed], seed))
        env_us = statistics.median(per_step) * 1e6
        part_us = {part: statistics.median(p[part] for p in parts) * 1e6 for part in parts[0]}
        part_us["env: rest"] = env_us - sum(part_us.values())  # call layers, observation dict, timer noise
        rows.append((count, 1e6 / env_us, 1e6 / (max(per_step) * 1e6), 1e6 / (min(per_step) * 1e6), env_us, part_us))

    print(f"\n{'humans':>6} {'env steps/s (median)':>21} {'min':>8} {'max':>8} {'us/step':>8}")
    for count, rate, low, high, env_us, _ in rows:
        print(f"{count:>6} {rate:>21,.0f} {low:>8,.0f} {high:>8,.0f} {env_us:>8.1f}")
    parts = list(rows[0][5])
    print("\nwhere an env step's time goes (us per step, median; share of the env step):")
    print(f"{'humans':>6} " + " ".join(f"{part:>22}" for part in parts))
    for count, _, _, _, env_us, part_us in rows:
        cells = " ".join(f"{part_us[p]:>14.1f} ({100 * part_us[p] / env_us:>4.1f}%)" for p in parts)
        print(f"{count:>6} {cells}")


if __name__ == "__main__":
    main()
