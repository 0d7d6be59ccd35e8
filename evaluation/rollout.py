"""Test episodes: run a deterministic policy on the held-out seeds and record what the metrics need.

The test episodes of one evaluation run side by side in lock-step, so the policy is called once
per step on the batch of the still-running episodes (one network forward for all of them). A
learned policy's episodes are the worlds of one native vector env
(:class:`crowdnav.envs.vector.CrowdNavVectorEnv`, stepped as one batch); a scripted policy, which
reads each episode's live simulator, plays one single env per seed. Both give the same episodes
bit for bit (world i of the batch is the single env seeded with seed i; tested). Nothing here
learns: the transitions go nowhere but into the trajectories.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from crowdnav.evaluation.metrics import Trajectory, episode_metrics

BatchPolicy = Callable[[Mapping[str, np.ndarray]], np.ndarray]
"""Observations stacked per key, shape (N, ...) -> actions (N, 2); :class:`agents.AgentPolicy` is one."""
ScriptedPolicy = Callable[[Any], np.ndarray]
"""A privileged robot policy: simulator -> action (2,), e.g. :class:`crowdnav.policies.StraightToGoal`."""


class HeldOutEpisodes:
    """The environments of the test episodes, built once and reused at every evaluation.

    ``env_options``: keyword arguments of :class:`crowdnav.envs.CrowdNavEnv` (the policy's
    :attr:`agents.AgentPolicy.env_options`); ``seeds``: the held-out episode seeds.
    """

    def __init__(self, env_options: Mapping[str, Any], seeds: Sequence[int]):
        self.env_options = dict(env_options)
        self.seeds = list(seeds)
        self._envs: list[Any] | None = None
        self._vector: Any = None

    @property
    def envs(self) -> list[Any]:
        """One single env per seed (built on first use: scripted policies, or ``batched=False``)."""
        if self._envs is None:
            from crowdnav.envs import CrowdNavEnv

            self._envs = [CrowdNavEnv(**self.env_options) for _ in self.seeds]
        return self._envs

    def run(self, policy: BatchPolicy | ScriptedPolicy, *, privileged: bool = False, record: bool = False,
            batched: bool = True) -> list[dict[str, Any]]:
        """Play one episode per seed with ``policy``; one dict per episode (seed order): outcome, return, metrics.

        ``privileged``: ``policy`` is a scripted robot policy (:mod:`crowdnav.policies`) called
        with each running episode's simulator instead of the stacked observations. ``record``:
        each dict also holds ``frames``, the episode's states step by step (see
        :mod:`crowdnav.evaluation.trajectories`). ``batched=False`` plays a learned policy's
        episodes on single envs too (the reference the batched run is tested against).
        """
        if batched and not privileged:
            return self._run_batched(policy, record)
        observations = [env.reset(seed=seed)[0] for env, seed in zip(self.envs, self.seeds, strict=True)]
        positions = [[env.simulator.positions.copy()] for env in self.envs]
        frames = [[_state(env.simulator)] for env in self.envs] if record else None
        forces: list[list[float]] = [[] for _ in self.envs]
        returns = [0.0] * len(self.envs)
        ends: list[dict[str, Any] | None] = [None] * len(self.envs)
        running = list(range(len(self.envs)))
        while running:
            if privileged:
                actions = np.stack([policy(self.envs[i].simulator) for i in running])
            else:
                batch = {key: np.stack([observations[i][key] for i in running]) for key in observations[running[0]]}
                actions = np.asarray(policy(batch)).reshape(len(running), -1)
            still = []
            for action, i in zip(actions, running, strict=True):
                env = self.envs[i]
                observations[i], reward, terminated, truncated, info = env.step(action)
                sim = env.simulator
                positions[i].append(sim.positions.copy())  # the simulator updates its arrays in place
                if frames is not None:
                    frames[i].append(_state(sim))
                forces[i].append(abs(complex(sim.robot_social_force)))
                returns[i] += float(reward)
                if terminated or truncated:
                    ends[i] = info
                else:
                    still.append(i)
            running = still
        episodes = [self._episode(i, positions[i], forces[i], returns[i], ends[i]) for i in range(len(self.envs))]
        if frames is not None:
            for episode, states, env in zip(episodes, frames, self.envs, strict=True):
                _add_frames(episode, states, env.simulator)
        return episodes

    def _run_batched(self, policy: BatchPolicy, record: bool) -> list[dict[str, Any]]:
        """:meth:`run` for a learned policy, the episodes stepped as one batch (ended worlds wait)."""
        if self._vector is None:
            from crowdnav.envs.vector import CrowdNavVectorEnv

            self._vector = CrowdNavVectorEnv(num_envs=len(self.seeds), autoreset_mode="Disabled", **self.env_options)
        env, count = self._vector, len(self.seeds)
        observations, _ = env.reset(seed=self.seeds)
        positions = [[env.positions(i)] for i in range(count)]
        frames = [[_world_state(env, i)] for i in range(count)] if record else None
        forces: list[list[float]] = [[] for _ in range(count)]
        returns = [0.0] * count
        ends: list[dict[str, Any] | None] = [None] * count
        running = np.ones(count, dtype=bool)
        while running.any():
            live = np.flatnonzero(running)
            batch = {key: values[live] for key, values in observations.items()}
            actions = np.zeros((count, 2))
            actions[live] = np.asarray(policy(batch)).reshape(len(live), -1)
            observations, rewards, terminated, truncated, infos = env.step(actions)
            force = env.robot_social_force()
            for i in live.tolist():  # bookkeeping of the trajectories, per running episode
                positions[i].append(env.positions(i))
                if frames is not None:
                    frames[i].append(_world_state(env, i))
                forces[i].append(abs(complex(force[i])))
                returns[i] += float(rewards[i])
                if terminated[i] or truncated[i]:
                    ends[i] = {"outcome": infos["outcome"][i]}
                    if infos.get("_collision_kind", np.zeros(count, dtype=bool))[i]:
                        ends[i]["collision_kind"] = infos["collision_kind"][i]
                    running[i] = False
        sims = [env.simulator(i) for i in range(count)]
        episodes = [self._episode(i, positions[i], forces[i], returns[i], ends[i], sims[i]) for i in range(count)]
        if frames is not None:
            for episode, states, sim in zip(episodes, frames, sims, strict=True):
                _add_frames(episode, states, sim)
        return episodes

    def _episode(self, i: int, positions: list[np.ndarray], forces: list[float], total: float, info: dict[str, Any],
                 sim: Any = None) -> dict[str, Any]:
        sim = self.envs[i].simulator if sim is None else sim
        trajectory = Trajectory(
            positions=np.stack(positions), radii=np.asarray(sim.radii, dtype=float).copy(), goal=complex(sim.robot_goal),
            goal_radius=float(sim.scenario.robot.goal_radius), dt=float(sim.dt), social_force=np.asarray(forces),
        )
        outcome = info["outcome"]
        return {
            "test_episode": i, "test_seed": self.seeds[i], "outcome": outcome, "collision_kind": info.get("collision_kind", ""),
            "return": total, **episode_metrics(trajectory, outcome == "success"),
        }

    def close(self) -> None:
        for env in self._envs or []:
            env.close()
        if self._vector is not None:
            self._vector.close()


def _add_frames(episode: dict[str, Any], states: list[dict[str, np.ndarray]], sim: Any) -> None:
    """The recorded states of an episode, and each agent's group for the whole episode (the robot is its own)."""
    groups = ["robot", *(sim.groups[g].name for g in sim.human_group.tolist())]
    episode["frames"] = {"dt": float(sim.dt), "groups": groups, **{key: np.stack([s[key] for s in states]) for key in states[0]}}


def _world_state(env: Any, i: int) -> dict[str, np.ndarray]:
    """:func:`_state` of world ``i`` of a vector env."""
    return {"positions": env.positions(i), "velocities": env.velocities(i),
            "goals": np.concatenate([[env.robot_goal(i)], env.human_goals(i)])}


def _state(sim: Any) -> dict[str, np.ndarray]:
    """Positions, velocities and goals of the robot (index 0) and the humans, copied (complex, (n + 1,))."""
    return {"positions": sim.positions.copy(), "velocities": sim.velocities.copy(),
            "goals": np.concatenate([[sim.robot_goal], sim.human_goals])}
