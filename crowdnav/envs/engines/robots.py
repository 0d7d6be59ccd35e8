"""Every robot of a ``robots:`` scenario driven by the caller, ``num_worlds`` worlds at once: the robots-only engines.

The robots-only PettingZoo env (``crowdnav.parallel_env(..., humans_as_agents=False, fixed_agents=True,
flat_observations=True)``, :class:`crowdnav.envs.parallel.CrowdNavParallelEnv`) is one world in which every robot is an
agent: each acts, is observed in its own frame (a flat float32 vector), is rewarded and ends on its own; a robot that
ended leaves the world (parked, no longer seen) and its agent stays, inactive, until the episode ends (every robot
ended, or the time limit while some robot runs). A :class:`crowdnav.envs.engines.protocol.RobotsEngine` plays ``num_worlds`` such
worlds with arrays: actions (W, R, 2), observations (W, R, D), and a :class:`crowdnav.envs.engines.protocol.RobotsStep` of per-robot
arrays. Two implement it, world ``i`` reset with seed ``s`` playing the env's episode after ``reset(seed=s)`` bit for
bit in both:

* :class:`crowdnav.envs.engines.stacked_robots.StackedRobots`: the worlds stacked in one
  :class:`crowdnav.batch.simulator.BatchSimulator` (array work over the worlds; loops over robots and crowd sizes);
* :class:`SingleRobots`: one robots-only env per world, for what the stack does not play (crowds of
  ``Simulator.grid_from`` humans or more, crowd models other than the social force, a shield, a residual plan).

:func:`robots_engine` chooses once. Robot ``k`` is the scenario's ``robots.<k>`` (``robot_names`` order). Both also play
scripted robots (:class:`ScriptedRobotsEngine`): the stacked engine those with a batched twin (straight, social force),
the per-world one any, called with each robot's view of its world's simulator. A world's state taken by either loads
into either (:mod:`crowdnav.envs.engines.robots_state`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol

import numpy as np
from gymnasium import spaces

from crowdnav.envs.core import load_env_world, option_overrides
from crowdnav.envs.engines.protocol import RobotsEngine, RobotsFrame, RobotsStep
from crowdnav.envs.engines.robots_state import robots_rows, robots_state
from crowdnav.envs.engines.stacked_robots import StackedRobots
from crowdnav.envs.engines.world_state import WorldState
from crowdnav.sensors.tracker import make_tracker
from crowdnav.sim.simulator import Simulator
from crowdnav.worlds.compiled import CompiledWorld


class ScriptedRobotsEngine(RobotsEngine, Protocol):
    """A :class:`crowdnav.envs.engines.protocol.RobotsEngine` whose robots a scripted policy can drive."""

    def scripted_actions(self, policy: Any, robots: np.ndarray) -> np.ndarray:
        """(W, R, 2) float32: scripted ``policy``'s action (:data:`crowdnav.planning.scripted.ScriptedPolicy`) for each of ``robots``
        ((W, R) bool: robots in their world), as ``policy`` returns it called with that robot's view of its world after the
        last step (``simulator.robot_view(k)``, the robots that ended there gone); 0 elsewhere. Call it after :meth:`observe`."""


def robots_world(options: Mapping[str, Any]) -> CompiledWorld:
    """The compiled world of the env options ``options`` (scenario, modalities, sensors, reward weights, overrides)."""
    overrides = option_overrides(options.get("modalities"), options.get("sensors"), options.get("reward_weights"), options.get("overrides"))
    world, _ = load_env_world(options.get("scenario"), overrides)
    return world


def stacks_robots(world: CompiledWorld, options: Mapping[str, Any]) -> bool:
    """Whether :class:`StackedRobots` plays ``world``'s robots as the robots-only env (else :class:`SingleRobots`): crowds
    below ``Simulator.grid_from`` walking by the social force alone (a view of stacked worlds lists the first robot only to
    the other models), no people tracker, no shield, residual plan or rendering (the env applies them per world)."""
    scenario = world.scenario
    models = {group.model for _, group in scenario.humans.crowd if not group.standing and group.model is not None}
    plain = not options.get("shield") and not options.get("residual") and options.get("render_mode") is None
    return (scenario.robots is not None and scenario.humans.max_count < Simulator.grid_from and models <= {"social_force"}
            and make_tracker(world, 1) is None and plain)


def robots_engine(options: Mapping[str, Any], num_worlds: int) -> ScriptedRobotsEngine:
    """The engine of ``num_worlds`` worlds of the robots-only env of ``options`` (:func:`stacks_robots` chooses which)."""
    world = robots_world(options)
    if stacks_robots(world, options):
        return StackedRobots(world, num_worlds)
    return SingleRobots(options, num_worlds)


class SingleRobots:
    """One robots-only PettingZoo env per world, stepped in one call (a loop over worlds: the engine for what does not stack)."""

    def __init__(self, options: Mapping[str, Any], num_worlds: int):
        from crowdnav.envs import parallel_env

        self.envs = [parallel_env(**options, humans_as_agents=False, fixed_agents=True, flat_observations=True) for _ in range(num_worlds)]
        self.num_worlds = num_worlds
        self.robot_names: list[str] = list(self.envs[0].core.robot_names)
        sizes = {int(spaces.flatdim(self.envs[0].observation_space(name))) for name in self.robot_names}
        if len(sizes) != 1:
            raise ValueError(f"the robots observe vectors of different lengths {sorted(sizes)}; a batch of robots needs one length")
        self.observation_size = sizes.pop()
        self._observations = np.zeros((num_worlds, len(self.robot_names), self.observation_size), np.float32)

    def reset(self, worlds: Sequence[int] | np.ndarray, seeds: Sequence[int | None]) -> None:
        for world, seed in zip(worlds, seeds, strict=True):
            observed, _ = self.envs[int(world)].reset(seed=seed)
            self._observations[int(world)] = [observed[name] for name in self.robot_names]

    def step(self, actions: np.ndarray, active: np.ndarray | None = None) -> RobotsStep:
        w, r = self.num_worlds, len(self.robot_names)
        step = RobotsStep(np.zeros((w, r), bool), np.zeros((w, r)), {}, np.full((w, r), None, object), {},
                          np.zeros(w, bool), np.zeros(w, bool))
        for world in range(w) if active is None else np.flatnonzero(active).tolist():
            env = self.envs[world]
            observed, rewards, terminations, truncations, infos = env.step(
                {name: actions[world, k] for k, name in enumerate(self.robot_names)})
            for k, (name, events) in enumerate(zip(self.robot_names, env.simulator.robot_events, strict=True)):
                info = infos[name]
                self._observations[world, k] = observed[name]
                step.stepped[world, k] = info["active"]
                step.rewards[world, k] = rewards[name]
                step.outcome[world, k] = info.get("outcome")
                for term, value in info.get("reward_terms", {}).items():
                    step.terms.setdefault(term, np.zeros((w, r)))[world, k] = value
                if events is not None and events.collision is not None and info.get("outcome") == "collision":
                    step.collisions[world, k] = events.collision
            step.truncated[world] = all(truncations.values())
            step.over[world] = all(terminations[name] or truncations[name] for name in self.robot_names)
        return step

    def observe(self) -> np.ndarray:
        observations: np.ndarray = self._observations.copy()
        return observations

    def scripted_actions(self, policy: Any, robots: np.ndarray) -> np.ndarray:
        """Any scripted policy: called robot by robot with its view of its world's simulator (the ended robots left at the step's end)."""
        actions = np.zeros((self.num_worlds, len(self.robot_names), 2), np.float32)
        for world, k in np.argwhere(robots).tolist():
            actions[world, k] = np.asarray(policy(self.envs[world].simulator.robot_view(k)), np.float32)
        return actions

    def frame(self) -> RobotsFrame:
        w, r = self.num_worlds, len(self.robot_names)
        sims = [env.simulator for env in self.envs]
        crowd = np.array([len(sim.positions) - 1 for sim in sims], dtype=np.int64)
        frame = RobotsFrame(np.zeros((w, r), complex), np.zeros((w, r), complex), np.zeros((w, r)),
                            np.full((w, int(crowd.max(initial=0))), complex(np.nan, np.nan)), crowd, np.zeros(w, dtype=np.int64))
        for world, sim in enumerate(sims):  # the per-world engine: its simulators read one by one
            team = sim.team
            assert team is not None  # a robots: scenario's
            frame.robots[world] = [sim.positions[0], *team.state.positions]
            frame.goals[world] = [sim.robot_goal, *team.state.goals]
            force = np.array([sim.robot_social_force, *team.social])
            frame.social_force[world] = np.hypot(force.real, force.imag)  # abs(complex): libm's hypot
            frame.humans[world, : crowd[world]] = sim.positions[1:]
            frame.stalls[world] = sim.human_stalls.sum()
        return frame

    def radii(self, world: int) -> tuple[np.ndarray, np.ndarray]:
        sim = self.envs[world].simulator
        assert sim.team is not None  # a robots: scenario's
        return sim.team.all_radii.copy(), sim.radii[1:].copy()

    def snapshot(self, world: int) -> WorldState:
        env = self.envs[world]
        return robots_state(env.core.snapshot({}), bool(env.agents), self._observations[world], self.robot_names)

    def load(self, world: int, state: WorldState) -> None:
        env = self.envs[world]
        state, rows = robots_rows(state, env.core.world_key, self.robot_names, self.observation_size)
        env.core.load(state)  # the simulator, every robot's reward memory, the tracker, whether the episode runs
        env.loaded_robots(state.env is not None and state.env.running)  # the env's own episode bookkeeping
        self._observations[world] = rows

    def close(self) -> None:
        for env in self.envs:
            env.close()
