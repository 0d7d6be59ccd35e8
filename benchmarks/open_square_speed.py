"""The crowd's walking speed in an open square: 10 humans between random goals, stall rule on and off.

    python benchmarks/open_square_speed.py [--seeds 8] [--steps 3000] [--preferred 0.8 1.2] [--goal-saturation D]
    python benchmarks/open_square_speed.py --preset calibrated --steps 4000   # the crowd preset's speeds and forces

``open_space`` with 10 humans (``on_goal: new_goal``, goals drawn anywhere in the square), the robot
standing still (the humans do not see it), stepped ``--steps`` steps per seed. Prints, per seed
and stall setting, the median speed of every human over every step, the median preferred speed,
their ratio, the median speed over the last 500 steps (a frozen crowd shows there) and the stalls
(docs/simulator.md#stalled-humans); with ``--steps`` of 4,000 or more also the crowd's mean speed over
steps 2,500-4,000 (issue 52's figure). ``--preset NAME``: ``humans.preset`` (docs/simulator.md#crowd-presets),
with the file's ``preferred_speed`` left out so the preset's speeds apply (``--preferred`` then ignored).
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
import yaml

from crowdnav import Simulator
from crowdnav.scenario.library import resolve

WINDOW = (2500, 4000)
"""Steps over which issue 52 reports the crowd's mean speed."""


def open_square(preset: str | None) -> Any:
    """``open_space``: the library name, or with a crowd preset its file without ``humans.preferred_speed`` (the preset's apply)."""
    if preset is None:
        return "open_space"
    document = yaml.safe_load(resolve("open_space").read_text(encoding="utf-8"))
    del document["humans"]["preferred_speed"]
    document["humans"]["preset"] = preset
    return document


def crowd_speeds(overrides: dict[str, object], seed: int, steps: int, preset: str | None = None) -> tuple[np.ndarray, Simulator]:
    """(steps, n) speeds (m/s) of every human after each step, and the simulator at the end."""
    sim = Simulator(open_square(preset), {"humans.count": 10, "max_steps": steps + 1, **overrides})
    sim.reset(seed=seed)
    speeds = np.empty((steps, sim.n_humans))
    for t in range(steps):
        sim.step(np.zeros(2))
        speeds[t] = np.abs(sim.human_velocities)
    return speeds, sim


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--preferred", type=float, nargs=2, default=[0.8, 1.2], help="humans.preferred_speed [min, max] (m/s)")
    parser.add_argument("--preset", default=None, help="humans.preset (e.g. calibrated); the preset's preferred speeds")
    parser.add_argument("--goal-saturation", type=float, default=None,
                        help="humans.social_force.goal_saturation_distance (m; default: the scenario's, 1 m): humans slow down within it")
    args = parser.parse_args()
    force = {} if args.goal_saturation is None else {"humans.social_force.goal_saturation_distance": args.goal_saturation}
    speed = {} if args.preset else {"humans.preferred_speed": list(args.preferred)}
    for label, stall in (("stall rule on (default)", {}), ("stall rule off", {"humans.stall.time": None})):
        ratios, medians, stalls, window = [], [], 0, []
        print(f"== {label}, " + (f"preset {args.preset}" if args.preset else f"preferred speed {args.preferred}"))
        for seed in range(args.seeds):
            speeds, sim = crowd_speeds({**speed, **force, **stall}, seed, args.steps, args.preset)
            if args.steps >= WINDOW[1]:
                window.append(float(speeds[WINDOW[0] : WINDOW[1]].mean()))
            preferred = float(np.median(sim.human_preferred_speed))
            median = float(np.median(speeds))
            ratios.append(median / preferred)
            medians.append(median)
            stalls += int(sim.human_stalls.sum())
            print(f"seed {seed}: median speed {median:.3f} m/s, preferred {preferred:.3f} (ratio {median / preferred:.2f}), "
                  f"last 500 steps {np.median(speeds[-500:]):.3f}, stalls {int(sim.human_stalls.sum())}")
        print(f"all seeds: median speed {np.median(medians):.3f} m/s, ratio to preferred: mean {np.mean(ratios):.3f}, "
              f"min {min(ratios):.2f}; stalls {stalls}")
        if window:
            print(f"mean speed over steps {WINDOW[0]:,}-{WINDOW[1]:,}: {np.mean(window):.3f} m/s (seeds: min {min(window):.3f}, "
                  f"max {max(window):.3f})")


if __name__ == "__main__":
    main()
