"""Training throughput of this checkout against another crowdnav checkout, in one run.

    git worktree add /tmp/crowdnav-before 1bf9eca      # e.g. the code the "Agents that learn" issue measured
    python benchmarks/bench_train_ab.py --before /tmp/crowdnav-before [--cases lidar+goal "leog+goal frozen"] [--repeats 2]

Each measurement is a fresh process (one torch thread) that builds crowdnav's default SAC agent for
the case on ``open_space`` with 5 humans, trains past ``learning_starts`` plus a warm-up, then times
``--steps`` env steps, gradient updates included (one per step: both versions' default
update-to-data ratio, printed). The two checkouts alternate within each repeat, so both see the
same machine load; the ratio of the medians per CPU second is the speed-up. The frozen case
pre-trains a throwaway encoder with each checkout (its weights do not change the speed).
Works with checkouts from before and after the ``crowdnav.agents`` namespace move.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

CASES = {"lidar+goal": (["lidar", "goal"], "scratch", 500), "leog+goal frozen": (["leog", "goal"], "frozen", 500),
         "leog+goal scratch": (["leog", "goal"], "scratch", 150)}
"""Case -> (modalities, encoder mode, timed steps)."""

_CHILD = r'''
import json, sys, tempfile, time
import numpy as np, torch
torch.set_num_threads(1)
try:
    from crowdnav.agents.config import config_from_mapping
    from crowdnav.agents.factory import load_leog_weights, make_env, make_model, precomputes_leog
    from crowdnav.agents.pretrain import pretrain_encoder
except ImportError:  # a checkout from before the namespace move
    from agents.config import config_from_mapping
    from agents.factory import load_leog_weights, make_env, make_model, precomputes_leog
    from agents.pretrain import pretrain_encoder
modalities, mode, steps, warmup = json.loads(sys.argv[1]), sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
encoder = {"mode": mode}
if mode != "scratch":
    grids = (np.random.default_rng(0).random((64, 1, 60, 60)) < 0.1).astype(np.uint8)
    encoder["weights"] = str(pretrain_encoder(grids, tempfile.mkdtemp(), epochs=1).encoder_path)
config = config_from_mapping({"scenario": "open_space", "modalities": modalities, "algo": "sac", "out": tempfile.mkdtemp(),
                              "progress": False, "overrides": {"humans.count": 5}, "encoder": encoder})
weights, saved = load_leog_weights(config)
model = make_model(config, make_env(config, weights if precomputes_leog(config) else None, 0), saved)
model.learn(model.learning_starts + warmup)
wall, cpu = time.perf_counter(), time.process_time()
model.learn(steps, reset_num_timesteps=False)
wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
print(json.dumps({"per_s": steps / wall, "per_cpu_s": steps / cpu, "gradient_steps": model.gradient_steps,
                  "train_freq": model.train_freq.frequency, "batch_size": model.batch_size}))
'''


def measure(tree: Path, case: str, warmup: int) -> dict:
    modalities, mode, steps = CASES[case]
    env = {**os.environ, "PYTHONPATH": str(tree), "OMP_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", _CHILD, json.dumps(modalities), mode, str(steps), str(warmup)],
                         cwd=tempfile.gettempdir(), env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", type=Path, required=True, help="the other crowdnav checkout (a git worktree)")
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--warmup", type=int, default=200, help="steps after learning_starts before timing")
    args = parser.parse_args(argv)
    here = Path(__file__).resolve().parent.parent
    print(f"# before: {args.before}  after: {here}; load average at start {os.getloadavg()[0]:.2f}")
    for case in args.cases:
        runs: dict[str, list[dict]] = {"before": [], "after": []}
        for repeat in range(args.repeats):
            order = ("before", "after") if repeat % 2 == 0 else ("after", "before")
            for which in order:
                runs[which].append(measure(args.before if which == "before" else here, case, args.warmup))
        before, after = (statistics.median(r["per_cpu_s"] for r in runs[w]) for w in ("before", "after"))
        walls = {w: statistics.median(r["per_s"] for r in runs[w]) for w in runs}
        utd = {w: f"{runs[w][0]['gradient_steps']} update / {runs[w][0]['train_freq']} step, batch {runs[w][0]['batch_size']}" for w in runs}
        print(f"{case:20s} before {before:7.1f} per CPU-s ({walls['before']:.1f}/s)  after {after:7.1f} per CPU-s "
              f"({walls['after']:.1f}/s)  speed-up {after / before:.2f}x  [{utd['before']} | {utd['after']}]")
    print(f"# load average at end {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
