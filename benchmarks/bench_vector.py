"""Env-steps per second of the native vector env against Gymnasium's SyncVectorEnv, in one run.

    python benchmarks/bench_vector.py [--scenario room_furniture] [--humans 10] [--batch 64] [--steps 200] [--repeats 3]

Four ways to step the same B worlds (all modalities unless ``--modalities``), random actions:

* ``single``: one CrowdNavEnv, B x steps steps (the per-world cost without batching);
* ``sync``: ``gymnasium.make_vec(..., vectorization_mode="sync")``, B single envs in a loop;
* ``native``: ``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")``;
* ``kernels``: the native env's batched simulator step and batched sensors alone, no rewards,
  infos, autoreset bookkeeping or copies (the floor the env's own work adds to).

Printed: median env-steps/s over the repeats and the ratios native / sync and native / kernels.

A several-robot scenario (``--scenario robots_crossing_hall --batch 32 --modalities goal lidar``) runs
the same cases: its native worlds are a group of single simulators (:mod:`crowdnav.envs.vector_team`),
and ``kernels`` is then their step and observations without the env's rewards, infos and copies.
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numpy as np

import crowdnav  # noqa: F401  (registers the ids)
from crowdnav.envs.registration import env_id

ALL = ["goal", "closest_obstacle", "lidar", "leog", "velocity"]


def _options(args: argparse.Namespace) -> dict:
    return {"modalities": args.modalities, "overrides": {"humans.count": args.humans}}


def single(args: argparse.Namespace) -> float:
    env = gym.make(env_id(args.scenario), **_options(args)).unwrapped
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps * args.batch, 2))
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return len(actions) / (time.perf_counter() - start)


def vector(args: argparse.Namespace, mode: str) -> float:
    env = gym.make_vec(env_id(args.scenario), num_envs=args.batch, vectorization_mode=mode, **_options(args))
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps, args.batch, 2)).astype(np.float32)
    start = time.perf_counter()
    for action in actions:
        env.step(action)
    return args.steps * args.batch / (time.perf_counter() - start)


def kernels(args: argparse.Namespace) -> float:
    env = gym.make_vec(env_id(args.scenario), num_envs=args.batch, vectorization_mode="vector_entry_point", **_options(args)).unwrapped
    env.reset(seed=0)
    batch = env.batch
    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps, args.batch, 2))
    start = time.perf_counter()
    for action in actions:
        result = batch.step(action)
        done = np.flatnonzero(result.terminated | result.truncated)
        if len(done):
            batch.reset(done, [None] * len(done))
        env._observe_all()  # the batched sensors, in the env's chunks of worlds
    return args.steps * args.batch / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="room_furniture")
    parser.add_argument("--humans", type=int, default=10)
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--steps", type=int, default=200, help="batch steps per measurement (single: batch x steps env steps)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--modalities", nargs="+", default=ALL)
    parser.add_argument("--cases", nargs="+", default=["single", "sync", "native", "kernels"], choices=["single", "sync", "native", "kernels"])
    args = parser.parse_args()
    run = {"single": lambda: single(args), "sync": lambda: vector(args, "sync"),
           "native": lambda: vector(args, "vector_entry_point"), "kernels": lambda: kernels(args)}
    results: dict[str, list[float]] = {case: [] for case in args.cases}
    for _ in range(args.repeats):  # interleaved, so every case sees the same machine load
        for case in args.cases:
            results[case].append(run[case]())
    medians = {case: statistics.median(values) for case, values in results.items()}
    print(f"{args.scenario}, {args.humans} humans, batch {args.batch}, modalities {' '.join(args.modalities)}; "
          f"median of {args.repeats} (env-steps/s)")
    for case, value in medians.items():
        print(f"  {case:8s} {value:10,.0f}")
    if "native" in medians:
        for other in ("sync", "single", "kernels"):
            if other in medians:
                print(f"  native / {other}: {medians['native'] / medians[other]:.2f}x")


if __name__ == "__main__":
    main()
