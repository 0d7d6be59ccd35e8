"""Evaluation's robot rollouts from the robots-only engine (evaluation/robot_rollout.py): several test episodes at once,
each a world of one engine, give every per-robot row (outcome, collision kind, return, every metric) exactly as one
robots-only PettingZoo env per test seed gives it, the driver evaluation used before (``_reference_rows`` below, kept
as it was), for a shared robot network (stacked engine, one ``predict`` for every robot of every world) and for the
scripted baselines (stacked engine, their batched twins acting for every robot; one env per world, each robot's view,
for a policy without a twin or a world that does not stack)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from crowdnav.evaluation.baselines import scripted_policy
from crowdnav.evaluation.metrics import Trajectory, episode_metrics
from crowdnav.evaluation.robot_rollout import RobotEpisodes

from crowdnav.envs.engines.robots import SingleRobots
from crowdnav.envs.engines.stacked_robots import StackedRobots

HALL = "robots_crossing_hall"
OPEN = {"max_steps": 60, "world.boundary_walls": False, "humans.count": [0, 7]}
"""No walls (a robot may leave the world), crowds of 0 to 7 humans (worlds of several crowd sizes), a short time limit."""
SCRIPTED = {**OPEN, "max_steps": 80}
"""The scripted baselines' worlds: time for the social-force robots to arrive one after the other (or not)."""


def _reference_rows(env_options: dict[str, Any], seeds: list[int], policy: Any, privileged: bool) -> list[dict[str, Any]]:
    """The rows of the rollout before the engine: one robots-only env, test seed after test seed (the code as it was)."""
    from crowdnav.envs import parallel_env

    env = parallel_env(**env_options, humans_as_agents=False, fixed_agents=True, flat_observations=True)
    robots = list(env.possible_agents)
    rows = []
    for i, seed in enumerate(seeds):
        observations, infos = env.reset(seed=seed)
        sim = env.simulator
        views = [sim.robot_view(k, with_robots=False) for k in range(len(robots))]
        tracks: list[list[np.ndarray]] = [[view.positions.copy()] for view in views]
        forces: list[list[float]] = [[] for _ in robots]
        returns = dict.fromkeys(robots, 0.0)
        ends: dict[str, dict[str, Any]] = {}
        while env.agents:
            if privileged:
                actions = {name: np.asarray(policy(sim.robot_view(k)), np.float32) if name not in ends else np.zeros(2, np.float32)
                           for k, name in enumerate(robots)}
            else:
                actions = policy.act(observations, infos)
            observations, rewards, _, _, infos = env.step(actions)
            for k, name in enumerate(robots):
                if name in ends:
                    continue
                returns[name] += float(rewards[name])
                view = sim.robot_view(k, with_robots=False) if infos[name].get("outcome") is None else None
                tracks[k].append(view.positions.copy() if view is not None else _final(tracks[k][-1], sim))
                forces[k].append(abs(view.robot_social_force) if view is not None else 0.0)
                if infos[name].get("outcome") is not None:
                    ends[name] = infos[name]
        for k, name in enumerate(robots):
            info, spec = ends.get(name, {"outcome": "truncated"}), views[k].scenario.robot
            positions = np.stack([track[: len(tracks[k][0])] for track in tracks[k]])
            trajectory = Trajectory(positions=positions, radii=views[k].radii.copy(), goal=complex(views[k].robot_goal),
                                    goal_radius=float(spec.goal_radius), dt=float(sim.dt), social_force=np.asarray(forces[k]),
                                    max_speed=float(spec.max_speed), human_stalls=int(sim.human_stalls.sum()))
            rows.append({"test_episode": i, "test_seed": seed, "robot": name, "outcome": info["outcome"],
                         "collision_kind": info.get("collision_kind") or "", "return": returns[name],
                         **episode_metrics(trajectory, info["outcome"] == "success")})
    env.close()
    return rows


def _final(previous: np.ndarray, sim: Any) -> np.ndarray:
    """A robot's row for the step it ended in: its last seen position (it has left the world), the humans' new ones."""
    row = previous.copy()
    humans = sim.positions[1:]
    row[1 : 1 + len(humans)] = humans[: len(row) - 1]
    return row


def _same_rows(rows: list[dict[str, Any]], expected: list[dict[str, Any]]) -> None:
    assert [(row["test_seed"], row["robot"]) for row in rows] == [(row["test_seed"], row["robot"]) for row in expected]
    for row, want in zip(rows, expected, strict=True):
        assert row.keys() == want.keys()
        for key, value in want.items():  # bit for bit (NaN where the reference has NaN)
            got = row[key]
            same = (isinstance(value, float) and math.isnan(value) and math.isnan(got)) or (got == value and type(got) is type(value))
            assert same, (key, got, value, row["test_seed"], row["robot"])


