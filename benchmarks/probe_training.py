"""Training runs, then their snapshots on held-out test episodes: the probe behind docs/agents.md's plateau tables.

One run:

    python benchmarks/probe_training.py '{"algo": "ppo", "modalities": ["closest_obstacle", "goal"],
        "scenario": "room_furniture", "overrides": {"humans.count": 5, "humans.preferred_speed": [0.5, 1.2]},
        "timesteps": 1500000, "checkpoint_every_steps": 300000, "out": "/tmp/probe/co"}' [--tests 100] [--baselines]

Many runs side by side, one process each (a many-core machine), cut at a wall-time limit:

    python benchmarks/probe_training.py --variants benchmarks/plateau_variants.json --out /tmp/sweep \
        --workers 15 --train-seconds 365 --last 3 [--baselines]

The JSON is a training config (``crowdnav.agents.TrainConfig`` fields; ``progress`` off unless given). A
variants file maps run names to configs; a config may name ``"base"``, a top-level entry whose fields it
extends, and each run's ``out`` is ``OUT/<name>``. After training, each ``snapshots/steps_<N>`` policy (the
``--last`` ones; default all) plays the held-out test episodes with seeds 0..tests-1 (deterministic
actions, batched); one line per snapshot: env steps, success rate and the other outcomes. ``--baselines``
also plays the two scripted robots on the same episodes. A run still training at ``--train-seconds`` is
killed and judged by the snapshots it saved: its learning-rate schedule did not run to its end, so such
numbers depend on the machine's speed (say so where they are quoted). Lighter than an experiment (no
protocol, leaderboard or curves): for quick questions.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import signal
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from crowdnav.agents import load_policy, train
from crowdnav.agents.runs.folder import policy_snapshots
from crowdnav.evaluation.baselines import scripted_policy
from crowdnav.evaluation.rollout import HeldOutEpisodes

from crowdnav.files import open_for_write

TRAIN = "import json, sys; from crowdnav.agents import train; train(json.loads(sys.argv[1]))"
"""What each side-by-side run executes: a fresh interpreter per run (one core each, nothing shared)."""


def outcomes(rows: list[dict]) -> str:
    counts = collections.Counter(row["outcome"] for row in rows)
    return f"success {counts['success'] / len(rows):.0%}  " + "  ".join(
        f"{name} {counts[name]}" for name in ("collision", "out_of_bounds", "truncated"))


def snapshot_lines(out: str, tests: int, last: int | None, label: str = "") -> tuple[list[str], dict | None]:
    """One line per evaluated snapshot of the run in ``out``; the env options of its policies."""
    lines, episodes = [], None
    for point, folder in sorted(policy_snapshots(out, "steps").items())[-(last or 0):]:
        policy = load_policy(folder)
        episodes = episodes or HeldOutEpisodes(policy.env_options, range(tests))
        lines.append(f"{label}{point:>10,} env steps: {outcomes(episodes.run(policy))}")
    return lines or [f"{label}no snapshot saved"], episodes.env_options if episodes else None


def baseline_lines(env_options: dict, tests: int) -> list[str]:
    scripted = HeldOutEpisodes({**env_options, "modalities": ["goal"]}, range(tests))
    return [f"{name:>21}: {outcomes(scripted.run(scripted_policy(name), privileged=True))}" for name in ("social_force", "straight")]


def load_variants(path: str, out: str) -> dict[str, dict[str, Any]]:
    entries = json.loads(Path(path).read_text())
    base = entries.pop("base", {})
    return {name: {"progress": False, **base, **config, "out": f"{out}/{name}"} for name, config in entries.items()}


def train_side_by_side(configs: dict[str, dict[str, Any]], workers: int, seconds: float) -> None:
    """Start every run (at most ``workers`` at once), kill what still trains after ``seconds``; logs in OUT/<name>.log."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    waiting, running, started = list(configs.items()), {}, time.monotonic()
    while (waiting or running) and time.monotonic() - started < seconds:
        for name in [name for name, process in running.items() if process.poll() is not None]:
            del running[name]
        while waiting and len(running) < workers:
            name, config = waiting.pop(0)
            Path(config["out"]).parent.mkdir(parents=True, exist_ok=True)
            # never through a planted link (refused in one line); the child keeps its own copy of the handle
            with os.fdopen(open_for_write(f"{config['out']}.log", os.O_WRONLY | os.O_CREAT | os.O_TRUNC), "w") as log:
                running[name] = subprocess.Popen([sys.executable, "-c", TRAIN, json.dumps(config)], stdout=log,
                                                 stderr=subprocess.STDOUT, env=env, start_new_session=True,
                                                 cwd=Path(config["out"]).parent)  # not a source tree: import the installed crowdnav
        time.sleep(1)
    for name, process in running.items():
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            print(f"{name}: still training at {seconds:.0f} s, killed", flush=True)
        process.wait()


def evaluate_variant(job: tuple[str, str, int, int | None]) -> list[str]:
    name, out, tests, last = job
    return snapshot_lines(out, tests, last, f"{name:>22} ")[0]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("config", nargs="?", help="training config as JSON (one run)")
    parser.add_argument("--variants", help="JSON file: run name -> training config (many runs side by side)")
    parser.add_argument("--out", default="runs/probe", help="with --variants: folder of the runs")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="with --variants: runs at once")
    parser.add_argument("--train-seconds", type=float, default=float("inf"), help="with --variants: kill runs still training after this")
    parser.add_argument("--last", type=int, help="evaluate only the last N snapshots of each run")
    parser.add_argument("--tests", type=int, default=100, help="held-out test episodes (seeds 0..N-1)")
    parser.add_argument("--baselines", action="store_true", help="also the scripted robots on the same episodes")
    args = parser.parse_args(argv)
    if (args.config is None) == (args.variants is None):
        parser.error("give one training config (JSON) or --variants FILE")
    if args.variants:
        configs = load_variants(args.variants, args.out)
        train_side_by_side(configs, args.workers, args.train_seconds)
        jobs = [(name, config["out"], args.tests, args.last) for name, config in configs.items()]
        with ProcessPoolExecutor(args.workers) as pool:
            for lines in pool.map(evaluate_variant, jobs):
                print("\n".join(lines), flush=True)
        env_options = snapshot_lines(jobs[0][1], 1, 1)[1] if args.baselines else None
    else:
        config = {"progress": False, **json.loads(args.config)}
        started = time.perf_counter()
        result = train(config)
        print(f"trained {result.episodes} episodes, {result.timesteps} env steps in {time.perf_counter() - started:.0f} s "
              f"({result.steps_per_second:.0f} env steps/s)", flush=True)
        lines, env_options = snapshot_lines(config["out"], args.tests, args.last)
        print("\n".join(lines), flush=True)
    if args.baselines and env_options is not None:
        print("\n".join(baseline_lines(env_options, args.tests)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
