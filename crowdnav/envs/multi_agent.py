"""Multi-agent plumbing of the ParallelEnv: global state, flat observations, human rewards and exits.

**Global state** (``env.state()``, for centralised critics): a float32 vector of ``(R + N) * 8``
values, R the scenario's robots (1 without ``robots:``) and N its maximum crowd size, read as a
table of ``R + N`` rows (rows 0..R-1 the robots, row ``R + i`` human ``i``; rows of humans absent
this episode, of robots that left and of a recorded crowd's empty places are zero) by the columns of
:data:`STATE_COLUMNS`, world frame, metres and m/s:

==========  ===============================================================
column      meaning
==========  ===============================================================
``x, y``    centre
``vx, vy``  velocity
``gx, gy``  goal (the robot's goal, or the human's current goal)
``radius``  body radius
``active``  1 for the robot and this episode's humans (also after they left
            ``agents``), 0 for padding
==========  ===============================================================

**Flat observations** (``flat_observations=True``): every agent's Dict observation becomes one
float32 Box, in the order of :func:`gymnasium.spaces.flatten_space` (the Dict's keys in order,
each array row-major), so SuperSuit's wrappers and MARL libraries that take Box spaces work.
With a crowd-size range or ``human_exit``, SuperSuit's ``pettingzoo_env_to_vec_env_v1`` also
needs the env's ``fixed_agents=True`` (every possible human an agent every step, the inactive
ones flagged and zero).

**Human rewards and exits** are pluggable: ``human_reward(simulator) -> (n,) floats`` and
``human_exit(simulator) -> (n,) bools``, called after each step on the episode's ``n`` humans.
A human whose exit is True is terminated (it leaves ``agents``) and stands still from then on,
an obstacle for the others. :func:`goal_reward` (+1 on reaching a goal) and :func:`exit_at_goal`
are the documented examples; by default humans get 0 and stay until the episode ends.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import cast

import numpy as np
from gymnasium import spaces

from crowdnav.crowd.replay import empty_places
from crowdnav.errors import CrowdNavError
from crowdnav.sim.simulator import Simulator
from crowdnav.suggest import did_you_mean

STATE_COLUMNS = ("x", "y", "vx", "vy", "gx", "gy", "radius", "active")

HumanReward = Callable[[Simulator], np.ndarray]
"""``(simulator) -> (n_humans,)`` rewards of the episode's humans after a step."""
HumanExit = Callable[[Simulator], np.ndarray]
"""``(simulator) -> (n_humans,)`` booleans: True terminates that human (it stands still from then on)."""


def state_space(max_humans: int, robots: int = 1) -> spaces.Box:
    """The Box of :func:`global_state` (unbounded: an open world's robot may step past its edge)."""
    low = np.full((robots + max_humans, len(STATE_COLUMNS)), -np.inf, dtype=np.float32)
    high = np.full_like(low, np.inf)
    low[:, 6:] = 0.0
    high[:, 7] = 1.0
    return spaces.Box(low.reshape(-1), high.reshape(-1), dtype=np.float32)


def global_state(sim: Simulator, max_humans: int) -> np.ndarray:
    """The state table of the module docstring, flattened row by row."""
    n = sim.n_humans
    if sim.team is not None:
        return _several_robots_state(sim, max_humans)
    table = np.zeros((1 + max_humans, len(STATE_COLUMNS)), dtype=np.float32)
    rows = table[: 1 + n]
    rows[:, 0], rows[:, 1] = sim.positions.real, sim.positions.imag
    rows[:, 2], rows[:, 3] = sim.velocities.real, sim.velocities.imag
    goals = np.concatenate([[sim.robot_goal], sim.human_goals])
    rows[:, 4], rows[:, 5] = goals.real, goals.imag
    rows[:, 6] = sim.radii[: 1 + n]
    rows[:, 7] = 1.0
    rows[1:][empty_places(sim.human_positions)] = 0.0  # nobody there: no 20,000 km coordinate in a critic's input
    return table.reshape(-1)


