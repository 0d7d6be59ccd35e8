"""Held-out test episodes of a multi-robot scenario, every robot driven by one policy: one row per robot per episode.

A shared robot policy (:class:`crowdnav.agents.marl.robots.RobotsPolicy`, trained with ``agents: robots``)
and the scripted baselines play the *same* episodes: test seed ``s`` resets the robots-only
PettingZoo env (``crowdnav.parallel_env(..., humans_as_agents=False, fixed_agents=True,
flat_observations=True)``) with ``s``, and every robot acts with the policy (a scripted one reads
that robot's ``simulator.robot_view(k)``, as the Gymnasium env's ``other_robots`` do). The humans
follow the scenario's crowd model; a robot that ends leaves the world, the others go on.
:class:`RobotEpisodes` plays several test episodes at once, each in a world of one robots-only engine
(:mod:`crowdnav.envs.engines.robots`): the rows are those of one env per seed, bit for bit.

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
from typing import TYPE_CHECKING, Any

import numpy as np
from crowdnav.evaluation.metrics import Trajectory, episode_metrics

from crowdnav.envs.engines.protocol import RobotsEngine, RobotsFrame, RobotsStep

if TYPE_CHECKING:
    from crowdnav.envs.engines.robots import ScriptedRobotsEngine

ScriptedPolicy = Callable[[Any], np.ndarray]
"""A privileged robot policy: a robot's view (``simulator.robot_view(k)``) -> action (2,)."""

ROBOTS_AGENTS = "robots"
"""A configuration's ``agents`` (and a baseline's env option) when every robot of the scenario is played by one policy."""


def robot_count(env_options: Mapping[str, Any]) -> int:
    """Robots in the scenario of ``env_options`` (rows per test episode)."""
    from crowdnav.scenario import load_scenario

    return len(load_scenario(env_options["scenario"], dict(env_options.get("overrides") or {})).robot_names)


WORLDS = 32
"""Test episodes a :class:`RobotEpisodes` plays at once (its engine's worlds)."""


