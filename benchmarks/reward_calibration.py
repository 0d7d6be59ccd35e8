"""Reward calibration: what the reward presets make of passing people and of each way an episode can end.

    python benchmarks/reward_calibration.py [--gammas 0.95 0.99] [--reward PRESET --reward-weight TERM=VALUE ...]

No training: scripted robot motions in the real :class:`crowdnav.Simulator`, scored by the real
:class:`crowdnav.envs.reward.Reward` under every preset of
:data:`crowdnav.scenario.reward_presets.REWARD_PRESETS` (plus a ``custom`` column when
``--reward`` / ``--reward-weight`` are given: that preset with those weights). Robot and human
radius 0.3 m, robot speed 1 m/s, time step 0.2 s, 150 steps, open world large enough that
nobody leaves it. Prints two markdown tables:

(a) **Passing encounters.** The robot drives straight along +x at 1 m/s past one human who walks
    the opposite way at 1 m/s (or stands), offset sideways so that the closest *surface* distance
    (centre distance minus both radii) is 0.5, 1 or 2 m; they start and end 8 m apart along x.
    Per step, the social term (``w_social * |F_social|``) over the steps of the pass (the centres
    within 2 m of each other along x): min / median / max, and its sum over the whole encounter.
    The column ``force`` is ``|F_social|`` itself (preset-free): its peak and its sum.
(b) **Outcomes.** Discounted return ``sum_t gamma^t r_t`` of scripted episodes toward a goal 6 m
    ahead: reach it; reach it past a person walking the other way at 0.5 m; collide with a wall,
    or with a person standing in the way, after 3 m of progress; stand still until the time
    limit; drive away from the goal until the time limit.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from crowdnav import Simulator
from crowdnav.cli.common import add_reward_options, reward_options
from crowdnav.envs.reward import Reward
from crowdnav.scenario.reward_presets import REWARD_PRESETS
from crowdnav.scenario.schema import RewardWeights

RADIUS = 0.3
"""Robot and human radius (m)."""
SPEED = 1.0
"""Robot speed, and the walking human's (m/s)."""
GOAL_DISTANCE = 6.0
"""Start-goal distance of the outcome episodes (m)."""
GAPS = (0.5, 1.0, 2.0)
"""Closest surface distances of the passing encounters (m)."""
PASS_WINDOW = 2.0
"""A step belongs to the pass while the centres are within this distance along the direction of travel (m)."""
ENCOUNTER_SPAN = 8.0
"""Distance along x between robot and human at the start and at the end of an encounter (m)."""

FORWARD, BACKWARD, STILL = np.array([1.0, 0.0]), np.array([-1.0, 0.0]), np.zeros(2)


def scenario(humans: int = 0, walls: Sequence[tuple[tuple[float, float], tuple[float, float]]] = (), behind: float = 40.0) -> dict:
    """An open 80 m x 80 m world (its edge ``behind`` m behind the robot), the robot at the origin heading +x, its goal
    6 m ahead; humans placed by hand later."""
    document = {
        "name": "reward_calibration",
        "description": "Scripted encounters for reward calibration.",
        "world": {"min": [-behind, -40], "max": [40, 40], "boundary_walls": False},
        "walls": [{"points": [list(a), list(b)], "thickness": 0.1} for a, b in walls],
        "robot": {
            "radius": RADIUS, "max_speed": SPEED, "start_heading": 0.0,
            "start": {"type": "points", "points": [[0.0, 0.0]]},
            "goal": {"type": "points", "points": [[GOAL_DISTANCE, 0.0]]},
        },
        "time_step": 0.2,
        "max_steps": 150,
    }
    if humans:
        spread = [[20.0, 20.0 + 2 * i] for i in range(humans)]  # moved by hand after reset
        document["humans"] = {
            "count": humans, "radius": RADIUS, "preferred_speed": [SPEED, SPEED], "on_goal": "stop",
            "spawn": [{"type": "points", "points": spread}], "goal": [{"type": "points", "points": spread}],
        }
    return document


