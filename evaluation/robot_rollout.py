"""Held-out test episodes of a multi-robot scenario, every robot driven by one policy: one row per robot per episode.

A shared robot policy (:class:`crowdnav.agents.marl.robots.RobotsPolicy`, trained with ``agents: robots``)
and the scripted baselines play the *same* episodes: test seed ``s`` resets the robots-only
PettingZoo env (``crowdnav.parallel_env(..., humans_as_agents=False, fixed_agents=True,
flat_observations=True)``) with ``s``, and every robot acts with the policy (a scripted one reads
that robot's ``simulator.robot_view(k)``, as the Gymnasium env's ``other_robots`` do). The humans
follow the scenario's crowd model; a robot that ends leaves the world, the others go on.

Each robot's row has the columns of a single-robot test episode (:mod:`crowdnav.evaluation.rollout`:
``test_episode``, ``test_seed``, ``outcome``, ``collision_kind``, ``return`` and the metrics of
:func:`crowdnav.evaluation.metrics.episode_metrics`, measured on that robot and the humans) plus
``robot``, the robot's name. The leaderboard's rates over these rows are the mean over robots
and episodes; :func:`robot_rates` breaks them down per robot.

:class:`FirstRobot` plays a shared robot policy the other way, as a track with several robots
defines its game: the network drives the first robot of the Gymnasium env, which drives the others
with the social-force robot (one row per episode, the first robot's).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from crowdnav.evaluation.metrics import Trajectory, episode_metrics

ScriptedPolicy = Callable[[Any], np.ndarray]
"""A privileged robot policy: a robot's view (``simulator.robot_view(k)``) -> action (2,)."""

ROBOTS_AGENTS = "robots"
"""A configuration's ``agents`` (and a baseline's env option) when every robot of the scenario is played by one policy."""


def robot_count(env_options: Mapping[str, Any]) -> int:
    """Robots in the scenario of ``env_options`` (rows per test episode)."""
    from crowdnav.scenario import load_scenario

    return len(load_scenario(env_options["scenario"], dict(env_options.get("overrides") or {})).robot_names)


class RobotEpisodes:
    """The test episodes of a multi-robot scenario, one env reused episode after episode.

    ``env_options``: keyword arguments of :class:`crowdnav.envs.CrowdNavEnv` (scenario, modalities,
    sensors, overrides, reward weights); ``seeds``: the held-out episode seeds.
    """

    def __init__(self, env_options: Mapping[str, Any], seeds: Sequence[int]):
        from crowdnav.envs import parallel_env

        self.env_options = {key: value for key, value in env_options.items() if key != "agents"}
        self.seeds = list(seeds)
        self.env = parallel_env(**self.env_options, humans_as_agents=False, fixed_agents=True, flat_observations=True)
        self.robots = list(self.env.possible_agents)

    def run(self, policy: Any, *, privileged: bool = False, on_end: Callable[[], None] | None = None) -> list[dict[str, Any]]:
        """One row per robot per seed (seed order, robots in scenario order).

        ``policy``: a shared robot policy (``policy.act(observations, infos) -> {robot: action}``),
        or with ``privileged`` a scripted robot policy called with each running robot's view.
        ``on_end`` is called once per episode as it ends (a progress bar).
        """
        rows = []
        for i, seed in enumerate(self.seeds):
            rows.extend(self._episode(i, seed, policy, privileged))
            if on_end is not None:
                on_end()
        return rows

    def _episode(self, i: int, seed: int, policy: Any, privileged: bool) -> list[dict[str, Any]]:
        env, robots = self.env, self.robots
        observations, infos = env.reset(seed=seed)
        sim = env.simulator
        views = [sim.robot_view(k, with_robots=False) for k in range(len(robots))]
        tracks: list[list[np.ndarray]] = [[view.positions.copy()] for view in views]  # robot k first, then the humans
        forces: list[list[float]] = [[] for _ in robots]
        returns = dict.fromkeys(robots, 0.0)
        ends: dict[str, dict[str, Any]] = {}
        specs = [view.scenario.robot for view in views]
        radii = [view.radii.copy() for view in views]
        while env.agents:
            if privileged:
                actions = {name: np.asarray(policy(sim.robot_view(k)), np.float32) if name not in ends else np.zeros(2, np.float32)
                           for k, name in enumerate(robots)}
            else:
                actions = policy.act(observations, infos)
            observations, rewards, terminations, truncations, infos = env.step(actions)
            for k, name in enumerate(robots):
                if name in ends:
                    continue
                returns[name] += float(rewards[name])
                view = sim.robot_view(k, with_robots=False) if infos[name].get("outcome") is None else None
                tracks[k].append(view.positions.copy() if view is not None else _final(tracks[k][-1], sim))
                forces[k].append(abs(view.robot_social_force) if view is not None else 0.0)
                if infos[name].get("outcome") is not None:
                    ends[name] = infos[name]
        rows = []
        for k, name in enumerate(robots):
            info = ends.get(name, {"outcome": "truncated"})
            positions = np.stack([track[: len(tracks[k][0])] for track in tracks[k]])
            trajectory = Trajectory(positions=positions, radii=radii[k], goal=complex(views[k].robot_goal),
                                    goal_radius=float(specs[k].goal_radius), dt=float(sim.dt), social_force=np.asarray(forces[k]),
                                    max_speed=float(specs[k].max_speed), human_stalls=int(sim.human_stalls.sum()))
            rows.append({"test_episode": i, "test_seed": seed, "robot": name, "outcome": info["outcome"],
                         "collision_kind": info.get("collision_kind") or "", "return": returns[name],
                         **episode_metrics(trajectory, info["outcome"] == "success")})
        return rows

    def close(self) -> None:
        self.env.close()