@pytest.fixture(scope="module")
def robots_policy(tmp_path_factory):
    """The smallest shared robot policy (one PPO rollout of 2 worlds x 3 robots x 16 steps) on the open hall, its mean
    action pushed toward each robot's goal (goal-frame velocities) so that robots meet, collide, arrive and time out."""
    torch = pytest.importorskip("torch")
    from crowdnav.agents.marl.robots import load_robots_policy, train_robots
    from crowdnav.agents.training.config import config_from_mapping

    out = tmp_path_factory.mktemp("robots") / "run"
    config = config_from_mapping({"scenario": HALL, "agents": "robots", "algo": "ppo", "num_envs": 2, "timesteps": 96, "n_steps": 16,
                                  "batch_size": 48, "net_arch": [16], "seed": 0, "out": str(out), "progress": False,
                                  "overrides": OPEN, "sensors": {"lidar": {"beams": 16}}, "robot_actions": "goal_velocity"})
    train_robots(config)
    policy = load_robots_policy(out)
    with torch.no_grad():
        policy.network.action_net.bias += torch.tensor([0.9, 0.0])
    return policy


SEEDS = list(range(100, 111))
"""Eleven test episodes: with 4 worlds, worlds take new seeds as others end (and idle at the end)."""


@pytest.mark.parametrize("worlds", [4, 16])
def test_a_shared_robot_policy_gives_the_rows_of_one_env_per_seed_from_the_stacked_engine(robots_policy, worlds):
    episodes = RobotEpisodes(robots_policy.env_options, SEEDS, worlds=worlds)
    try:
        rows = episodes.run(robots_policy)
        assert isinstance(episodes.engine(), StackedRobots)
    finally:
        episodes.close()
    expected = _reference_rows(robots_policy.env_options, SEEDS, robots_policy, privileged=False)
    assert {row["outcome"] for row in expected} >= {"collision", "truncated", "success"}
    _same_rows(rows, expected)


def test_a_shared_robot_policy_on_a_world_that_does_not_stack_gives_the_same_rows_from_one_env_per_world(robots_policy):
    options = {**robots_policy.env_options, "overrides": {**OPEN, "humans.model": "orca"}}
    episodes = RobotEpisodes(options, SEEDS[:5], worlds=3)
    try:
        rows = episodes.run(robots_policy)
        assert isinstance(episodes.engine(), SingleRobots)
    finally:
        episodes.close()
    _same_rows(rows, _reference_rows(options, SEEDS[:5], robots_policy, privileged=False))


@pytest.mark.parametrize(("name", "worlds"), [("straight", 4), ("social_force", 4), ("social_force", 16)])
def test_a_scripted_baseline_gives_the_rows_of_one_env_per_seed_from_the_stacked_engine(name, worlds):
    """Every robot, the first one included, driven by the baseline's batched twin; robots leave while others go on."""
    options = {"scenario": HALL, "modalities": ["goal"], "overrides": SCRIPTED}
    policy = scripted_policy(name)
    episodes = RobotEpisodes(options, SEEDS, worlds=worlds)
    try:
        rows = episodes.run(policy, privileged=True)
        assert isinstance(episodes.engine(policy, privileged=True), StackedRobots)
    finally:
        episodes.close()
    expected = _reference_rows(options, SEEDS, scripted_policy(name), privileged=True)
    assert len({row["outcome"] for row in expected}) >= 2
    steps = {(row["test_seed"], row["robot"]): row["steps"] for row in expected}
    assert any(steps[seed, "east_bound"] < max(steps[seed, robot] for robot in ("west_bound", "north_bound")) for seed in SEEDS)
    _same_rows(rows, expected)


def test_a_scripted_policy_without_a_batched_twin_or_on_a_world_that_does_not_stack_plays_one_env_per_world():
    options = {"scenario": HALL, "modalities": ["goal"], "overrides": OPEN}
    straight = scripted_policy("straight")
    episodes = RobotEpisodes(options, SEEDS[:5], worlds=3)
    try:
        rows = episodes.run(straight.__call__, privileged=True)  # a callable: no batched twin
        assert isinstance(episodes.engine(straight.__call__, privileged=True), SingleRobots)
    finally:
        episodes.close()
    _same_rows(rows, _reference_rows(options, SEEDS[:5], straight, privileged=True))
    orca_crowd = {**options, "overrides": {**OPEN, "humans.model": "orca"}}
    episodes = RobotEpisodes(orca_crowd, SEEDS[:5], worlds=3)
    try:
        rows = episodes.run(straight, privileged=True)
        assert isinstance(episodes.engine(straight, privileged=True), SingleRobots)
    finally:
        episodes.close()
    _same_rows(rows, _reference_rows(orca_crowd, SEEDS[:5], straight, privileged=True))


@pytest.mark.slow  # 8 s; the shared-policy cases at 4 and 16 worlds check several at once in the default suite
def test_the_rows_do_not_depend_on_how_many_episodes_play_at_once(robots_policy):
    played = {}
    for worlds in (1, 5):
        episodes = RobotEpisodes(robots_policy.env_options, SEEDS[:6], worlds=worlds)
        try:
            played[worlds] = episodes.run(robots_policy)
            played[worlds, "again"] = episodes.run(robots_policy)  # the engine reused: the same rows
        finally:
            episodes.close()
    _same_rows(played[5], played[1])
    _same_rows(played[5, "again"], played[1])
