"""Early stopping on validation episodes for a finished experiment: each run read at its best snapshot on validation seeds.

    python benchmarks/validation_choice.py RESULTS/EXPERIMENT [--episodes 300] [--seed-base 500000]
                                           [--configurations NAME ...]

Plays every run's evaluation-point snapshots on validation episodes (seeds 500,000 on by default, disjoint from the
test and training seeds), keeps per run the snapshot with the most validation successes (ties: the later) and prints
its test evaluation, already stored by the protocol (crowdnav.evaluation.validation_choice). Validation outcomes are
stored beside each run and reused. The rule is fixed here, so it can be declared before a run's test rates are seen.
"""

from __future__ import annotations

import argparse
import sys

from crowdnav.evaluation.validation_choice import VALIDATION_EPISODES, VALIDATION_SEED_BASE, choose_on_validation, summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("experiment", help="an experiment's results folder (crowdnav benchmark --out DIR: DIR/<experiment>)")
    parser.add_argument("--episodes", type=int, default=VALIDATION_EPISODES, help="validation episodes per snapshot (default 300)")
    parser.add_argument("--seed-base", type=int, default=VALIDATION_SEED_BASE, help="first validation seed (default 500000)")
    parser.add_argument("--configurations", nargs="*", default=None, help="only these configurations (default: every one)")
    args = parser.parse_args(argv)
    try:
        choices = choose_on_validation(args.experiment, episodes=args.episodes, seed_base=args.seed_base,
                                       configurations=args.configurations)
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(summary(choices))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
