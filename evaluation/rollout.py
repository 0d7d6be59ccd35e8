"""Test episodes: run a deterministic policy on the held-out seeds and record what the metrics need.

The test episodes of one evaluation run side by side in lock-step, so the policy is called once
per step on the batch of the still-running episodes (one network forward for all of them). A
learned policy's episodes are the worlds of one native vector env
(:class:`crowdnav.envs.vector.env.CrowdNavVectorEnv`, stepped as one batch); a scripted policy, which
reads each episode's live simulator, plays one single env per seed. Both give the same episodes
bit for bit (world i of the batch is the single env seeded with seed i; tested). Nothing here
learns: the transitions go nowhere but into the trajectories.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from functools import partial
from typing import Any

import numpy as np
from crowdnav.evaluation.metrics import Trajectory, episode_metrics

from crowdnav.envs.engines.protocol import world_frame

BatchPolicy = Callable[[Mapping[str, np.ndarray]], np.ndarray]
"""Observations stacked per key, shape (N, ...) -> actions (N, 2); :class:`crowdnav.agents.AgentPolicy` is one. A policy
whose ``recurrent`` attribute is True is played through its ``predict(observations, state, episode_start) -> (actions,
state)`` instead, on every episode's row (:class:`_Acting`)."""
ScriptedPolicy = Callable[[Any], np.ndarray]
"""A privileged robot policy: simulator -> action (2,), e.g. :class:`crowdnav.planning.scripted.StraightToGoal`."""


class HeldOutEpisodes:
    """The environments of the test episodes, built once and reused at every evaluation.

    ``env_options``: keyword arguments of :class:`crowdnav.envs.CrowdNavEnv` (the policy's
    :attr:`crowdnav.agents.AgentPolicy.env_options`); ``seeds``: the held-out episode seeds.
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
            batched: bool = True, on_end: Callable[[], None] | None = None) -> list[dict[str, Any]]:
        """Play one episode per seed with ``policy``; one dict per episode (seed order): outcome, return, metrics.

        ``privileged``: ``policy`` is a scripted robot policy (:mod:`crowdnav.planning.scripted`) called
        with each running episode's simulator instead of the stacked observations. ``record``:
        each dict also holds ``frames``, the episode's states step by step (see
        :mod:`crowdnav.evaluation.trajectories`). ``batched=False`` plays a learned policy's
        episodes on single envs too (the reference the batched run is tested against). ``on_end`` is
        called once per episode as it ends (a progress bar).
        """
        ended = on_end or (lambda: None)
        if batched and not privileged:
            return self._run_batched(policy, record, ended)
        envs = self.envs
        observations = [env.reset(seed=seed)[0] for env, seed in zip(envs, self.seeds, strict=True)]
        log = _Log([env.simulator.positions.copy() for env in envs], [world_frame(env.simulator) for env in envs] if record else None)
        running = list(range(len(envs)))
        acting = None if privileged else _Acting(policy, len(envs))
        while running:
            if acting is None:
                actions = np.stack([policy(envs[i].simulator.robot_view(0)) for i in running])  # several robots: it sees the others
            else:
                actions = acting(partial(_stacked, observations), running)
            still = []
            for action, i in zip(actions, running, strict=True):
                observations[i], reward, terminated, truncated, info = envs[i].step(action)
                sim = envs[i].simulator  # it updates its arrays in place: the log copies them
                log.step(i, sim.positions.copy(), partial(world_frame, sim), complex(sim.robot_social_force), reward)
                if terminated or truncated:
                    log.ends[i] = info
                    ended()
                else:
                    still.append(i)
            running = still
        return log.episodes(self, [env.simulator for env in envs])

    def _run_batched(self, policy: BatchPolicy, record: bool, ended: Callable[[], None]) -> list[dict[str, Any]]:
        """:meth:`run` for a learned policy, the episodes stepped as one batch (ended worlds wait)."""
        if self._vector is None:
            from crowdnav.envs.vector.env import CrowdNavVectorEnv

            self._vector = CrowdNavVectorEnv(num_envs=len(self.seeds), autoreset_mode="Disabled", **self.env_options)
        env, count = self._vector, len(self.seeds)
        observations, _ = env.reset(seed=self.seeds)
        log = _Log([env.positions(i) for i in range(count)], [env.engine.frame(i) for i in range(count)] if record else None)
        running, acting = np.ones(count, dtype=bool), _Acting(policy, count)
        while running.any():
            live = np.flatnonzero(running)
            actions = np.zeros((count, 2))
            actions[live] = acting(partial(_rows_of, observations), live)
            observations, rewards, terminated, truncated, infos = env.step(actions)
            force = env.robot_social_force()
            for i in live.tolist():  # bookkeeping of the trajectories, per running episode
                log.step(i, env.positions(i), partial(env.engine.frame, i), force[i], rewards[i])
                if terminated[i] or truncated[i]:
                    log.ends[i] = {"outcome": infos["outcome"][i]}
                    if infos.get("_collision_kind", np.zeros(count, dtype=bool))[i]:
                        log.ends[i]["collision_kind"] = infos["collision_kind"][i]
                    running[i] = False
                    ended()
        return log.episodes(self, [env.simulator(i) for i in range(count)])

    def _episode(self, i: int, sim: Any, positions: list[np.ndarray], forces: list[float], total: float,
                 info: dict[str, Any]) -> dict[str, Any]:
        trajectory = Trajectory(
            positions=np.stack(positions), radii=np.asarray(sim.radii, dtype=float).copy(), goal=complex(sim.robot_goal),
            goal_radius=float(sim.scenario.robot.goal_radius), dt=float(sim.dt), social_force=np.asarray(forces),
            max_speed=float(sim.scenario.robot.max_speed), human_stalls=int(sim.human_stalls.sum()),
            walking_group=walking_groups(sim),
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


def _rows_of(observations: Mapping[str, np.ndarray], rows: Any) -> dict[str, np.ndarray]:
    """Rows ``rows`` of a vector env's observations, per key."""
    return {key: values[rows] for key, values in observations.items()}


