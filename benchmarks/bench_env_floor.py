"""The single env side by side with its numpy floor: what the env layer costs per step.

    python benchmarks/bench_env.py --floor [--scenarios room_furniture open_space] [--steps 3000] [--repeats 5] [--clock cpu]

The floor is the same work done directly on the env's own simulator, sensors and reward, with
no env layer: per step the action check, ``Simulator.step``, every modality's ``observe()`` into
the observation dict, the reward and the info the env returns (reward terms, outcome,
``is_success``, ``human_stalls``); at an episode's end the simulator and reward resets and the
reset observation. It replays the env's action sequence and yields what the env returns, checked
equal bit for bit before timing (:func:`check_floor`). ``ratio`` = floor s/step / env s/step: 1.0x
means the env adds nothing. ``gym.make`` is the same env behind Gymnasium's default wrappers
(order enforcing, passive checker). Each case is timed with one clock around its whole loop,
interleaved repeat by repeat (every case sees the same machine load); medians over the repeats.

Modality sets: ``default`` (the scenario's own ``sensors.modalities``) and ``all`` (every
modality, 360-beam LIDAR, 60x60 LEOG, as in the main benchmark).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any

import gymnasium as gym
import numpy as np

from crowdnav.envs import CrowdNavEnv
from crowdnav.envs.core import checked_robot_action, step_info
from crowdnav.envs.registration import env_id

ALL_MODALITIES = ["goal", "closest_obstacle", "lidar", "leog", "velocity", "humans"]
ALL_SENSORS = {"lidar": {"beams": 360}, "leog": {"size": 6.0, "resolution": 0.1}}

Step = tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]


def floor_steps(env: CrowdNavEnv, actions: np.ndarray, seed: int) -> Iterator[Step]:
    """The env's episodes from ``env.reset(seed=seed)`` replayed on its own parts: each step's (observation, reward, terminated, truncated, info)."""
    core = env.core
    if core.simulator.team is not None:
        raise ValueError("the floor replays one robot's episodes; a several-robot scenario is not supported")
    sim, reward = core.simulator, core.reward
    sensors = [(key, core.modalities[key]) for key in env.observation_space.spaces]
    sim.reset(seed=seed)
    reward.reset(sim)
    observation = {key: modality.observe(sim) for key, modality in sensors}
    for action in actions:
        events = sim.step(checked_robot_action(action))
        observation = {key: modality.observe(sim) for key, modality in sensors}
        value, terms = reward(sim, events)
        info = step_info(events, terms)
        info["human_stalls"] = int(np.add.reduce(sim.human_stalls))  # as the env sums them
        terminated = events.terminated
        if not terminated:
            info["outcome"], info["is_success"] = "truncated", False
        yield observation, value, terminated, events.truncated and not terminated, info
        if terminated or events.truncated:
            sim.reset()
            reward.reset(sim)
            observation = {key: modality.observe(sim) for key, modality in sensors}


def env_steps(env: gym.Env, actions: np.ndarray, seed: int) -> Iterator[Step]:
    """The env's own steps for ``actions`` from ``reset(seed=seed)``, reset at each episode's end."""
    env.reset(seed=seed)
    for action in actions:
        result = env.step(action)
        yield result
        if result[2] or result[3]:
            env.reset()


def check_floor(env: CrowdNavEnv, actions: np.ndarray, seed: int) -> None:
    """Raise AssertionError unless the floor returns what the env returns, bit for bit, step by step."""
    # one after the other (they share the simulator), each step's arrays copied in case a later step reuses them
    runs = [[({k: v.copy() for k, v in step[0].items()}, *step[1:]) for step in steps(env, actions, seed)]
            for steps in (env_steps, floor_steps)]
    for t, (ours, theirs) in enumerate(zip(*runs, strict=True)):
        same = (ours[0].keys() == theirs[0].keys() and all(a.dtype == b.dtype and a.tobytes() == b.tobytes()
                                                           for a, b in zip(ours[0].values(), theirs[0].values(), strict=True))
                and repr(ours[1:]) == repr(theirs[1:]))
        if not same:
            raise AssertionError(f"step {t}: the floor differs from the env:\n{ours[1:]}\n{theirs[1:]}")


CLOCK: Callable[[], float] = time.perf_counter


def seconds_per_step(steps: Iterator[Step], count: int) -> float:
    """Run ``steps`` to the end under one clock."""
    start = CLOCK()
    for _ in steps:
        pass
    return (CLOCK() - start) / count


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--floor", action="store_true", help="(how bench_env.py hands over)")
    parser.add_argument("--scenarios", nargs="+", default=["room_furniture", "open_space"])
    parser.add_argument("--modalities", nargs="+", default=["default", "all"], choices=["default", "all"])
    parser.add_argument("--steps", type=int, default=3000, help="timed env steps per repeat")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--clock", choices=["wall", "cpu"], default="wall", help="cpu: the process's CPU time (a loaded machine)")
    args = parser.parse_args(argv)
    global CLOCK
    CLOCK = time.process_time if args.clock == "cpu" else time.perf_counter
    print("$ python " + " ".join(sys.argv))
    print(f"# {args.steps} steps x {args.repeats} repeats (median, {args.clock} clock), Python {platform.python_version()}, numpy {np.__version__}, "
          f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"{'scenario':>15} {'modalities':>10} {'floor us/step':>14} {'env us/step':>12} {'ratio':>6} "
          f"{'gym.make us/step':>17} {'ratio':>6}")
    for scenario in args.scenarios:
        for which in args.modalities:
            options: dict[str, Any] = {"modalities": ALL_MODALITIES, "sensors": ALL_SENSORS} if which == "all" else {}
            env = CrowdNavEnv(scenario, **options)
            wrapped = gym.make(env_id(scenario), **options)
            actions = [np.random.default_rng(seed).uniform(-1, 1, size=(args.steps, 2)).astype(np.float32) for seed in range(args.repeats)]
            check_floor(env, actions[0][:500], 0)
            times: dict[str, list[float]] = {"floor": [], "env": [], "gym.make": []}
            for seed in range(args.repeats):  # interleaved, the order turned each repeat
                cases = [("floor", floor_steps(env, actions[seed], seed)), ("env", env_steps(env, actions[seed], seed)),
                         ("gym.make", env_steps(wrapped, actions[seed], seed))]  # generators: nothing runs before it is timed
                for name, steps in cases[seed % 3:] + cases[:seed % 3]:
                    times[name].append(seconds_per_step(steps, args.steps))
            us = {name: statistics.median(values) * 1e6 for name, values in times.items()}
            print(f"{scenario:>15} {which:>10} {us['floor']:>14.1f} {us['env']:>12.1f} {us['floor'] / us['env']:>5.3f}x "
                  f"{us['gym.make']:>17.1f} {us['floor'] / us['gym.make']:>5.3f}x")
            env.close()
            wrapped.close()


if __name__ == "__main__":
    main()
