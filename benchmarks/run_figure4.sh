#!/usr/bin/env bash
# The paper's Figure-4 experiments with the full protocol (700 training episodes, 14 evaluations
# of 20 held-out test episodes, 5 seeds per configuration), one experiment after the other, in
# the background, at low CPU priority. Safe to start again after an interruption: finished runs
# are skipped, interrupted ones resume from their last checkpoint, finished experiments are
# marked by OUT/<experiment>.done (holding the experiment's wall time in seconds).
#
#   benchmarks/run_figure4.sh [OUT]        # start or resume (default OUT: results)
#   tail -f results/modalities.log         # follow one experiment
#   python benchmarks/publish_results.py results/modalities   # when done: copy into docs/results/
#
# About 1 hour per experiment on a 2-core laptop (encoders: several: two of its three
# configurations train the CNN).
set -euo pipefail
cd "$(dirname "$0")/.."
out=$(realpath -m "${1:-results}")
mkdir -p "$out"
nohup bash -c '
  for exp in modalities fusion paradigms modalities_paper encoders; do
    [ -f "$0/$exp.done" ] && continue
    start=$(date +%s)
    nice -n 15 .venv/bin/crowdnav benchmark "$exp" --workers 2 --no-progress --no-video --out "$0" >> "$0/$exp.log" 2>&1 \
      && echo $(( $(date +%s) - start )) > "$0/$exp.done"
  done' "$out" > /dev/null 2>&1 &
echo "started PID $! ; logs: $out/<experiment>.log ; results: $out/<experiment>/"
