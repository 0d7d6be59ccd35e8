"""Env-steps per second of the native vector env against Gymnasium's SyncVectorEnv, in one run.

    python benchmarks/bench_vector.py [--scenario room_furniture] [--humans 10] [--batch 64] [--steps 200] [--repeats 3]

Four ways to step the same B worlds (all modalities unless ``--modalities``), random actions:

* ``single``: one CrowdNavEnv, B x steps steps (the per-world cost without batching);
* ``sync``: ``gymnasium.make_vec(..., vectorization_mode="sync")``, B single envs in a loop;
* ``native``: ``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")``;
* ``kernels``: the native env's batched simulator step and batched sensors alone, no rewards,
  infos, autoreset bookkeeping or copies (the floor the env's own work adds to);
* ``sb3_single`` / ``sb3_native``: the two ways ``crowdnav train`` could collect from B worlds for SB3:
  ``DummyVecEnv`` of B ``make_env`` stacks (CrowdNavEnv, observation normalisation, episode seeds,
  Monitor) against ``make_vec_env`` (the native env through ``CrowdNavSB3VecEnv``), with the training
  config's options (``--modalities``, ``--humans``). Neither records its actions any more (the
  ``ActionLog`` that training wrapped them in until its checkpoints stored world states cost 4-7 us
  per step of all worlds).

Printed: median env-steps/s over the repeats and the ratios native / sync, native / single, native /
kernels and sb3_native / sb3_single. ``--clock cpu`` times with the process's CPU time instead of the
wall clock: on a machine shared with other jobs the wall clock also counts the time the process waits
for a core. One world (``--batch 1``) is a size like any other: the native env then holds it as a
single env (``crowdnav.envs.vector.env.stacks``), and ``kernels`` does not apply.

A several-robot scenario (``--scenario robots_crossing_hall --batch 32 --modalities goal lidar``) runs
the same cases: its native worlds are stacked too (:mod:`crowdnav.envs.engines.stacked_team`: the other
robots of every world in the batched simulator, their scripted policy batched), and ``kernels`` is then
the batched simulator's step (the other robots standing still: their policy is the engine's) and the
observations. Measured 2026-12-07 (2 shared cores, ``--clock cpu --cases single native --repeats 1``, five
alternating processes of the code before and after): 32 worlds from 2,252 env-steps/s (one single env
per world) to 8,828 (3.92x; the single env 2,109), docs/environments.md#several-robots-in-the-native-vector-env.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np

import crowdnav  # noqa: F401  (registers the ids)
from crowdnav.envs.registration import env_id

ALL = ["goal", "closest_obstacle", "lidar", "leog", "velocity"]


def _options(args: argparse.Namespace) -> dict:
    return {"modalities": args.modalities, "overrides": {"humans.count": args.humans}}


CLOCK: Callable[[], float] = time.perf_counter


def single(args: argparse.Namespace) -> float:
    env = gym.make(env_id(args.scenario), **_options(args)).unwrapped
    env.reset(seed=0)
    # float32 like the other cases' (the action space's dtype): both then pay the same conversion
    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps * args.batch, 2)).astype(np.float32)
    start = CLOCK()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return len(actions) / (CLOCK() - start)


def vector(args: argparse.Namespace, mode: str) -> float:
    env = gym.make_vec(env_id(args.scenario), num_envs=args.batch, vectorization_mode=mode, **_options(args))
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps, args.batch, 2)).astype(np.float32)
    start = CLOCK()
    for action in actions:
        env.step(action)
    return args.steps * args.batch / (CLOCK() - start)


def kernels(args: argparse.Namespace) -> float:
    env = gym.make_vec(env_id(args.scenario), num_envs=args.batch, vectorization_mode="vector_entry_point", **_options(args)).unwrapped
    env.reset(seed=0)
    batch = env.engine  # the worlds behind the engine protocol (stacked: StackedWorlds)
    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps, args.batch, 2))
    start = CLOCK()
    for action in actions:
        result = batch.step(action)
        done = np.flatnonzero(result.terminated | result.truncated)
        if len(done):
            batch.reset(done, [None] * len(done))
        env._observe_all()  # the batched sensors, in the env's chunks of worlds
    return args.steps * args.batch / (CLOCK() - start)


def sb3(args: argparse.Namespace, native: bool) -> Callable[[], float]:
    """The SB3 collection stack ``crowdnav train`` builds for ``native`` (or not), made once; returns its timing run."""
    from functools import partial

    from crowdnav.agents.sb3.factory import make_env, make_vec_env
    from crowdnav.agents.training.config import config_from_mapping
    from stable_baselines3.common.vec_env import DummyVecEnv

    config = config_from_mapping({"scenario": args.scenario, "modalities": args.modalities, "algo": "ppo", "seed": 0,
                                  "out": tempfile.mkdtemp(), "overrides": {"humans.count": args.humans}, "num_envs": args.batch})
    env = make_vec_env(config) if native else DummyVecEnv([partial(make_env, config)] * args.batch)
    env.reset()
    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps, args.batch, 2)).astype(np.float32)

    def run() -> float:
        start = CLOCK()
        for action in actions:
            env.step(action)
        return args.steps * args.batch / (CLOCK() - start)
    return run


CASES = ["single", "sync", "native", "kernels", "sb3_single", "sb3_native"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="room_furniture")
    parser.add_argument("--humans", type=int, default=10)
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--steps", type=int, default=200, help="batch steps per measurement (single: batch x steps env steps)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--modalities", nargs="+", default=ALL)
    parser.add_argument("--cases", nargs="+", default=CASES[:4], choices=CASES)
    parser.add_argument("--clock", choices=["wall", "cpu"], default="wall", help="cpu: the process's CPU time (a loaded machine)")
    args = parser.parse_args()
    global CLOCK
    CLOCK = time.process_time if args.clock == "cpu" else time.perf_counter
    run = {"single": lambda: single(args), "sync": lambda: vector(args, "sync"),
           "native": lambda: vector(args, "vector_entry_point"), "kernels": lambda: kernels(args)}
    run.update({case: sb3(args, case == "sb3_native") for case in ("sb3_single", "sb3_native") if case in args.cases})
    results: dict[str, list[float]] = {case: [] for case in args.cases}
    for _ in range(args.repeats):  # interleaved, so every case sees the same machine load
        for case in args.cases:
            results[case].append(run[case]())
    medians = {case: statistics.median(values) for case, values in results.items()}
    print(f"{args.scenario}, {args.humans} humans, batch {args.batch}, modalities {' '.join(args.modalities)}; "
          f"median of {args.repeats} (env-steps/s, {args.clock} clock)")
    for case, value in medians.items():
        print(f"  {case:8s} {value:10,.0f}")
    if "native" in medians:
        for other in ("sync", "single", "kernels"):
            if other in medians:
                print(f"  native / {other}: {medians['native'] / medians[other]:.2f}x")
    if "sb3_native" in medians and "sb3_single" in medians:
        pairs = [n / s for n, s in zip(results["sb3_native"], results["sb3_single"], strict=True)]
        print(f"  sb3_native / sb3_single: {medians['sb3_native'] / medians['sb3_single']:.2f}x "
              f"(median of the per-repeat ratios {statistics.median(pairs):.2f}x)")


if __name__ == "__main__":
    main()
