"""Test episodes: run a deterministic policy on the held-out seeds and record what the metrics need.

The test episodes of one evaluation run side by side in lock-step, one environment per seed,
so the policy is called once per step on the batch of the still-running episodes (one
network forward for all of them). Nothing here learns: the transitions go nowhere but into
the trajectories.
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
        from crowdnav.envs import CrowdNavEnv

        self.env_options = dict(env_options)
        self.seeds = list(seeds)
        self.envs = [CrowdNavEnv(**self.env_options) for _ in self.seeds]

    def run(self, policy: BatchPolicy | ScriptedPolicy, *, privileged: bool = False, record: bool = False) -> list[dict[str, Any]]:
        """Play one episode per seed with ``policy``; one dict per episode (seed order): outcome, return, metrics.

        ``privileged``: ``policy`` is a scripted robot policy (:mod:`crowdnav.policies`) called
        with each running episode's simulator instead of the stacked observations. ``record``:
        each dict also holds ``frames``, the episode's states step by step (see
        :mod:`crowdnav.evaluation.trajectories`).
        """
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
                sim = env.simulator  # each agent's group, for the whole episode (the robot is its own)
                groups = ["robot", *(sim.groups[g].name for g in sim.human_group.tolist())]
                episode["frames"] = {"dt": float(sim.dt), "groups": groups,
                                     **{key: np.stack([s[key] for s in states]) for key in states[0]}}
        return episodes

    def _episode(self, i: int, positions: list[np.ndarray], forces: list[float], total: float, info: dict[str, Any]) -> dict[str, Any]:
        sim = self.envs[i].simulator
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
        for env in self.envs:
            env.close()


def _state(sim: Any) -> dict[str, np.ndarray]:
    """Positions, velocities and goals of the robot (index 0) and the humans, copied (complex, (n + 1,))."""
    return {"positions": sim.positions.copy(), "velocities": sim.velocities.copy(),
            "goals": np.concatenate([[sim.robot_goal], sim.human_goals])}