class RobotEpisodes:
    """The test episodes of a multi-robot scenario, played ``worlds`` at a time as the worlds of one robots-only engine.

    ``env_options``: keyword arguments of :class:`crowdnav.envs.CrowdNavEnv` (scenario, modalities,
    sensors, overrides, reward weights); ``seeds``: the held-out episode seeds. A shared robot policy plays through
    :func:`crowdnav.envs.engines.robots.robots_engine` (the worlds stacked where the scenario stacks), its network
    predicting each world's robots (:func:`_shared` says why not all at once). So do the scripted baselines an
    ``agents: robots`` experiment plays, straight and social force: their batched twins act for every robot of the
    stack, the first one included, as each robot's view of its simulator would have them act
    (:meth:`crowdnav.envs.engines.stacked_robots.StackedRobots.scripted_actions`). The other scripted policies (ORCA,
    the planners, a callable; the shielded baselines' worlds do not stack) play on
    :class:`crowdnav.envs.engines.robots.SingleRobots`, called with one robot's view of one simulator. Each episode is
    its seed's in the robots-only env bit for bit, whichever world plays it and whatever plays beside it.
    ``stacked=False``: one env per world for every policy (the same rows; what the stack is measured against,
    ``benchmarks/bench_robot_rollout.py``).
    """

    def __init__(self, env_options: Mapping[str, Any], seeds: Sequence[int], *, worlds: int = WORLDS, stacked: bool = True):
        from crowdnav.envs.engines.robots import robots_world
        from crowdnav.sim.simulator import Simulator

        self.env_options = {key: value for key, value in env_options.items() if key != "agents"}
        self.seeds = list(seeds)
        self.worlds = max(1, min(int(worlds), len(self.seeds)))
        sim = Simulator(robots_world(self.env_options))
        self.robots: list[str] = list(sim.scenario.robot_names)
        self._specs = [sim.robot_scenario(k).robot for k in range(len(self.robots))]
        self._dt = float(sim.dt)
        self._stacked = stacked
        self._engines: dict[bool, ScriptedRobotsEngine] = {}
        """The engine of each kind (stacked where the scenario stacks, or one env per world), built on first use and reused."""

    def engine(self, policy: Any = None, privileged: bool = False) -> ScriptedRobotsEngine:
        """The engine that plays ``policy``: a shared robot policy, or with ``privileged`` a scripted one (class docstring)."""
        from crowdnav.envs.engines.robots import SingleRobots, robots_engine
        from crowdnav.envs.engines.stacked_robots import scripted_name

        stacked = self._stacked and (not privileged or scripted_name(policy) is not None)
        if stacked not in self._engines:
            self._engines[stacked] = robots_engine(self.env_options, self.worlds) if stacked else SingleRobots(self.env_options, self.worlds)
        return self._engines[stacked]

    def run(self, policy: Any, *, privileged: bool = False, on_end: Callable[[], None] | None = None) -> list[dict[str, Any]]:
        """One row per robot per seed (seed order, robots in scenario order).

        ``policy``: a shared robot policy (:class:`crowdnav.agents.marl.robots.RobotsPolicy`: its ``network``,
        ``observe`` and ``commands``), or with ``privileged`` a scripted robot policy called with each running robot's
        view (``simulator.robot_view(k)``). ``on_end`` is called once per episode as it ends (a progress bar).
        """
        engine = self.engine(policy, privileged)
        act = _scripted(policy, engine) if privileged else _shared(policy)
        w, seeds = engine.num_worlds, self.seeds
        tracks = _Tracks(engine)
        episode = np.full(w, -1, dtype=np.int64)
        playing = np.zeros(w, dtype=bool)
        rows: dict[int, list[dict[str, Any]]] = {}

        def start(worlds: np.ndarray, first: int) -> None:
            numbers = np.arange(first, first + len(worlds))
            engine.reset(worlds, [seeds[i] for i in numbers])
            episode[worlds], playing[worlds] = numbers, True
            tracks.start(worlds)

        start(np.arange(min(w, len(seeds))), 0)
        following = int(playing.sum())
        observations = engine.observe()
        while playing.any():
            step = engine.step(act(observations, tracks.acting, tracks.running, playing), playing)
            tracks.step(step, playing)
            ended = np.flatnonzero(step.over)
            for world in ended.tolist():  # per episode, as it ends: its rows
                rows[int(episode[world])] = self._rows(tracks, world, int(episode[world]))
                if on_end is not None:
                    on_end()
            playing[ended] = False
            again = ended[: max(0, len(seeds) - following)]
            if len(again):
                start(again, following)
                following += len(again)
            observations = engine.observe()  # once the ended worlds started their next episodes (their last one unread)
        return [row for i in range(len(seeds)) for row in rows[i]]

    def _rows(self, tracks: _Tracks, world: int, i: int) -> list[dict[str, Any]]:
        """Each robot's row of the episode ``world`` just ended (test episode ``i``)."""
        robots_radii, humans_radii = tracks.engine.radii(world)
        rows = []
        for k, name in enumerate(self.robots):
            spec, outcome = self._specs[k], tracks.outcome[world, k] or "truncated"
            trajectory = Trajectory(positions=tracks.positions(world, k), radii=np.concatenate([[robots_radii[k]], humans_radii]),
                                    goal=complex(tracks.goals[world, k]), goal_radius=float(spec.goal_radius), dt=self._dt,
                                    social_force=tracks.forces(world, k), max_speed=float(spec.max_speed),
                                    human_stalls=int(tracks.stalls[world]))
            rows.append({"test_episode": i, "test_seed": self.seeds[i], "robot": name, "outcome": outcome,
                         "collision_kind": tracks.kind[world, k] or "", "return": float(tracks.returns[world, k]),
                         **episode_metrics(trajectory, outcome == "success")})
        return rows

    def close(self) -> None:
        for engine in self._engines.values():
            engine.close()
        self._engines.clear()