def start(sim: Simulator, robot: complex, goal: complex, human: complex | None = None, human_velocity: complex = 0j) -> None:
    """Reset, then put the robot (heading +x) and the human where the run wants them.

    A walking human's goal lies far along its velocity, so it keeps walking straight at 1 m/s (it
    does not see the robot); a standing human's goal is its own position, where it stops.
    """
    sim.reset(seed=0)
    sim.positions[0], sim.robot_goal, sim.robot_heading = robot, goal, 0.0
    sim.velocities[:] = 0
    if human is not None:
        sim.positions[1] = human
        sim.velocities[1] = human_velocity
        sim.human_goals[0] = human + 30 * human_velocity if human_velocity else human
    sim.refresh()


@dataclass
class Run:
    """A scripted run scored under several weight sets at once."""

    rewards: dict[str, np.ndarray]
    """Weight-set name -> (T,) rewards."""
    socials: dict[str, np.ndarray]
    """Weight-set name -> (T,) social terms."""
    force: np.ndarray
    """(T,) |F_social| after each step."""
    along: np.ndarray
    """(T,) robot-human centre offset along x after each step (nan without a human)."""
    gap: np.ndarray
    """(T,) robot-human surface distance after each step (nan without a human)."""
    outcome: str


def play(sim: Simulator, weights: dict[str, RewardWeights], action: Callable[[int], np.ndarray], steps: int) -> Run:
    """Step ``action(t)`` until the episode ends or ``steps`` steps, scoring every weight set."""
    scorers = {name: Reward(w) for name, w in weights.items()}
    for scorer in scorers.values():
        scorer.reset(sim)
    rewards = {name: [] for name in weights}
    socials = {name: [] for name in weights}
    force, along, gap, outcome = [], [], [], "running"
    for t in range(steps):
        events = sim.step(action(t))
        for name, scorer in scorers.items():
            reward, terms = scorer(sim, events)
            rewards[name].append(reward)
            socials[name].append(terms["social"])
        force.append(abs(sim.robot_social_force))
        offset = sim.human_positions[0] - sim.robot_position if sim.n_humans else complex("nan")
        along.append(offset.real)
        gap.append(abs(offset) - 2 * RADIUS)
        if events.outcome is not None:
            outcome = events.outcome
            break
    arrays = {name: np.array(values) for name, values in rewards.items()}
    return Run(arrays, {name: np.array(values) for name, values in socials.items()}, np.array(force), np.array(along), np.array(gap), outcome)


# --------------------------------------------------------------------------- (a) passing


def encounter(weights: dict[str, RewardWeights], gap: float, walking: bool) -> Run:
    """The robot passes one human at closest surface distance ``gap``; they are abeam of each other at x = 0."""
    sim = Simulator(scenario(humans=1))
    human_speed = SPEED if walking else 0.0
    closing = (SPEED + human_speed) * sim.dt  # metres the x-offset shrinks per step
    steps_to_meet = round(ENCOUNTER_SPAN / closing)
    lateral = 2 * RADIUS + gap
    robot = complex(-SPEED * sim.dt * steps_to_meet, 0.0)
    human = complex(human_speed * sim.dt * steps_to_meet, lateral)
    start(sim, robot, goal=complex(35.0, 0.0), human=human, human_velocity=complex(-human_speed, 0.0))
    return play(sim, weights, lambda t: FORWARD, 2 * steps_to_meet)


def encounter_rows(weights: dict[str, RewardWeights]) -> tuple[list[str], list[list[str]]]:
    header = ["human", "closest gap (m)", "steps in pass", "force peak / sum"]
    for name in weights:
        header += [f"{name}: social per step min / median / max", f"{name}: sum per pass"]
    rows = []
    for walking in (True, False):
        for gap in GAPS:
            run = encounter(weights, gap, walking)
            window = np.abs(run.along) <= PASS_WINDOW + 1e-9
            row = ["walking towards the robot, 1 m/s" if walking else "standing", number(run.gap.min()), str(int(window.sum())),
                   f"{number(run.force.max())} / {number(run.force.sum())}"]
            for name in weights:
                social = run.socials[name][window]
                row += [" / ".join(number(v) for v in (social.min(), float(np.median(social)), social.max())),
                        number(run.socials[name].sum())]
            rows.append(row)
    return header, rows


# -------------------------------------------------------------------------- (b) outcomes


