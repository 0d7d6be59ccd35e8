"""What the people tracker (``sensors.tracker``) adds to a native vector-env step, against the ``perfect`` profile.

    nice .venv/bin/python benchmarks/bench_tracker.py [--scenario room_furniture] [--humans 10] [--batch 32] [--steps 200] [--repeats 7]

The same B worlds (random actions, autoreset) are stepped with each profile of ``--profiles`` (first: the
reference, ``perfect``), the cases interleaved repeat by repeat so every profile sees the same machine
load, each timed with the process's CPU time (``--clock wall`` for the wall clock). Printed per
profile: the median milliseconds per vector step, the median of the per-repeat ratios to the
reference (the tracker's share: issue 51 asks for at most 1.20 at 32 worlds and 10 humans), and the
median time of the tracker's own updates per step (``PeopleTracker.update``, the same clock).
``--modalities`` picks the observation (default: ``goal humans velocity``, a SARL-style agent's
tracker reader; ``--modalities goal closest_obstacle plan`` is the main job's, whose planner costs more).
``--baseline DIR`` adds, next to each tracker profile, the same profile with the people tracker of another checkout
(DIR: its repository root, e.g. ``git worktree add /tmp/tracker_base HEAD``; its ``crowdnav/sensors/tracker.py``,
``sightlines.py`` and ``tracker_draws.py``), interleaved in the same process: the tracker before and after a change.
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from crowdnav.envs.vector.env import CrowdNavVectorEnv

CLOCK: Callable[[], float] = time.process_time


BASELINE = "@baseline"
"""Suffix of a profile run with the ``--baseline`` checkout's tracker."""


def baseline_tracker(root: str) -> Any:
    """The ``PeopleTracker`` class of the checkout at ``root``, with that checkout's sightlines and draws (loaded under
    their own names for its imports, then the modules of this checkout put back)."""
    names = ("sightlines", "tracker_draws", "tracker")
    saved = {name: sys.modules.get(f"crowdnav.sensors.{name}") for name in names}
    loaded = {}
    try:
        for name in names:
            spec = importlib.util.spec_from_file_location(f"crowdnav.sensors.{name}", Path(root) / "crowdnav" / "sensors" / f"{name}.py")
            assert spec is not None and spec.loader is not None
            loaded[name] = sys.modules[spec.name] = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(loaded[name])
    finally:
        for name, module in saved.items():
            if module is not None:
                sys.modules[f"crowdnav.sensors.{name}"] = module
    return loaded["tracker"].PeopleTracker


def stepper(args: argparse.Namespace, profile: str) -> Callable[[], tuple[float, float]]:
    """A vector env of ``profile`` (``BASELINE``-suffixed: with the baseline's tracker), reset once; its timing run returns
    the seconds per vector step, and of them the tracker's updates."""
    name = profile.removesuffix(BASELINE)
    env = CrowdNavVectorEnv(args.scenario, num_envs=args.batch, modalities=args.modalities,
                            overrides={"humans.count": args.humans, "sensors.tracker.profile": name})
    engine: Any = env.engine
    if name != profile:
        engine.tracker = baseline_tracker(args.baseline)(engine.batch.world, engine.tracker.values, engine.num_worlds)
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps, args.batch, 2)).astype(np.float32)
    for action in actions[:10]:  # warm caches (the planner's maps, numpy's dispatch)
        env.step(action)
    spent = [0.0]
    tracker = getattr(env.engine, "tracker", None)
    if tracker is not None:  # the stacked worlds' tracker: its updates timed on the same clock
        update = tracker.update

        def timed(*given: Any) -> None:
            start = CLOCK()
            update(*given)
            spent[0] += CLOCK() - start
        tracker.update = timed

    def run() -> tuple[float, float]:
        spent[0] = 0.0
        start = CLOCK()
        for action in actions:
            env.step(action)
        return (CLOCK() - start) / len(actions), spent[0] / len(actions)
    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="room_furniture")
    parser.add_argument("--humans", type=int, default=10)
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--steps", type=int, default=200, help="vector steps per measurement")
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--modalities", nargs="+", default=["goal", "humans", "velocity"])
    parser.add_argument("--profiles", nargs="+", default=["perfect", "lidar_tracker", "camera_front"])
    parser.add_argument("--clock", choices=["wall", "cpu"], default="cpu", help="cpu: the process's CPU time (a shared machine)")
    parser.add_argument("--baseline", help="another checkout's root: each tracker profile also with its people tracker")
    args = parser.parse_args()
    global CLOCK
    CLOCK = time.perf_counter if args.clock == "wall" else time.process_time
    if args.baseline:
        args.profiles = [case for profile in args.profiles
                         for case in ([profile] if profile == args.profiles[0] else [profile + BASELINE, profile])]
    runs = {profile: stepper(args, profile) for profile in args.profiles}
    seconds: dict[str, list[float]] = {profile: [] for profile in args.profiles}
    tracking: dict[str, list[float]] = {profile: [] for profile in args.profiles}
    for _ in range(args.repeats):  # interleaved: every profile sees the same load
        for profile, run in runs.items():
            step, tracker = run()
            seconds[profile].append(step)
            tracking[profile].append(tracker)
    reference = args.profiles[0]
    print(f"{args.scenario}, {args.humans} humans, {args.batch} worlds, modalities {' '.join(args.modalities)}; "
          f"median of {args.repeats} x {args.steps} steps ({args.clock} clock)")
    for profile, values in seconds.items():
        ratios = [value / base for value, base in zip(values, seconds[reference], strict=True)]
        print(f"  {profile:23s} {statistics.median(values) * 1e3:7.3f} ms/step   x{statistics.median(ratios):.3f} of {reference}"
              f"   tracker updates {statistics.median(tracking[profile]) * 1e3:6.3f} ms/step")


if __name__ == "__main__":
    main()
