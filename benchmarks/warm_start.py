"""Demonstrations as a warm start, measured: the clone alone, RL from the clone, RL from scratch.

    python benchmarks/warm_start.py --algo ppo --seeds 0 1 2 --timesteps 300000 --every 50000 --out runs/warm_start

The Figure-4 setting (``room_furniture``, 5 humans at 0.5-1.2 m/s, closest obstacle + goal),
batched training with crowdnav's defaults (32 worlds). For each seed:

* ``scratch``: ``--timesteps`` env steps of RL from a new model;
* ``warm``: the same, from a new model warm-started with ``demonstrations.episodes:
  --demonstrations`` (:func:`crowdnav.agents.imitation.demonstrations.warm_start`: behaviour cloning of the
  social-force robot, value / critic pre-training, off-policy: the demonstrations in the replay
  buffer);

each evaluated at step 0 (the untrained model; the clone alone) and at every ``--every`` env
steps (the run's snapshots) on the held-out test episodes, seeds 0 .. ``--test-episodes`` - 1,
with the deterministic policy (:class:`crowdnav.evaluation.rollout.HeldOutEpisodes`). Training,
cloning and evaluation are deterministic: the same command gives the same numbers.
``--set KEY=VALUE`` (dotted key, YAML value) changes the training config of both runs, e.g.
``--set demonstrations.dagger_rounds=2``. Prints one JSON line per evaluation, then the table of
docs/agents.md#demonstrations-warm-start; ``OUT/results.json`` keeps them all. A run whose
last snapshot exists is not trained again; an interrupted one resumes.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import torch
from crowdnav.agents.imitation.demonstrations import warm_start
from crowdnav.agents.runs.checkpoint import AgentPolicy, load_policy
from crowdnav.agents.runs.folder import policy_snapshots
from crowdnav.agents.sb3.factory import env_options, make_model, make_vec_env, observation_normalization
from crowdnav.agents.training.config import TrainConfig, load_config
from crowdnav.agents.training.run import train
from crowdnav.agents.training.wrappers import scales_to_json
from crowdnav.evaluation.rollout import HeldOutEpisodes

from crowdnav.cli.common import CliError, parse_overrides
from crowdnav.files import atomic_write_text

FIGURE_4 = {"scenario": "room_furniture", "overrides": {"humans.count": 5, "humans.preferred_speed": [0.5, 1.2]},
            "modalities": ["closest_obstacle", "goal"]}


def success(policy: Any, held: HeldOutEpisodes) -> dict[str, Any]:
    rows = held.run(policy)
    outcomes = {o: sum(r["outcome"] == o for r in rows) for o in ("success", "collision", "out_of_bounds", "truncated")}
    return {"success": outcomes["success"] / len(rows), "outcomes": outcomes}


def step_zero(config: TrainConfig, held: HeldOutEpisodes) -> dict[str, Any]:
    """The new model before any RL step (warm-started when the config asks): its test success, and the warm start's report."""
    env = make_vec_env(config)
    model = make_model(config, env)
    started = time.perf_counter()
    report = warm_start(model, config)
    seconds = time.perf_counter() - started
    scales = observation_normalization(env)
    policy = AgentPolicy(model, {"algo": config.algo, "env": env_options(config),
                                 "observation_normalization": None if scales is None else scales_to_json(scales)})
    env.close()
    return {**success(policy, held), "warm_start_seconds": round(seconds, 1), "warm_start": report}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--algo", default="ppo")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--timesteps", type=int, default=300_000, help="RL env steps per run (0: step 0 only, no training)")
    parser.add_argument("--every", type=int, default=50_000, help="env steps between evaluated snapshots")
    parser.add_argument("--demonstrations", type=int, default=100, help="demonstration episodes of the warm start")
    parser.add_argument("--test-episodes", type=int, default=100)
    parser.add_argument("--runs", nargs="+", default=["scratch", "warm"], choices=["scratch", "warm"])
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="training-config override; repeatable")
    parser.add_argument("--out", default="runs/warm_start")
    args = parser.parse_args(argv)
    try:
        settings = parse_overrides(args.set)
    except CliError as error:
        parser.error(str(error))
    torch.set_num_threads(1)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results_file = out / "results.json"
    results: dict[str, Any] = json.loads(results_file.read_text()) if results_file.is_file() else {}
    held: HeldOutEpisodes | None = None
    for seed in args.seeds:
        for run in args.runs:
            name = f"{args.algo}_{run}_s{seed}"
            folder = out / name
            budget = {"timesteps": args.timesteps, "checkpoint_every_steps": args.every} if args.timesteps else {}
            config = load_config(None, {**FIGURE_4, "algo": args.algo, "seed": seed, **budget, "out": str(folder), "progress": False,
                                        "demonstrations.episodes": args.demonstrations if run == "warm" else 0, **settings})
            held = held or HeldOutEpisodes(env_options(config), list(range(args.test_episodes)))
            points = results.setdefault(name, {})
            if "0" not in points:
                points["0"] = step_zero(config, held)
                print(json.dumps({"run": name, "steps": 0, **points["0"]}), flush=True)
            snapshots = policy_snapshots(folder, "steps") if folder.is_dir() else {}
            if args.timesteps and args.timesteps not in snapshots:
                started = time.perf_counter()
                result = train(config, resume=(folder / "checkpoint").exists())
                points["train"] = {"seconds": round(time.perf_counter() - started, 1), "steps_per_second": round(result.steps_per_second)}
                snapshots = policy_snapshots(folder, "steps")
            for steps, snapshot in sorted(snapshots.items()):
                if str(steps) not in points:
                    points[str(steps)] = success(load_policy(snapshot, trusted=True), held)  # this script's own runs
                    print(json.dumps({"run": name, "steps": steps, **points[str(steps)]}), flush=True)
            atomic_write_text(results_file, json.dumps(results, indent=1) + "\n")
    steps = sorted({int(s) for points in results.values() for s in points if s.isdigit()})
    print("| run | " + " | ".join(f"{s // 1000}k" if s else "0" for s in steps) + " |")
    print("|---" * (len(steps) + 1) + "|")
    for name, points in sorted(results.items()):
        print(f"| {name} | " + " | ".join(f"{points[str(s)]['success']:.2f}" if str(s) in points else "" for s in steps) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