def outcome_runs(weights: dict[str, RewardWeights]) -> list[tuple[str, Run]]:
    """(description, run) of every scripted outcome."""
    goal = complex(GOAL_DISTANCE, 0.0)
    runs = []

    sim = Simulator(scenario())
    start(sim, 0j, goal)
    runs.append((f"reach: straight to the goal {GOAL_DISTANCE:g} m away", play(sim, weights, lambda t: FORWARD, 150)))

    # abeam of each other after 15 steps (3 m), 0.5 m apart (surfaces)
    sim = Simulator(scenario(humans=1))
    start(sim, 0j, goal, human=complex(3.0 + 15 * SPEED * sim.dt, 2 * RADIUS + 0.5), human_velocity=complex(-SPEED, 0.0))
    runs.append(("reach, passing a person walking the other way at 0.5 m", play(sim, weights, lambda t: FORWARD, 150)))

    # the robot's surface meets the wall's face (x = 3.25) during step 15, centre at x = 3.0
    sim = Simulator(scenario(walls=[((3.3, -3.0), (3.3, 3.0))]))
    start(sim, 0j, goal)
    runs.append(("collide: a wall, after 3 m of progress", play(sim, weights, lambda t: FORWARD, 150)))

    sim = Simulator(scenario(humans=1))
    start(sim, 0j, goal, human=complex(3.0 + 2 * RADIUS - 0.05, 0.0))
    runs.append(("collide: a person standing in the way, after 3 m", play(sim, weights, lambda t: FORWARD, 150)))

    sim = Simulator(scenario())
    start(sim, 0j, goal)
    runs.append(("time out: stand still for 150 steps", play(sim, weights, lambda t: STILL, 150)))

    sim = Simulator(scenario())
    start(sim, 0j, goal)
    runs.append(("wander: drive away from the goal for 150 steps (30 m)", play(sim, weights, lambda t: BACKWARD, 150)))

    # an open world's edge 5 m behind the robot: leaving it ends the episode (out_of_bounds)
    sim = Simulator(scenario(behind=5.0))
    start(sim, 0j, goal)
    runs.append(("leave: drive away from the goal out of an open world 5 m behind", play(sim, weights, lambda t: BACKWARD, 150)))
    return runs


def discounted(rewards: np.ndarray, gamma: float) -> float:
    return float((rewards * gamma ** np.arange(len(rewards))).sum())


def outcome_rows(weights: dict[str, RewardWeights], gammas: Sequence[float]) -> tuple[list[str], list[list[str]]]:
    header = ["episode", "outcome", "steps"] + [f"{name}: gamma {gamma:g}" for name in weights for gamma in gammas]
    rows = []
    for description, run in outcome_runs(weights):
        steps = len(run.force)
        rows.append([description, run.outcome, str(steps)]
                    + [number(discounted(run.rewards[name], gamma)) for name in weights for gamma in gammas])
    return header, rows


# ------------------------------------------------------------------------------- output


def number(value: float) -> str:
    """Three significant digits, without exponents above 1e-4."""
    if abs(value) >= 1000:
        return f"{value:.0f}"
    text = f"{value:.3g}"
    return "0" if text in ("0", "-0") else text


def markdown(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def weight_sets(args: argparse.Namespace) -> dict[str, RewardWeights]:
    """Every preset, plus ``custom`` when ``--reward`` or ``--reward-weight`` is given."""
    sets = {name: RewardWeights(preset=name) for name in REWARD_PRESETS}
    custom = reward_options(args)
    if custom:
        sets["custom"] = RewardWeights(**custom)
    return sets


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--gammas", type=float, nargs="+", default=[0.95, 0.99], metavar="GAMMA", help="discount factors of table (b)")
    add_reward_options(parser)
    args = parser.parse_args(argv)
    weights = weight_sets(args)
    print("Weights:\n")
    terms = list(next(iter(weights.values())).terms)
    print(markdown(["weights", *terms], [[name, *(number(w.terms[t]) for t in terms)] for name, w in weights.items()]))
    print("\n(a) Social term while the robot (1 m/s) passes one human; gap = closest surface distance (centre distance - 0.6 m);"
          " force = |F_social|, the humans' social force on the robot:\n")
    print(markdown(*encounter_rows(weights)))
    print(f"\n(b) Discounted return sum_t gamma^t r_t of scripted episodes (goal {GOAL_DISTANCE:g} m ahead, 1 m/s, dt 0.2 s, 150 steps):\n")
    print(markdown(*outcome_rows(weights, args.gammas)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
