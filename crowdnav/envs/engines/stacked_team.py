"""Several robots per world, stacked: :class:`StackedTeamWorlds`, the vector env's engine for a ``robots:`` scenario.

The worlds' simulator is the one :class:`crowdnav.envs.engines.stacked.StackedWorlds` steps, whose
:class:`crowdnav.batch.simulator.BatchSimulator` holds every world's other robots (:mod:`crowdnav.batch.team`);
this engine adds what the single env (:class:`crowdnav.envs.single.CrowdNavEnv`) does around its simulator for
them, each as array work over the worlds: the other robots' actions from their scripted policy
(:mod:`crowdnav.batch.robot_policies`), their outcomes (``info["other_robots"]``), the robots that ended
leaving the world, the first robot's observation with the other robots in its range sensors (the worlds grouped
by which robots are still there: a view lists only those), their reward memories and the single env's part of a
world's state (:class:`crowdnav.envs.engines.world_state.EnvState`), so a snapshot loads into either engine or a single env.

A robot that ends leaves the world after the step's observation (the single env's ``finish_step``): here when
the next step starts (or a snapshot, a frame or a simulator is asked for), so every observation of the world
until then shows it, as the single env's last observation does.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from crowdnav.batch.bucket import Bucket
from crowdnav.batch.robot_policies import RobotPolicy
from crowdnav.batch.robot_views import robot_view
from crowdnav.batch.simulator import StepResult
from crowdnav.batch.state import BatchState
from crowdnav.batch.team import TeamStack
from crowdnav.envs.engines.protocol import with_team
from crowdnav.envs.engines.stacked import StackedWorlds
from crowdnav.envs.engines.world_state import EnvState, WorldState, check_state, make_state
from crowdnav.sensors import Modality, build_modalities
from crowdnav.sim.robots import TeamState
from crowdnav.sim.simulator import Simulator
from crowdnav.worlds.compiled import CompiledWorld


def first_robot_modalities(world: CompiledWorld) -> dict[str, Modality]:
    """The first robot's modalities (``robots.0.modalities``, default ``sensors.modalities``), as the single env builds them."""
    scenario, sensors = world.scenario, world.scenario.sensors
    own = getattr(scenario.robot_specs[0], "modalities", None)
    return build_modalities(own if own is not None else sensors.modalities, world, sensors)


