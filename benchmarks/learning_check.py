"""Single-seed learning runs for diagnosis: SAC with crowdnav's defaults plus any ``--set`` override.

    python benchmarks/learning_check.py --seeds 0 [--episodes 400] [--set KEY=VALUE ...] --out runs/lc

The learning check itself is the experiment ``crowdnav benchmark learning_check`` (5 seeds, two
scenarios, baselines, curves; docs/agents.md#learning-check). This script is its quick,
hand-driven relative: for each seed, trains SAC (``open_space``, closest obstacle + goal unless
``--set modalities=...``) for ``--episodes`` episodes with crowdnav's defaults and the ``--set``
training-config overrides (YAML value, dotted key), saving a snapshot every ``--eval-every``
episodes, and evaluates each snapshot on ``--test-episodes`` held-out episodes with the
deterministic policy. Test episodes use seeds 0, 1, ...; training episodes use seeds >=
1,000,000 (``crowdnav.agents.train_seed``), so the two sets are disjoint. docs/agents.md#how-the-recipe-was-found
lists the runs made with it.

Resumable: an interrupted training resumes from its checkpoint, and evaluations already in
``OUT/seed_N/evaluations.json`` are not redone (``OUT/results.json`` gathers all seeds, so
several processes can check different seeds into the same ``--out``). Pass: every seed reaches >= ``--target`` success on the
test episodes at some evaluation within the budget (the final evaluation is reported too).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from crowdnav.agents import load_policy, train
from crowdnav.agents.runs.checkpoint import find_checkpoint
from crowdnav.agents.training.config import load_config

from crowdnav.cli.common import CliError, parse_overrides
from crowdnav.files import atomic_write_text
from crowdnav.sim.simulator import OUTCOMES

MODALITIES = ["closest_obstacle", "goal"]
"""The main job's input (``--set modalities=[lidar, goal]`` for another)."""


def evaluate(policy_path: Path, seeds: list[int]) -> dict[str, float]:
    """The rate of each outcome (:data:`crowdnav.sim.simulator.OUTCOMES`) of the deterministic policy on the episodes with ``seeds``."""
    policy = load_policy(policy_path)
    env = policy.make_env()
    outcomes = []
    for seed in seeds:
        observation, _ = env.reset(seed=seed)
        while True:
            observation, _, terminated, truncated, info = env.step(policy(observation))
            if terminated or truncated:
                outcomes.append(info["outcome"])
                break
    return {name: outcomes.count(name) / len(outcomes) for name in OUTCOMES}


def run_seed(seed: int, args: argparse.Namespace, results: dict, save) -> None:
    out = args.out / f"seed_{seed}"
    config = load_config(None, {"scenario": args.scenario, "modalities": MODALITIES, "algo": "sac", "episodes": args.episodes,
                                "seed": seed, "out": str(out), "checkpoint_every": args.eval_every, "progress": False,
                                "save_replay_buffer": True, **args.settings})
    done = False
    try:
        done = int(json.loads((find_checkpoint(out) / "policy.json").read_text())["episodes"]) >= args.episodes
    except FileNotFoundError:
        pass
    if not done:
        started = time.perf_counter()
        result = train(config, resume=(out / "checkpoint").exists())
        print(f"seed {seed}: trained to {result.episodes} episodes ({result.timesteps} steps) in {result.seconds:.0f} s, "
              f"{result.steps_per_second:.0f} steps/s, training success {result.success_rate:.0%} "
              f"[{time.perf_counter() - started:.0f} s]", flush=True)
    test_seeds = list(range(args.test_episodes))
    seed_results = results.setdefault(str(seed), {})
    for snapshot in sorted((out / "snapshots").glob("episode_*")):
        episodes = int(snapshot.name.split("_")[1])
        if str(episodes) in seed_results or episodes > args.episodes:
            continue
        seed_results[str(episodes)] = evaluate(snapshot, test_seeds)
        save()
        rates = seed_results[str(episodes)]
        print(f"seed {seed} after {episodes:4d} episodes: " + "  ".join(f"{name} {rates[name]:.0%}" for name in OUTCOMES), flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--episodes", type=int, default=300)
    parser.add_argument("--eval-every", type=int, default=50)
    parser.add_argument("--test-episodes", type=int, default=20)
    parser.add_argument("--target", type=float, default=0.8)
    parser.add_argument("--scenario", default="open_space")
    parser.add_argument("--out", type=Path, default=Path("runs/learning_check"))
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="training-config override (dotted key, YAML value), e.g. --set overrides={humans.count: 5}; repeatable")
    args = parser.parse_args(argv)
    try:
        args.settings = parse_overrides(args.set)
    except CliError as error:
        parser.error(str(error))
    print(f"settings beyond crowdnav's defaults: {args.settings or 'none'}", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    results_file = args.out / "results.json"
    results = {}
    for seed in args.seeds:
        # one file per seed, so processes checking different seeds into the same --out never clash
        seed_file = args.out / f"seed_{seed}" / "evaluations.json"
        results[str(seed)] = json.loads(seed_file.read_text()) if seed_file.exists() else {}

        def save(seed_file: Path = seed_file, seed: int = seed) -> None:
            seed_file.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(seed_file, json.dumps(results[str(seed)], indent=2) + "\n")

        run_seed(seed, args, results, save)
    # results.json: every seed evaluated in --out so far, this process's and others'
    merged = {path.parent.name.removeprefix("seed_"): json.loads(path.read_text())
              for path in sorted(args.out.glob("seed_*/evaluations.json"))}
    atomic_write_text(results_file, json.dumps(merged, indent=2) + "\n")
    summary = {}
    for seed in args.seeds:
        evaluations = {int(k): v["success"] for k, v in results[str(seed)].items()}
        reached = [episodes for episodes, rate in sorted(evaluations.items()) if rate >= args.target]
        summary[seed] = {"best": max(evaluations.values()), "final": evaluations[max(evaluations)],
                         "first_reaching_target": reached[0] if reached else None}
    print(json.dumps({"summary": summary}, indent=2))
    passed = all(entry["first_reaching_target"] is not None for entry in summary.values())
    mean_final = float(np.mean([entry["final"] for entry in summary.values()]))
    print(f"{'PASS' if passed else 'FAIL'}: every seed reaches {args.target:.0%} test success within {args.episodes} episodes; "
          f"mean final success {mean_final:.0%}")
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main())