def _stacked(observations: Sequence[Mapping[str, np.ndarray]], rows: Any) -> dict[str, np.ndarray]:
    """The single envs' observations ``rows``, stacked per key."""
    return {key: np.stack([observations[i][key] for i in rows]) for key in observations[0]}


class _Acting:
    """A learned policy's actions for the running episodes, one call per step.

    A memoryless policy sees only the running rows. A recurrent one (``recurrent`` True) sees every episode's row, the
    ended ones included (their actions are dropped), so that row ``i`` of its state stays episode ``i``'s memory; each
    episode starts once, at the first step (every world plays one episode).
    """

    def __init__(self, policy: Any, count: int):
        self.policy, self.recurrent = policy, bool(getattr(policy, "recurrent", False))
        self.state: Any = None
        self.starts = np.ones(count, dtype=bool)

    def __call__(self, stack: Callable[[Any], Mapping[str, np.ndarray]], running: Sequence[int] | np.ndarray) -> np.ndarray:
        """The actions of the ``running`` episodes; ``stack(rows)`` stacks those episodes' observations per key."""
        if not self.recurrent:
            return np.asarray(self.policy(stack(running))).reshape(len(running), -1)
        actions, self.state = self.policy.predict(stack(np.arange(len(self.starts))), self.state, self.starts)
        self.starts = np.zeros_like(self.starts)
        return np.asarray(actions).reshape(len(self.starts), -1)[np.asarray(running)]


class _Log:
    """What the test episodes keep step by step: positions, social force, return, how each ended (and frames)."""

    def __init__(self, first_positions: list[np.ndarray], first_states: list[dict[str, np.ndarray]] | None):
        count = len(first_positions)
        self.positions = [[p] for p in first_positions]
        self.frames = None if first_states is None else [[s] for s in first_states]
        self.forces: list[list[float]] = [[] for _ in range(count)]
        self.returns = [0.0] * count
        self.ends: list[dict[str, Any] | None] = [None] * count
        """Per episode: its last info (``outcome``, ``collision_kind`` after a collision) once it ended."""

    def step(self, i: int, positions: np.ndarray, state: Callable[[], dict[str, np.ndarray]], force: complex, reward: float) -> None:
        """Episode ``i`` took a step: its new positions (a copy), its state (called only when recording), force and reward."""
        self.positions[i].append(positions)
        if self.frames is not None:
            self.frames[i].append(state())
        self.forces[i].append(abs(complex(force)))
        self.returns[i] += float(reward)

    def episodes(self, owner: HeldOutEpisodes, sims: Sequence[Any]) -> list[dict[str, Any]]:
        """One dict per episode (see :meth:`HeldOutEpisodes.run`); ``sims``: each episode's simulator (radii, goal, groups)."""
        ends = [end for end in self.ends if end is not None]
        if len(ends) < len(self.ends):  # run() steps until every episode has ended: a bug, not a result
            raise RuntimeError(f"episodes {[i for i, end in enumerate(self.ends) if end is None]} have not ended")
        out = [owner._episode(i, sim, self.positions[i], self.forces[i], self.returns[i], ends[i]) for i, sim in enumerate(sims)]
        if self.frames is not None:
            for episode, states, sim in zip(out, self.frames, sims, strict=True):
                # each agent's group, for the whole episode (the robot is its own; several robots: after the humans)
                groups = ["robot", *(sim.groups[g].name for g in sim.human_group.tolist()), *["robot"] * (sim.robot_count - 1)]
                names = [sim.scenario.robot_names[0], *(f"human_{i}" for i in range(sim.n_humans)), *sim.scenario.robot_names[1:]]
                episode["frames"] = {"dt": float(sim.dt), "groups": groups, "agents": names,
                                     **{key: np.stack([s[key] for s in states]) for key in states[0]}}
        return out


def walking_groups(sim: Any) -> np.ndarray | None:
    """(n,) each human's group if that group walks together (``walk_together``), else -1; None without such groups."""
    together = getattr(sim, "together", None)
    if together is None:
        return None
    labels: np.ndarray = np.where(together[sim.human_group], sim.human_group, -1)
    return labels
