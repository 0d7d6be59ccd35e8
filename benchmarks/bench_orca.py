"""Cost of ORCA against the social force: a simulator step with each crowd model, and each privileged robot's decision.

    python benchmarks/bench_orca.py [--scenario room_furniture] [--counts 10 100] [--steps 3000] [--repeats 5]

Crowd: microseconds per ``Simulator.step`` (random robot actions, pre-drawn; an episode that
ends is reset inside the timed loop) with ``humans.model`` social_force, orca, and orca with
``see_robot`` (the robot is one more ORCA agent). Robot: microseconds per call of the scripted
robot policy (``SocialForceRobot``, ``OrcaRobot``) on the social-force crowd, the step itself not
counted. Medians over repeats (seeds 0, 1, ...). Needs pyrvo (``pip install -e ".[orca]"`` in crowdnav's clone).
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
from importlib.metadata import version

import numpy as np

from crowdnav import Simulator
from crowdnav.planning.scripted import OrcaRobot, SocialForceRobot


def step_microseconds(sim: Simulator, steps: int, seed: int) -> float:
    actions = np.random.default_rng(seed).uniform(-1, 1, size=(steps, 2))
    sim.reset(seed=seed)
    start = time.perf_counter()
    for action in actions:
        events = sim.step(action)
        if events.terminated or events.truncated:
            sim.reset()
    return (time.perf_counter() - start) / steps * 1e6


def policy_microseconds(sim: Simulator, policy, steps: int, seed: int) -> float:
    sim.reset(seed=seed)
    spent = 0.0
    for _ in range(steps):
        start = time.perf_counter()
        action = policy(sim)
        spent += time.perf_counter() - start
        events = sim.step(action)
        if events.terminated or events.truncated:
            sim.reset()
    return spent / steps * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenario", default="room_furniture")
    parser.add_argument("--counts", type=int, nargs="+", default=[10, 100])
    parser.add_argument("--steps", type=int, default=3000, help="timed steps per repeat")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print(f"# {args.scenario}, {args.steps} steps x {args.repeats} repeats, Python {platform.python_version()}, "
          f"numpy {np.__version__}, pyrvo {version('pyrvo')}; microseconds, median [min, max]")
    print(f"{'humans':>6}  {'what':<28} {'us':>8} {'min':>8} {'max':>8}  {'x social force':>14}")
    crowds = {"step, social_force crowd": {}, "step, orca crowd": {"humans.model": "orca"},
              "step, orca crowd, see_robot": {"humans.model": "orca", "humans.see_robot": True}}
    robots = {"robot policy, SocialForceRobot": SocialForceRobot, "robot policy, OrcaRobot": OrcaRobot}
    for count in args.counts:
        base = {}
        for label, overrides in crowds.items():
            sim = Simulator(args.scenario, overrides={"humans.count": count, **overrides})
            times = [step_microseconds(sim, args.steps, seed) for seed in range(args.repeats)]
            base.setdefault("step", statistics.median(times))
            _row(count, label, times, base["step"])
        sim = Simulator(args.scenario, overrides={"humans.count": count})
        for label, make in robots.items():
            policy = make()
            times = [policy_microseconds(sim, policy, args.steps, seed) for seed in range(args.repeats)]
            base.setdefault("robot", statistics.median(times))
            _row(count, label, times, base["robot"])


def _row(count: int, label: str, times: list[float], reference: float) -> None:
    median = statistics.median(times)
    print(f"{count:>6}  {label:<28} {median:>8.1f} {min(times):>8.1f} {max(times):>8.1f}  {median / reference:>14.2f}", flush=True)


if __name__ == "__main__":
    main()