class FirstRobot:
    """A shared robot policy driving the first robot only, as a batch policy of the Gymnasium env's test episodes.

    What a track with several robots plays (:data:`crowdnav.evaluation.track.FIRST_ROBOT_NOTE`): the
    first robot is evaluated, the env drives the others with the social-force robot. The shared
    network reads the first robot's observation as it did in training: the Gymnasium env's Dict is
    that robot's observation, flattened in its keys' order as the robots-only env flattens it, then
    scaled and given robot 0's one-hot (:meth:`crowdnav.agents.marl.robots.RobotsPolicy.inputs`).
    ``space``: the Gymnasium env's observation space.
    """

    def __init__(self, policy: Any, space: Any):
        self.policy, self.space, self.name = policy, space, policy.robots[0]

    def __call__(self, batch: Mapping[str, np.ndarray]) -> np.ndarray:
        from gymnasium import spaces

        count = len(next(iter(batch.values())))
        flat = [np.asarray(spaces.flatten(self.space, {key: batch[key][i] for key in self.space.spaces}), np.float32)
                for i in range(count)]
        actions, _ = self.policy.network.predict(np.stack([self.policy.observe(0, row) for row in flat]), deterministic=True)
        robots = self.policy.robots  # every robot named, only the first acting: its kinematics turn its command
        return np.stack([np.asarray(self.policy.commands({self.name: np.asarray(action, np.float32)}, robots, {self.name: row})[self.name],
                                    np.float32) for action, row in zip(actions, flat, strict=True)])


def _final(previous: np.ndarray, sim: Any) -> np.ndarray:
    """A robot's row for the step it ended in: it has left the world (moved far away), so its last seen position stays.

    Its path therefore misses the ending step's few centimetres; the humans' positions are the new ones.
    """
    row = previous.copy()
    humans = sim.positions[1:]
    row[1 : 1 + len(humans)] = humans[: len(row) - 1]
    return row


def robot_rates(tests: Any) -> Any:
    """Final-evaluation rates per robot: a DataFrame with one row per (experiment, configuration, robot).

    ``tests``: test rows with a ``robot`` column (a robots run's or baseline's ``test_episodes.csv``,
    or :func:`crowdnav.evaluation.storage.load_results`' tests); the last evaluation of each run counts.
    """
    import pandas as pd

    from crowdnav.sim.simulator import OUTCOMES

    if "robot" not in tests or tests["robot"].isna().all():
        return pd.DataFrame(columns=["experiment", "configuration", "label", "robot", "episodes", *OUTCOMES,
                                     "collision_robot", "collision_human", "collision_static"])
    frame = tests[tests["robot"].notna() & (tests["robot"] != "")]
    last = frame.groupby(["experiment", "configuration", "seed"])["evaluation"].transform("max")
    final = frame[frame["evaluation"] == last].drop_duplicates(["experiment", "configuration", "seed", "test_episode", "robot"])
    rows = []
    for (experiment, configuration, robot), group in final.groupby(["experiment", "configuration", "robot"], sort=True):
        collided = group["outcome"] == "collision"
        kinds = group["collision_kind"].fillna("") if "collision_kind" in group else pd.Series("", index=group.index)
        rows.append({"experiment": experiment, "configuration": configuration, "label": group["label"].iloc[0], "robot": robot,
                     "episodes": len(group), **{outcome: float((group["outcome"] == outcome).mean()) for outcome in OUTCOMES},
                     # whom it hit: another robot is the multi-robot scenario's own risk
                     **{f"collision_{kind}": float((collided & (kinds == kind)).mean()) for kind in ("robot", "human", "static")}})
    return pd.DataFrame(rows)