class StackedTeamWorlds(StackedWorlds):
    """``num_worlds`` worlds of a ``robots:`` scenario in one batch, the other robots driven by ``policy`` (see the module docstring).

    ``modalities``: the first robot's (:func:`first_robot_modalities`). Implements :class:`crowdnav.envs.engines.protocol.WorldEngine`.
    """

    def __init__(self, world: CompiledWorld, num_worlds: int, modalities: dict[str, Modality], policy: RobotPolicy):
        super().__init__(world, num_worlds, modalities)
        assert self.batch.team is not None
        self.team: TeamStack = self.batch.team
        self._policy = policy
        m = len(self.team.specs)
        self._outcomes = np.full((self.num_worlds, m), None, dtype=object)
        """Each other robot's outcome so far this episode (None while it runs)."""
        self._leaving = np.zeros((self.num_worlds, m), dtype=bool)
        """Robots that ended at their world's last step and leave it before anything else happens there."""
        self._other_distance = np.zeros((self.num_worlds, m))
        """Each other robot's reward memory (its goal distance at reset: the single env rewards only the first robot)."""
        self._loaded: dict[int, dict[str, np.ndarray]] = {}
        """World -> the observation a loaded state carried, observed until the world steps or resets."""
        self._sees_robots = {key for key, modality in modalities.items() if modality.sees_robots}

    def reset(self, worlds: Sequence[int] | np.ndarray, seeds: Sequence[int | None] | np.ndarray) -> None:
        super().reset(worlds, seeds)
        worlds = np.asarray(worlds, dtype=np.int64)
        self._outcomes[worlds] = None
        self._leaving[worlds] = False
        gap = self.team.goals[worlds] - self.team.positions[worlds]
        self._other_distance[worlds] = np.hypot(gap.real, gap.imag)  # Reward.reset: abs(goal - position)
        restarted = set(worlds.tolist())
        for world in [world for world in self._loaded if world in restarted]:
            del self._loaded[world]

    def step(self, actions: np.ndarray, active: np.ndarray | None = None) -> StepResult:
        self._leave()
        located, ego = self._ego_positions()
        worlds = np.flatnonzero(located if active is None else located & active)  # (a world never reset or loaded has no robots)
        others = np.zeros((self.num_worlds, len(self.team.specs), 2))
        others[worlds] = self._policy(self.team, worlds, ego[worlds])
        result = self.batch.step(actions, active, others)
        team = self.team
        ended = team.ended[worlds]
        self._outcomes[worlds] = np.where(ended, team.outcome[worlds], self._outcomes[worlds])
        over = (result.terminated | result.truncated)[worlds]
        self._leaving[worlds] = ended & ~over[:, None]  # out of the world after this step's observation, unless the episode is over
        for world in [world for world in self._loaded if active is None or active[world]]:  # they observe their new state now
            del self._loaded[world]
        return result

    def _leave(self) -> None:
        """The robots that ended at the last step leave their worlds (the single env's ``retire_robots`` after its observation)."""
        if self._leaving.any():
            self.batch.retire(self._leaving)
            self._leaving[:] = False

    def _ego_positions(self) -> tuple[np.ndarray, np.ndarray]:
        """Which worlds hold an episode, and their first robots' positions (0 elsewhere)."""
        located, out = np.zeros(self.num_worlds, dtype=bool), np.zeros(self.num_worlds, dtype=complex)
        for bucket in self.batch.buckets.values():
            located[bucket.world], out[bucket.world] = True, bucket.state.positions[:, 0]
        return located, out

    def other_robots(self, stepping: np.ndarray) -> dict[int, dict[str, str | None]]:
        names = self.team.names[1:]
        return {int(i): dict(zip(names, self._outcomes[i], strict=True)) for i in np.flatnonzero(stepping)}

    # ------------------------------------------------------------------ observations

    def observe(self, out: Mapping[str, np.ndarray]) -> None:
        for bucket in self.batch.buckets.values():
            rows, size = np.arange(len(bucket)), self.batch.chunk_size(bucket.n)
            for start in range(0, len(rows), size):  # chunks of worlds, as the simulator steps them
                self._observe_rows(bucket, rows[start : start + size], out)
        for world, observation in self._loaded.items():
            for key, values in out.items():
                values[world] = observation[key]

    def _observe_rows(self, bucket: Bucket, rows: np.ndarray, out: Mapping[str, np.ndarray]) -> None:
        """The observations of ``rows`` of ``bucket`` (each row's depends on its world alone) into their worlds' rows of ``out``."""
        state = self.batch.state(bucket, rows)
        worlds = bucket.world[rows]
        for key, values in out.items():
            if key not in self._sees_robots:
                values[worlds] = self.modalities[key].observe_batch(state)
        if self._sees_robots & out.keys():
            self._observe_with_robots(state, worlds, out)

    def _observe_with_robots(self, state: BatchState, worlds: np.ndarray, out: Mapping[str, np.ndarray]) -> None:
        """The range sensors' readings of ``worlds`` (``state``: theirs), the other robots still in each world among the discs
        (:class:`crowdnav.sim.robot_view.RobotView` of the first robot), one call per set of robots present."""
        team = self.team
        others = team.active[worlds, 1:]
        patterns, which = np.unique(others, axis=0, return_inverse=True)
        which = which.reshape(-1)
        for p, pattern in enumerate(patterns):  # worlds whose views hold the same discs
            rows = np.flatnonzero(which == p)
            view = robot_view(state, team, worlds[rows], 0, np.flatnonzero(pattern) + 1, rows)
            for key in self._sees_robots & out.keys():
                out[key][worlds[rows]] = self.modalities[key].observe_batch(view)

    def _observation(self, world: int) -> dict[str, np.ndarray]:
        """``world``'s observation now (what :meth:`observe` writes for it)."""
        if world in self._loaded:
            return {key: values.copy() for key, values in self._loaded[world].items()}
        out = {key: np.zeros((self.num_worlds, *modality.space().shape), dtype=modality.space().dtype)
               for key, modality in self.modalities.items()}
        bucket, row = self.batch.locate(world)
        self._observe_rows(bucket, np.array([row]), out)
        return {key: values[world].copy() for key, values in out.items()}

    # ------------------------------------------------------------------ a world's state

    def _team_now(self, world: int) -> TeamState:
        """``world``'s other robots as the single env holds them after its step (the robots that ended gone)."""
        return self.team.state_of(world, self._leaving[world])

    def snapshot(self, world: int) -> WorldState:
        episode = dataclasses.replace(self.batch.snapshot(world), team=self._team_now(world))
        names = self.team.names[1:]
        env = EnvState(True, dict(zip(names, self._outcomes[world].tolist(), strict=True)), self._observation(world))
        rewards = (float(self._previous_distance[world]), *map(float, self._other_distance[world]))
        return make_state(self.world_key, episode, rewards, None, env)

    def load(self, world: int, state: WorldState) -> None:
        state = check_state(state, self.world_key)
        self.batch.load(world, state.episode)
        self._previous_distance[world], *others = state.rewards
        self._other_distance[world] = others
        self._leaving[world] = False
        env = state.env
        self._outcomes[world] = None if env is None else [env.other_outcomes[name] for name in self.team.names[1:]]
        if env is None:
            self._loaded.pop(world, None)
        else:
            self._loaded[world] = {key: values.copy() for key, values in env.observation.items()}

    def frame(self, world: int) -> dict[str, np.ndarray]:
        return with_team(super().frame(world), self._team_now(world))

    def simulator(self, world: int) -> Simulator:
        snapshot = self.batch.simulator(world)
        leaving = np.flatnonzero(self._leaving[world]) + 1
        if len(leaving):
            snapshot.retire_robots(leaving)
        return snapshot
