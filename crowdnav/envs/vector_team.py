"""Several-robot worlds in the native vector env: :class:`TeamWorlds`, a group of per-world simulators stepped in one call.

A scenario with ``robots:`` puts the robots after the first in each world's :class:`crowdnav.robots.Team`,
whose per-robot work (each robot's kinematics, scripted policy, outcome and retirement) is not
stacked across worlds by :class:`crowdnav.batch.simulator.BatchSimulator`. For such a scenario
:class:`crowdnav.envs.vector.CrowdNavVectorEnv` holds its worlds here instead: one
:class:`crowdnav.envs.single.CrowdNavEnv` per world (its own :class:`crowdnav.Simulator`, the other
robots' policies, the first robot's sensors and reward), all stepped by one :meth:`TeamWorlds.step`
call. Each world's step is the single env's own, so world ``i`` plays the single env's episodes bit
for bit by construction; the vector env keeps everything around it (autoreset modes, episode seeds,
reset masks, the infos' layout, SB3's adapter, a training resume) as it is for one-robot worlds.
Inside a world nothing loops over humans (the simulator's step is array work); the loop is over
worlds, so a step of K worlds costs about K single steps (docs/environments.md#several-robots
measures it).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from crowdnav.batch.simulator import StepResult
from crowdnav.envs.single import CrowdNavEnv
from crowdnav.sensors import Modality
from crowdnav.simulator import Simulator
from crowdnav.world import CompiledWorld


class TeamWorlds:
    """``num_worlds`` single envs of one several-robot world, reset and stepped as a batch (the vector env's engine).

    ``world``: the compiled scenario with every env option applied (sensors, reward weights, overrides);
    ``other_robots``: the single env's option (a policy name, or a callable / class; a class is made per
    robot of each world). After :meth:`reset` / :meth:`step`, ``observations[i]`` is world i's last
    observation, and for the worlds that stepped ``rewards``, ``terms`` and ``other_robots[i]`` its reward,
    reward terms and ``info["other_robots"]``.
    """

    def __init__(self, world: CompiledWorld, num_worlds: int, other_robots: str | Callable[..., Any] = "social-force"):
        self.num_worlds = int(num_worlds)
        # the compiled scenario already holds every option (load_env_world applied them): each env loads it as it is
        self.envs = [CrowdNavEnv(world.scenario, other_robots=other_robots) for _ in range(self.num_worlds)]
        first = self.envs[0]
        self.modalities: dict[str, Modality] = first.core.modalities
        """The first robot's modalities (``robots.0.modalities`` or ``sensors.modalities``), the vector env's observation keys."""
        self.observations: list[dict[str, np.ndarray]] = [{} for _ in range(self.num_worlds)]
        self.rewards = np.zeros(self.num_worlds)
        self.terms: list[dict[str, float]] = [{} for _ in range(self.num_worlds)]
        self.other_robots: list[dict[str, str | None]] = [{} for _ in range(self.num_worlds)]

    def reset(self, worlds: Sequence[int] | np.ndarray, seeds: Sequence[int | None] | np.ndarray) -> None:
        """Start a new episode in each of ``worlds`` (``seeds[k]`` for ``worlds[k]``; None continues its generator)."""
        for world, seed in zip(worlds, seeds, strict=True):
            self.observations[int(world)], _ = self.envs[int(world)].reset(seed=None if seed is None else int(seed))

    def step(self, actions: np.ndarray, active: np.ndarray | None = None) -> StepResult:
        """Step every world (or those of the bool mask ``active``) with its row of ``actions`` ((num_worlds, 2))."""
        b = self.num_worlds
        result = StepResult(goal_reached=np.zeros(b, dtype=bool), left_world=np.zeros(b, dtype=bool), truncated=np.zeros(b, dtype=bool))
        worlds = range(b) if active is None else np.flatnonzero(active)
        for i in worlds:  # per world: the single env's step (its simulator steps every agent as arrays)
            i = int(i)
            env = self.envs[i]
            self.observations[i], self.rewards[i], _, _, info = env.step(actions[i])
            events = env.simulator.robot_events[0]  # the first robot's: it is in the world until its episode ends
            assert events is not None
            result.goal_reached[i], result.left_world[i], result.truncated[i] = events.goal_reached, events.left_world, events.truncated
            if events.collision is not None:
                result.collisions[i] = events.collision
            self.terms[i] = info["reward_terms"]
            self.other_robots[i] = info["other_robots"]
        return result

    def simulators(self) -> list[Simulator]:
        """Each world's simulator (live: read it, do not step it)."""
        return [env.simulator for env in self.envs]

    def goal_distance(self) -> np.ndarray:
        """(num_worlds,) the first robot's goal distance in each world."""
        return np.array([sim.robot_goal_distance for sim in self.simulators()], dtype=float)

    def social_force(self) -> np.ndarray:
        """(num_worlds,) complex: the humans' social-force repulsion on each world's first robot."""
        return np.array([sim.robot_social_force for sim in self.simulators()], dtype=complex)

    def stalls(self) -> np.ndarray:
        """(num_worlds,) int64: how many times a human stalled this episode, per world."""
        return np.array([int(sim.human_stalls.sum()) for sim in self.simulators()], dtype=np.int64)

    def row(self, name: str, world: int) -> np.ndarray:
        """A copy of world ``world``'s simulator array ``name`` (``positions``: the first robot then the humans)."""
        values: np.ndarray = np.array(getattr(self.envs[world].simulator, name), copy=True)
        return values

    def simulator(self, world: int) -> Simulator:
        """A snapshot of ``world``'s simulator (:meth:`crowdnav.Simulator.clone`): stepping it leaves the world as it is."""
        return self.envs[world].simulator.clone()
