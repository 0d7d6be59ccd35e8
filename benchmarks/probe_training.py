"""One training run, then every snapshot on held-out test episodes: the probe behind docs/agents.md's plateau table.

    python benchmarks/probe_training.py '{"algo": "ppo", "modalities": ["closest_obstacle", "goal"],
        "scenario": "room_furniture", "overrides": {"humans.count": 5, "humans.preferred_speed": [0.5, 1.2]},
        "timesteps": 1500000, "checkpoint_every_steps": 300000, "out": "/tmp/probe/co"}' [--tests 100] [--baselines]

The JSON is a training config (``crowdnav.agents.TrainConfig`` fields; ``progress`` off unless given). After
training, each ``snapshots/steps_<N>`` policy plays the held-out test episodes with seeds
0..tests-1 (deterministic actions, batched); one line per snapshot: env steps, success rate and
the other outcomes. ``--baselines`` also plays the two scripted robots on the same episodes.
Lighter than an experiment (no protocol, leaderboard or curves): for quick questions, one seed.
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
import time

from crowdnav.agents import load_policy, train
from crowdnav.agents.run_folder import policy_snapshots
from crowdnav.evaluation.baselines import scripted_policy
from crowdnav.evaluation.rollout import HeldOutEpisodes


def outcomes(rows: list[dict]) -> str:
    counts = collections.Counter(row["outcome"] for row in rows)
    return f"success {counts['success'] / len(rows):.0%}  " + "  ".join(
        f"{name} {counts[name]}" for name in ("collision", "out_of_bounds", "truncated"))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("config", help="training config as JSON")
    parser.add_argument("--tests", type=int, default=100, help="held-out test episodes (seeds 0..N-1)")
    parser.add_argument("--baselines", action="store_true", help="also the scripted robots on the same episodes")
    args = parser.parse_args(argv)
    config = {"progress": False, **json.loads(args.config)}
    started = time.perf_counter()
    result = train(config)
    print(f"trained {result.episodes} episodes, {result.timesteps} env steps in {time.perf_counter() - started:.0f} s "
          f"({result.steps_per_second:.0f} env steps/s)", flush=True)
    episodes = None
    for point, folder in sorted(policy_snapshots(config["out"], "steps").items()):
        policy = load_policy(folder)
        episodes = episodes or HeldOutEpisodes(policy.env_options, range(args.tests))
        print(f"{point:>10,} env steps: {outcomes(episodes.run(policy))}", flush=True)
    if args.baselines and episodes is not None:
        scripted = HeldOutEpisodes({**episodes.env_options, "modalities": ["goal"]}, range(args.tests))
        for name in ("social_force", "straight"):
            print(f"{name:>21}: {outcomes(scripted.run(scripted_policy(name), privileged=True))}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