def _several_robots_state(sim: Simulator, max_humans: int) -> np.ndarray:
    """:func:`global_state` with R robots: R robot rows first (a robot that left: all zero), then the humans."""
    team, n = sim.team, sim.n_humans
    assert team is not None  # several robots
    robots = team.count
    table = np.zeros((robots + max_humans, len(STATE_COLUMNS)), dtype=np.float32)
    active = team.state.active
    positions = np.concatenate([sim.robot_positions, sim.human_positions])
    velocities = np.concatenate([sim.velocities[:1], team.state.velocities, sim.human_velocities])
    goals = np.concatenate([sim.robot_goals, sim.human_goals])
    rows = table[: robots + n]
    rows[:, 0], rows[:, 1] = positions.real, positions.imag
    rows[:, 2], rows[:, 3] = velocities.real, velocities.imag
    rows[:, 4], rows[:, 5] = goals.real, goals.imag
    rows[:, 6] = np.concatenate([team.all_radii, sim.radii[1:]])
    rows[:, 7] = 1.0
    table[:robots][~active] = 0.0
    rows[robots:][empty_places(sim.human_positions)] = 0.0  # a recorded crowd's empty place: nobody there
    return table.reshape(-1)


def goal_reward(sim: Simulator) -> np.ndarray:
    """Example human reward: +1 on the step a human reaches its goal, 0 otherwise."""
    return sim.human_arrived.astype(np.float64)


def exit_at_goal(sim: Simulator) -> np.ndarray:
    """Example human exit: a human leaves the episode when it reaches its goal."""
    leaving: np.ndarray = sim.human_arrived.copy()  # (numpy types copy() of an unknown shape as Any)
    return leaving


def flat_spaces(observation_spaces: Mapping[str, spaces.Dict]) -> dict[str, spaces.Box]:
    """Each agent's Dict space as the flat Box of :func:`gymnasium.spaces.flatten_space`."""
    # a Dict of Boxes flattens to a Box (flatten_space is typed for any space)
    return {agent: cast(spaces.Box, spaces.flatten_space(space)) for agent, space in observation_spaces.items()}


def flatten_batch(space: spaces.Dict, batch: Mapping[str, np.ndarray], n: int) -> np.ndarray:
    """(n, flat size) rows of ``n`` agents' Dict observations stacked per key, in flatten_space order.

    One concatenation for all humans instead of one ``spaces.flatten`` call per human.
    """
    return np.concatenate([np.asarray(batch[key], dtype=np.float32).reshape(n, -1) for key in space.spaces], axis=1)


class UnknownAgentError(CrowdNavError, KeyError):
    """An agent name the env does not have: a KeyError, as the dict lookup it replaces, with a one-line message."""

    def __str__(self) -> str:  # KeyError would show the message quoted
        return str(self.args[0]) if self.args else ""


def unknown_agent(name: object, valid: Sequence[str]) -> UnknownAgentError:
    """``unknown agent 'robot'; did you mean 'robot_0'? the agents are: robot_0, robot_1, human_0 .. human_9``."""
    return UnknownAgentError(f"unknown agent {name!r}{did_you_mean(name, valid) or ';'} the agents are: {agent_list(valid)}")


def agent_list(names: Sequence[str]) -> str:
    """Agent names for a message: the robots by name, each run of consecutive humans as ``human_0 .. human_9``."""
    out: list[str] = []
    run: list[int] = []
    for name in [*names, ""]:  # "" flushes the last run
        number = name[len("human_") :] if name.startswith("human_") else ""
        if number.isdigit() and (not run or int(number) == run[-1] + 1):
            run.append(int(number))
            continue
        if run:
            out.extend([f"human_{i}" for i in run] if len(run) <= 2 else [f"human_{run[0]} .. human_{run[-1]}"])
            run = []
        if number.isdigit():
            run = [int(number)]
        elif name:
            out.append(name)
    return ", ".join(out) or "none"