class _Tracks:
    """What each robot of ``engine``'s worlds did this episode, recorded step by step for its row: its return and
    outcome, where it and the humans were after each step, the humans' social force on it (array work over the worlds).

    A robot's trajectory stops at the step it ended: that last row keeps its position before the step (it has left the
    world, parked far away) beside the humans' new positions, and its social force there is 0, as the single-episode
    rollout has always measured it.
    """

    def __init__(self, engine: RobotsEngine):
        self.engine = engine
        w, r = engine.num_worlds, len(engine.robot_names)
        self.returns = np.zeros((w, r))
        self.outcome = np.full((w, r), None, dtype=object)
        self.kind = np.full((w, r), None, dtype=object)
        self.running = np.zeros((w, r), dtype=bool)
        """Robots with no outcome yet this episode (a scripted policy acts for them)."""
        self.acting = np.zeros((w, r), dtype=bool)
        """Robots that acted at their world's last step or were just reset: the env's ``infos[name]["active"]``."""
        self.ended_at = np.zeros((w, r), dtype=np.int64)
        self.at = np.zeros(w, dtype=np.int64)
        """Per robot, the step it ended at; per world, the steps played this episode."""
        self.goals = np.zeros((w, r), complex)
        self.stalls = np.zeros(w, dtype=np.int64)
        self._robots = np.zeros((0, w, r), complex)
        self._humans = np.zeros((0, w, 0), complex)
        self._forces = np.zeros((0, w, r))
        """Per step (the reset's row first) and world: every robot's centre, the humans' and the forces after that step."""
        self._crowd = np.zeros(w, dtype=np.int64)
        """Each world's number of humans (the engine's last frame)."""

    def start(self, worlds: np.ndarray) -> None:
        """New episodes in ``worlds`` (just reset): the reset's row."""
        self.returns[worlds], self.outcome[worlds], self.kind[worlds] = 0.0, None, None
        self.running[worlds], self.acting[worlds], self.at[worlds] = True, True, 0
        frame = self.engine.frame()
        self.goals[worlds] = frame.goals[worlds]
        self._write(frame, worlds)

    def step(self, step: RobotsStep, playing: np.ndarray) -> None:
        """The step just taken in the ``playing`` worlds."""
        worlds = np.flatnonzero(playing)
        self.at[worlds] += 1
        counted = self.running & playing[:, None]  # robots whose episode went on into this step
        self.returns = np.where(counted, self.returns + step.rewards, self.returns)
        ends = counted & (step.outcome != None)  # noqa: E711  (an object array: None compared entry by entry)
        self.outcome[ends] = step.outcome[ends]
        for (world, k), contact in step.collisions.items():  # the collisions of the step (a few)
            if ends[world, k]:
                self.kind[world, k] = contact.kind
        self.ended_at[ends] = np.broadcast_to(self.at[:, None], ends.shape)[ends]
        self.running &= ~ends
        self.acting = np.where(playing[:, None], step.stepped, self.acting)
        frame = self.engine.frame()
        self.stalls[worlds] = frame.stalls[worlds]
        self._write(frame, worlds)

    def _write(self, frame: RobotsFrame, worlds: np.ndarray) -> None:
        """``frame``'s rows of ``worlds`` as each one's step ``at``."""
        steps, w, r = self._robots.shape
        size, crowd = int(self.at[worlds].max(initial=0)) + 1, max(frame.humans.shape[1], self._humans.shape[2])
        if size > steps or crowd > self._humans.shape[2]:  # grown by doubling: a few times an evaluation
            grown = steps if size <= steps else max(size, 2 * steps, 64)
            self._robots = _grown(self._robots, (grown, w, r), 0j)
            self._forces = _grown(self._forces, (grown, w, r), 0.0)
            self._humans = _grown(self._humans, (grown, w, crowd), complex(np.nan, np.nan))
        at = self.at[worlds]
        self._robots[at, worlds] = frame.robots[worlds]
        self._forces[at, worlds] = frame.social_force[worlds]
        self._humans[at, worlds, : frame.humans.shape[1]] = frame.humans[worlds]
        self._humans[at, worlds, frame.humans.shape[1] :] = complex(np.nan, np.nan)
        self._crowd = frame.crowd

    def positions(self, world: int, k: int) -> np.ndarray:
        """(T + 1, n + 1): robot ``k`` then the humans of ``world`` at each state of its episode (the ending row as above)."""
        end = int(self.ended_at[world, k]) if self.outcome[world, k] is not None else int(self.at[world])
        n = int(self._crowd[world])
        out = np.empty((end + 1, n + 1), complex)
        out[:, 0] = self._robots[: end + 1, world, k]
        if end and self.outcome[world, k] is not None:
            out[end, 0] = out[end - 1, 0]
        out[:, 1:] = self._humans[: end + 1, world, :n]
        return out

    def forces(self, world: int, k: int) -> np.ndarray:
        """(T,): the humans' social force on robot ``k`` of ``world`` after each step (0 at the step it ended)."""
        end = int(self.ended_at[world, k]) if self.outcome[world, k] is not None else int(self.at[world])
        out = self._forces[1 : end + 1, world, k].copy()
        if end and self.outcome[world, k] is not None:
            out[-1] = 0.0
        return out


