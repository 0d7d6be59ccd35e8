"""Test episodes per second of a shared robot policy's or a scripted baseline's evaluation (one row per robot per episode).

    python benchmarks/bench_robot_rollout.py [--scenario robots_crossing_hall] [--episodes 32] [--worlds 32] [--repeats 3]
                                             [--policy RUN | --baseline straight|social_force] [--old COMMIT] [--clock cpu]

The same test episodes played by :class:`crowdnav.evaluation.robot_rollout.RobotEpisodes` three ways:

* ``old``: the rollout of commit ``--old`` (default b391f70, before the engine: one robots-only PettingZoo env, test
  seed after test seed, ``RobotsPolicy.act`` per step), read with ``git show``;
* ``single``: ``--worlds`` episodes at once, one robots-only env per world (``stacked=False``: the per-world engine);
* ``stacked``: ``--worlds`` episodes at once in the stacked engine (what ``crowdnav evaluate`` and experiments use).

``--baseline``: the scripted baseline an ``agents: robots`` experiment plays, driving every robot, on its env options
(the scenario, the goal observation): ``single`` is how it played before its batched twin drove the stack.

The script checks that every case gives the same rows (every column, bit for bit) and prints the median test
episodes/s of each and the ratios. ``--policy``: a shared robot run (``crowdnav train --agents robots``) played on its
own settings with ``--scenario`` and the default sensors; without it, the smallest run is trained first (a few
seconds; its robots mostly wander until the time limit, the longest episodes). ``--clock cpu`` times with the
process's CPU time (a machine shared with other jobs). Measured 2026-12-07 (2 shared cores, ``OMP_NUM_THREADS=1 ...
--repeats 3 --clock cpu``, the smallest run, every episode to the 150-step limit): old 4.8 test episodes/s, single 6.7
(1.40x), stacked 24.7 (5.15x); 100 episodes (``--episodes 100 --repeats 1``): 5.3, 7.2, 26.7 (5.03x).
Scripted baselines (``--baseline``), measured 2026-12-07 on the same 2 shared cores (``OMP_NUM_THREADS=1 ... --baseline
social_force --repeats 3 --clock cpu``): social force, every robot arriving, old 23.2, single 22.8, stacked 129.7 test
episodes/s (5.68x single); 100 episodes: 23.9, 23.4, 120.4 (5.15x); straight (collisions, arrivals): 64.9, 60.4, 228.0 (3.77x).
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import statistics
import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

CLOCK: Callable[[], float] = time.perf_counter
CASES = ["old", "single", "stacked"]


def shared_policy(args: argparse.Namespace) -> Any:
    """The ``--policy`` run's shared robot policy, or the smallest one trained now."""
    from crowdnav.agents.marl.robots import load_robots_policy, train_robots
    from crowdnav.agents.training.config import config_from_mapping

    if args.policy:
        return load_robots_policy(args.policy)
    out = Path(tempfile.mkdtemp()) / "run"
    train_robots(config_from_mapping({"scenario": args.scenario, "agents": "robots", "algo": "ppo", "num_envs": 2, "timesteps": 96,
                                      "n_steps": 16, "batch_size": 48, "net_arch": [64, 64], "seed": 0, "out": str(out),
                                      "progress": False, "robot_actions": "velocity"}))
    return load_robots_policy(out)


def played(args: argparse.Namespace) -> tuple[dict[str, Any], Any, bool]:
    """(env options, policy, privileged): the ``--baseline`` on an experiment's baseline options, or the shared robot policy."""
    if args.baseline:
        from crowdnav.evaluation.baselines import baseline_env_options, scripted_policy

        options = baseline_env_options({"scenario": args.scenario, "agents": "robots"})
        return options, scripted_policy(args.baseline), True
    policy = shared_policy(args)
    return policy.env_options, policy, False


def old_rollout(commit: str) -> Any:
    """``evaluation/robot_rollout.py`` as it was at ``commit``, as a module."""
    text = subprocess.run(["git", "show", f"{commit}:evaluation/robot_rollout.py"], check=True, capture_output=True, text=True,
                          cwd=Path(__file__).resolve().parents[1]).stdout
    path = Path(tempfile.mkdtemp()) / "old_robot_rollout.py"
    path.write_text(text, encoding="utf-8")
    spec = importlib.util.spec_from_file_location("old_robot_rollout", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def timing(args: argparse.Namespace, case: str, play: tuple[dict[str, Any], Any, bool], seeds: list[int],
           rows: dict[str, list[dict[str, Any]]]) -> Callable[[], float]:
    """The case's episodes, made once; returns its timing run (test episodes/s), which keeps its rows in ``rows``."""
    from crowdnav.evaluation.robot_rollout import RobotEpisodes

    options, policy, privileged = play
    if case == "old":
        episodes = old_rollout(args.old).RobotEpisodes(options, seeds)
    else:
        episodes = RobotEpisodes(options, seeds, worlds=args.worlds, stacked=case == "stacked")

    def run() -> float:
        start = CLOCK()
        rows[case] = episodes.run(policy, privileged=privileged)
        return len(seeds) / (CLOCK() - start)
    return run


def _same(a: Any, b: Any) -> bool:
    return a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="robots_crossing_hall")
    parser.add_argument("--episodes", type=int, default=32)
    parser.add_argument("--worlds", type=int, default=32)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--policy", help="a shared robot run (crowdnav train --agents robots); default: the smallest, trained now")
    parser.add_argument("--baseline", choices=["straight", "social_force"], help="a scripted baseline driving every robot instead")
    parser.add_argument("--old", default="b391f70", help="the commit whose rollout is the 'old' case")
    parser.add_argument("--cases", nargs="+", default=CASES, choices=CASES)
    parser.add_argument("--clock", choices=["wall", "cpu"], default="wall", help="cpu: the process's CPU time (a loaded machine)")
    args = parser.parse_args()
    global CLOCK
    CLOCK = time.process_time if args.clock == "cpu" else time.perf_counter
    play = played(args)
    seeds = list(range(1_000_000, 1_000_000 + args.episodes))
    rows: dict[str, list[dict[str, Any]]] = {}
    run = {case: timing(args, case, play, seeds, rows) for case in args.cases}
    results: dict[str, list[float]] = {case: [] for case in args.cases}
    for _ in range(args.repeats):  # interleaved, so every case sees the same machine load
        for case in args.cases:
            results[case].append(run[case]())
    first = rows[args.cases[0]]
    for case in args.cases[1:]:
        same = len(rows[case]) == len(first) and all(row.keys() == want.keys() and all(_same(row[key], want[key]) for key in want)
                                                     for row, want in zip(rows[case], first, strict=True))
        if not same:
            raise SystemExit(f"{case} and {args.cases[0]} gave different rows")
    medians = {case: statistics.median(values) for case, values in results.items()}
    outcomes = sorted({str(row["outcome"]) for row in first})
    playing = f"baseline {args.baseline}" if args.baseline else "a shared robot policy"
    print(f"{args.scenario}, {playing}, {args.episodes} test episodes x {len(first) // max(1, args.episodes)} robots ({', '.join(outcomes)}), "
          f"{args.worlds} worlds; the same rows in every case; median of {args.repeats} (test episodes/s, {args.clock} clock)")
    for case, value in medians.items():
        print(f"  {case:8s} {value:10,.1f}")
    for case in ("single", "stacked"):
        if case in medians and "old" in medians:
            print(f"  {case} / old: {medians[case] / medians['old']:.2f}x")
    if "single" in medians and "stacked" in medians:
        print(f"  stacked / single: {medians['stacked'] / medians['single']:.2f}x")


if __name__ == "__main__":
    main()
