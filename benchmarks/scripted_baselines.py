"""How hard is each scenario? Outcome rates and mean return of the scripted robot policies.

    python benchmarks/scripted_baselines.py [--scenarios open_space room_furniture] [--episodes 200]
                                            [--set humans.count=5 ...]

Runs ``straight`` (head for the goal at full speed, blind to everyone) and ``social-force``
(the humans' own model applied to the robot: goal attraction plus repulsion from the humans'
*positions*, no velocities; privileged, it reads the simulator) on episodes with seeds 0, 1,
... of each scenario, with the scenario's own reward weights. Prints success / collision /
out_of_bounds / truncated rates, the mean return, the mean episode length and each reward term's mean sum
per episode. A learned policy that sees the same scene should at least match ``straight``;
``social-force`` shows what a purely reactive, position-only policy can reach.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from crowdnav.cli.common import CliError, add_override_option, parse_overrides
from crowdnav.envs import CrowdNavEnv
from crowdnav.envs.reward import REWARD_TERMS
from crowdnav.planning.scripted import SocialForceRobot, StraightToGoal
from crowdnav.scenario.library import library_names
from crowdnav.sim.simulator import OUTCOMES

POLICIES = {"straight": StraightToGoal, "social-force": SocialForceRobot}


def run(scenario: str, policy_name: str, episodes: int, overrides: dict) -> dict:
    """Outcome rates, mean return / length and mean reward terms of one policy on one scenario."""
    env = CrowdNavEnv(scenario, modalities=["goal"], overrides=overrides)
    policy = POLICIES[policy_name]()
    outcomes, returns, lengths = [], [], []
    terms = dict.fromkeys(REWARD_TERMS, 0.0)
    for seed in range(episodes):
        env.reset(seed=seed)
        total, length = 0.0, 0
        while True:
            _, reward, terminated, truncated, info = env.step(policy(env.simulator))
            total, length = total + reward, length + 1
            for name, value in info["reward_terms"].items():
                terms[name] += value
            if terminated or truncated:
                break
        outcomes.append(info["outcome"])
        returns.append(total)
        lengths.append(length)
    env.close()
    return {
        **{name: outcomes.count(name) / episodes for name in OUTCOMES},
        "return": float(np.mean(returns)), "length": float(np.mean(lengths)),
        "terms": {name: value / episodes for name, value in terms.items()},
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenarios", nargs="+", default=library_names())
    parser.add_argument("--episodes", type=int, default=200)
    add_override_option(parser)
    args = parser.parse_args(argv)
    try:
        overrides = parse_overrides(args.overrides)
    except CliError as error:
        parser.error(str(error))
    print(f"{args.episodes} episodes (seeds 0..{args.episodes - 1}) per scenario and policy" + (f"; overrides {overrides}" if overrides else ""))
    print(f"{'scenario':24s} {'policy':13s} " + " ".join(f"{name:>13s}" for name in OUTCOMES) + f" {'return':>8s} {'length':>7s}  "
          + " ".join(f"{name:>12s}" for name in REWARD_TERMS))
    for scenario in args.scenarios:
        for policy_name in POLICIES:
            row = run(scenario, policy_name, args.episodes, overrides)
            print(f"{scenario:24s} {policy_name:13s} " + " ".join(f"{row[name]:13.1%}" for name in OUTCOMES)
                  + f" {row['return']:8.0f} {row['length']:7.1f}  " + " ".join(f"{row['terms'][name]:12.0f}" for name in REWARD_TERMS),
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
