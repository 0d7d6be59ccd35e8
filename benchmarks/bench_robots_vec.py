"""World-steps per second of the shared robot policy's training env (``agents: robots``): the stacked engine against one
robots-only env per world, in one run.

    python benchmarks/bench_robots_vec.py [--scenario robots_crossing_hall] [--worlds 32] [--steps 200] [--repeats 3] [--clock cpu]

Both cases are :class:`crowdnav.agents.marl.vec_env.RobotsVecEnv` (SB3's VecEnv, one row per robot per world) over
the same worlds, stepped with the same random actions (``robot_actions: velocity``, as the shared robot runs train):

* ``single``: one robots-only PettingZoo env per world (:class:`crowdnav.envs.engines.robots.SingleRobots`, what
  collected before the stacked engine and what a scenario that does not stack still gets);
* ``stacked``: the worlds in one batched simulator (:class:`crowdnav.envs.engines.stacked_robots.StackedRobots`).

Their rows are the same bit for bit (tests/agents/test_marl_vec_env.py). Printed: each case's median world-steps/s
(robot rows/s is that times the robots) and stacked / single. ``--clock cpu`` times with the process's CPU time: on
a machine shared with other jobs the wall clock also counts the time the process waits for a core. Measured
2026-12-07 (2 shared cores, ``OMP_NUM_THREADS=1 ... --clock cpu --repeats 5``): 32 worlds, single 1,453 world-steps/s,
stacked 5,120 (3.52x); docs/agents.md#several-robots-shared-parameter-ppo.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable

import numpy as np

CLOCK: Callable[[], float] = time.perf_counter
CASES = ["single", "stacked"]


def vec_env(args: argparse.Namespace, stacked: bool):  # noqa: ANN201  (a RobotsVecEnv: SB3 imported on demand)
    from crowdnav.agents.marl.vec_env import RobotsVecEnv
    from crowdnav.agents.training.config import config_from_mapping

    config = config_from_mapping({"scenario": args.scenario, "agents": "robots", "algo": "ppo", "num_envs": args.worlds, "seed": 0,
                                  "out": tempfile.mkdtemp() + "/run", "progress": False, "robot_actions": "velocity"})
    return RobotsVecEnv.make(config, stacked=stacked)


def timing(args: argparse.Namespace, stacked: bool) -> Callable[[], float]:
    """The case's env, made and warmed once (20 steps); returns its timing run (world-steps/s over ``--steps`` steps)."""
    vec = vec_env(args, stacked)
    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps + 20, vec.num_envs, 2)).astype(np.float32)
    vec.reset()
    for action in actions[:20]:
        vec.step(action)

    def run() -> float:
        start = CLOCK()
        for action in actions[20:]:
            vec.step(action)
        return args.steps * args.worlds / (CLOCK() - start)
    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="robots_crossing_hall")
    parser.add_argument("--worlds", type=int, default=32)
    parser.add_argument("--steps", type=int, default=200, help="steps of every world per measurement")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--cases", nargs="+", default=CASES, choices=CASES)
    parser.add_argument("--clock", choices=["wall", "cpu"], default="wall", help="cpu: the process's CPU time (a loaded machine)")
    args = parser.parse_args()
    global CLOCK
    CLOCK = time.process_time if args.clock == "cpu" else time.perf_counter
    run = {case: timing(args, case == "stacked") for case in args.cases}
    results: dict[str, list[float]] = {case: [] for case in args.cases}
    for _ in range(args.repeats):  # interleaved, so every case sees the same machine load
        for case in args.cases:
            results[case].append(run[case]())
    medians = {case: statistics.median(values) for case, values in results.items()}
    print(f"{args.scenario}, {args.worlds} worlds; median of {args.repeats} (world-steps/s, {args.clock} clock)")
    for case, value in medians.items():
        print(f"  {case:8s} {value:10,.0f}")
    if len(medians) == 2:
        print(f"  stacked / single: {medians['stacked'] / medians['single']:.2f}x")


if __name__ == "__main__":
    main()