def _grown(array: np.ndarray, shape: tuple[int, int, int], fill: Any) -> np.ndarray:
    out = np.full(shape, fill, dtype=array.dtype)
    out[: array.shape[0], :, : array.shape[2]] = array
    return out


def _shared(policy: Any) -> Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """A shared robot policy's actions for every robot of the playing worlds: their inputs (zero for a robot that left,
    every world's at once), the network's deterministic actions, each robot's command (:meth:`RobotActions.batch`).

    The network acts on one world's robots at a time, as many rows as :meth:`RobotsPolicy.act` gives it: torch's CPU
    matrix product picks its kernel by the number of rows (with MKL, fewer than 16 rows into a 2-wide layer sum in
    another order than 16 or more), so one pass over every world's rows would move the actions in their last bits and
    the episodes with them; each world's rows are copied into a tensor of their own, since a slice's memory alignment
    can decide the kernel too (AMD EPYC: a slice of the stacked rows moved returns in their 7th digit against a fresh
    array). What SB3's ``predict`` does around each pass (evaluation mode, no gradients, the tensor,
    the clip to the action space) is done once per step."""
    import torch

    network = policy.network
    low, high = network.action_space.low, network.action_space.high

    def act(observations: np.ndarray, acting: np.ndarray, running: np.ndarray, playing: np.ndarray) -> np.ndarray:
        w, r = acting.shape
        inputs = torch.as_tensor(policy.observe.rows(observations, acting).reshape(w, r, -1), device=network.device)
        actions = np.zeros((w, r, 2), np.float32)
        network.set_training_mode(False)
        with torch.no_grad():
            for world in np.flatnonzero(playing).tolist():
                actions[world] = network._predict(inputs[world].clone(), deterministic=True).cpu().numpy().reshape(r, 2)
        return np.asarray(policy.commands.batch(np.clip(actions, low, high), observations))

    return act


def _scripted(policy: ScriptedPolicy, engine: ScriptedRobotsEngine) -> Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """A scripted robot policy's actions: each running robot's as called with its view of its world
    (:meth:`crowdnav.envs.engines.robots.ScriptedRobotsEngine.scripted_actions`); 0 for a robot that ended."""

    def act(observations: np.ndarray, acting: np.ndarray, running: np.ndarray, playing: np.ndarray) -> np.ndarray:
        return engine.scripted_actions(policy, running & playing[:, None])

    return act


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
