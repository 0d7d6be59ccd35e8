#!/usr/bin/env bash
# Figure 4(b) of the paper (modalities: LEOG, LIDAR, closest obstacle) with the paper's full
# protocol: 700 training episodes, 14 evaluations of 20 test episodes, 5 seeds per configuration.
# Runs in the background with 2 worker processes; safe to start again after an interruption
# (finished runs are skipped, interrupted ones resume from their last checkpoint).
#
#   benchmarks/run_experiment_b.sh            # start (or resume) in the background
#   tail -f results/modalities.log            # follow it
#
# Results: results/modalities/ (curves.png/pdf, leaderboard.md/csv, per-run data).
set -euo pipefail
cd "$(dirname "$0")/.."
mkdir -p results
nohup .venv/bin/crowdnav benchmark modalities --out results --workers 2 --no-progress >> results/modalities.log 2>&1 &
echo "started PID $! ; log: results/modalities.log ; results: results/modalities/"
