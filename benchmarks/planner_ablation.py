"""What the lattice planners reach on a setting's test episodes: the oracle, and the predictive planner by prediction and horizon.

    python benchmarks/planner_ablation.py figure4 --episodes 100
    python benchmarks/planner_ablation.py room --episodes 100
    python benchmarks/planner_ablation.py circle --episodes 500

Each row plays the same test episodes (seeds 0 .. episodes-1) with one planner and prints its
outcome counts and wall time: the oracle (the humans' future), the predictive planner with
constant-velocity prediction over 1 and 2 s, and the same with the humans frozen where they stand
(what a planner without prediction reaches). docs/agents.md#what-holds-ppo-near-75 quotes it.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from typing import Any

from crowdnav.envs import CrowdNavEnv
from crowdnav.planning import OraclePlanner
from crowdnav.planning.predictive import PlannerSettings, PredictivePlanner

SETTINGS: dict[str, tuple[str, dict[str, Any]]] = {
    "figure4": ("room_furniture", {"humans.count": 5, "humans.preferred_speed": [0.5, 1.2]}),
    "room": ("room_furniture", {}),
    "circle": ("circle_crossing", {"humans.model": "orca", "humans.preferred_speed": [1.0, 1.0]}),
}
"""Setting name -> (scenario, overrides): the three settings of docs/planning.md."""

PLANNERS: dict[str, Any] = {
    "oracle (the future)": OraclePlanner,
    "predictive, constant velocity, 2 s": lambda: PredictivePlanner(PlannerSettings()),
    "predictive, constant velocity, 1 s": lambda: PredictivePlanner(PlannerSettings(horizon=1.0)),
    "predictive, humans frozen, 2 s": lambda: PredictivePlanner(PlannerSettings(prediction="frozen")),
}


def play(scenario: str, overrides: dict[str, Any], planner: Any, seeds: range) -> Counter[str]:
    """Outcome counts of ``planner`` on the episodes ``seeds``."""
    env = CrowdNavEnv(scenario=scenario, modalities=["goal"], overrides=overrides)
    outcomes: Counter[str] = Counter()
    for seed in seeds:
        env.reset(seed=seed)
        while True:
            _, _, terminated, truncated, info = env.step(planner(env.simulator))
            if terminated or truncated:
                outcomes[info["outcome"]] += 1
                break
    return outcomes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("setting", choices=sorted(SETTINGS))
    parser.add_argument("--episodes", type=int, default=100, help="test episodes, seeds 0 .. N-1 (default: 100)")
    args = parser.parse_args()
    scenario, overrides = SETTINGS[args.setting]
    print(f"| planner ({args.setting}, {args.episodes} test episodes) | success | collision | truncated | seconds |")
    print("|---|---|---|---|---|")
    for name, make in PLANNERS.items():
        start = time.perf_counter()
        counts = play(scenario, overrides, make(), range(args.episodes))
        total = sum(counts.values())
        print(f"| {name} | {counts['success'] / total:.0%} | {counts['collision'] / total:.0%} | "
              f"{counts['truncated'] / total:.0%} | {time.perf_counter() - start:.0f} |", flush=True)


if __name__ == "__main__":
    main()
