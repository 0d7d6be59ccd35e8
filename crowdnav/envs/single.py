"""The single-robot environment (Gymnasium): the robot is the agent, the crowd is simulated."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from crowdnav.envs.core import EnvCore, ScenarioSource, step_info
from crowdnav.envs.engines.world_state import WorldState
from crowdnav.planning.scripted import SCRIPTED_POLICIES
from crowdnav.rendering.episode_view import RENDER_MODES
from crowdnav.sim.events import StepEvents
from crowdnav.sim.robot_view import RobotWorld

OTHER_ROBOT_POLICIES = tuple(name for name in SCRIPTED_POLICIES if name != "random")
"""Names ``other_robots`` accepts (:data:`crowdnav.planning.scripted.SCRIPTED_POLICIES` but ``random``, which has no episode seed)."""


class CrowdNavEnv(gym.Env):
    """A robot navigating to its goal among social-force humans and static obstacles.

    **Agent.** The robot. The humans follow the simulator's built-in social-force model (the
    same :mod:`crowdnav.sim.forces` functions as :class:`crowdnav.SocialForcePolicy`); use
    :func:`crowdnav.parallel_env` to control them.

    **Action.** ``Box(-1, 1, (2,), float32)``. Holonomic robot: ``(vx, vy)`` in the robot frame
    (x forward, y left) times ``robot.max_speed``, the norm capped at 1. Unicycle robot:
    ``(v, omega)`` times ``(max_speed, max_angular_speed)``. Values outside [-1, 1] are
    clipped; a NaN or infinite value raises ValueError.

    **Observation.** ``Dict`` with one key per modality (``modalities`` option, default
    ``scenario.sensors.modalities``), each a float32 ``Box`` unless noted; see docs/sensors.md:

    * ``goal`` (3,) polar ``(distance m, sin, cos)`` of the goal's bearing in the robot frame,
      distance in [0, 2 x world diagonal]; or (2,) cartesian ``(x, y)`` m in the robot frame.
    * ``closest_obstacle`` (3,) polar or (2,) cartesian like ``goal``: the nearest point of any
      human or static obstacle, distance clipped to ``max_range`` (nothing in range: ``max_range``
      at bearing 0).
    * ``lidar`` (beams,) range / ``max_range`` in [0, 1] (1: nothing within range); beam k points
      at ``-fov/2 + fov * (k + 0.5) / beams`` from the heading, counter-clockwise.
    * ``leog`` (1, H, W) uint8 in {0, 255}, ``H = W = size / resolution``: local egocentric
      occupancy grid centred on the robot and turning with it, row 0 farthest ahead, column 0
      farthest left; 255 where a cell's centre is inside a human, round obstacle or polygon.
    * ``velocity`` (2,) the robot's velocity in the robot frame, m/s, in [-max_speed, max_speed].
    * ``humans`` (count, 6) float32: the nearest humans by surface distance within ``max_range``,
      one row each ``(x, y, vx, vy, radius, 1)`` (position and velocity relative to the robot, robot
      frame); absent rows all zero.

    **Reward.** Sum of the named terms of :mod:`crowdnav.envs.reward` (weights: scenario
    ``reward`` section, a preset plus single-term overrides, overridable with ``reward_weights``;
    docs/agents.md#reward), each in ``info["reward_terms"]`` every step, with ``d_t`` the
    robot-goal distance (m) after step t; in brackets the ``default`` preset, then the ``paper``
    preset: ``step = w_step`` (-0.1, -5); ``goal_progress = w_goal_progress * (d_{t-1} - d_t)``
    (5, 10); ``social = w_social * |F_social|`` (-1, -100), the humans' social-force repulsion on
    the robot; ``goal_reached = w_goal_reached`` (25, 500) and ``collision = w_collision`` (-25,
    -500) once, on the last step (``collision`` also when the robot leaves the world: outcome
    ``out_of_bounds``).

    **Episode end.** ``terminated`` when the robot reaches its goal (``outcome`` success),
    collides (``collision``) or leaves the world (``out_of_bounds``); ``truncated`` at
    ``scenario.max_steps`` otherwise (never both). The robot cannot escape the task: leaving the
    world (the robot's centre outside the scenario's ``world.min`` / ``world.max`` rectangle) is
    either impossible (``world.boundary_walls``: the walls are obstacles, touching them is a
    collision) or ends the episode with outcome ``out_of_bounds`` (open space), a failure that
    pays the ``collision`` reward term. Precedence within one step: collision > out_of_bounds >
    success > truncated. Every step's info holds ``outcome``
    (``"success" | "collision" | "out_of_bounds" | "truncated"``, :data:`crowdnav.sim.simulator.OUTCOMES`)
    and ``is_success`` (bool): on a terminating step how the episode ended, on any other step
    ``"truncated"`` and False, the outcome of an episode cut there (at ``max_steps``, or by a
    ``TimeLimit`` wrapper that the env cannot see); after a collision also ``collision_kind``
    (``"human" | "static"``) and ``collision_partner`` (``human_<i>`` or the obstacle's scenario
    path). ``human_stalls`` (int, every step): how many times a human stalled so far this episode
    (``humans.stall``, docs/simulator.md#stalled-humans). Calling step() after the end raises RuntimeError.

    **Options.** ``scenario``: library name, YAML path or :class:`crowdnav.Scenario`;
    ``modalities``; ``sensors`` (``{"lidar": {"beams": 180}}``); ``reward_weights``
    (``{"social": -50}``); ``overrides`` (``{"humans.count": 10}``); all validated like the
    scenario file (ScenarioError naming the path). ``render_mode``: None, ``"rgb_array"``
    (``render()`` returns a uint8 (H, W, 3) frame; no display needed) or ``"human"`` (a pygame
    window updated at every reset and step, at ``metadata["render_fps"]`` = 1 / time_step);
    ``render_options`` (:class:`crowdnav.rendering.RenderOptions` or a mapping of its fields:
    overlays for the LIDAR, LEOG inset, closest obstacle, humans' goals, frame size).
    ``shield``: None (default), True or a mapping of
    :class:`crowdnav.planning.predictive.PlannerSettings` fields: before each step, an action
    that the robot's own tracker (``humans`` sensor settings), its pose, the map and a
    constant-velocity prediction call unsafe is replaced by the nearest safe move
    (:mod:`crowdnav.planning.shield`); ``info["shielded"]`` says whether it was. Holonomic, one robot.
    ``residual``: False (default) or True: the executed action is the ``plan`` observation (the
    predictive planner's move from the robot's own sensing; the key must be observed) plus the
    policy's action, clipped like any action (then shielded, if the shield is on).

    **Several robots** (a scenario with ``robots:``): the agent is the first robot (its own
    modalities; its range sensors see the other robots, its ``humans`` modality the humans only).
    The others are driven by ``other_robots``: a name of :data:`OTHER_ROBOT_POLICIES`
    (``"social-force"``, the default; ``"straight"``; ``"orca"`` with pyrvo) or a callable
    ``policy(view) -> action`` called with :meth:`crowdnav.Simulator.robot_view` of each robot
    (one policy object per robot: a class is instantiated per robot, another callable shared).
    A robot that ends (success, collision, out of the world) leaves the world after that step (the
    step's observation still shows it, as in :func:`crowdnav.parallel_env`); the episode ends
    with the first robot's end or the time limit. ``info["other_robots"]`` maps each other
    robot's name to its outcome, None while it runs; a collision with another robot is
    ``collision_kind`` ``"robot"`` with its name as ``collision_partner``.
    """

    metadata = {"render_modes": RENDER_MODES, "render_fps": 5.0}

    def __init__(self, scenario: ScenarioSource | None = None, *, other_robots: str | Callable[..., Any] = "social-force",
                 **options: Any):
        # The engine both envs share (simulator, sensors, reward); it takes and checks the options.
        self.core = EnvCore(scenario, **options)
        self._other_names = self.core.robot_names[1:]
        self._other_policies = [_other_robot_policy(other_robots) for _ in self._other_names]
        self._other_outcomes: dict[str, str | None] = {}
        self.render_mode = self.core.render_mode
        self.scenario = self.core.scenario
        self.simulator = self.core.simulator
        self.metadata = {**self.metadata, "render_fps": 1.0 / self.scenario.time_step}
        self.observation_space = self.core.observation_space
        self.action_space = self.core.action_space

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Start an episode; the same seed gives the same episode. ``options`` is accepted and unused."""
        super().reset(seed=seed)
        observation = self.core.reset(seed)
        # The simulator's generator is the episode's only randomness: expose it as np_random.
        self._np_random = self.simulator.rng
        self._other_outcomes = dict.fromkeys(self._other_names)
        return observation, {}

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        return self.finish_step(*self.advance(action))

    def advance(self, action: np.ndarray) -> tuple[StepEvents, float, dict[str, float]]:
        """The first half of :meth:`step`: move the world (the other robots by their policies); (events, reward, terms)."""
        if self._other_names:
            return self.core.step(action, other_robot_actions=self._other_actions())
        return self.core.step(action)

    def finish_step(self, events: StepEvents, reward: float, terms: dict[str, float], view: RobotWorld | None = None,
                    given: dict[str, np.ndarray] | None = None) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """The second half of :meth:`step`: observe, take out the other robots that ended, the step's tuple.

        ``view`` / ``given``: the robot's view and readings the caller already made of this state
        (:meth:`crowdnav.envs.core.EnvCore.observe_robot`; the native vector env batches the LIDAR).
        """
        terminated = events.terminated
        truncated = events.truncated and not terminated
        info = step_info(events, terms)
        info["human_stalls"] = int(np.add.reduce(self.simulator.human_stalls))  # .sum() without its Python wrapper
        if self.core.shield is not None:
            info["shielded"] = self.core.shielded
        observation = self.core.observe(view, given)  # a robot that ends this step is still seen; it leaves after (as in parallel_env)
        if self._other_names:
            info["other_robots"] = self._others_after_step(terminated or truncated)
        if not terminated:
            # Any step that does not terminate may be the last one: a TimeLimit wrapper
            # (gymnasium.make(..., max_episode_steps=N)) truncates after this method returns, without
            # asking the env, so the info names the outcome the episode has if it stops here.
            info.setdefault("outcome", "truncated")
            info.setdefault("is_success", False)
        return observation, reward, terminated, truncated, info

    def _other_actions(self) -> np.ndarray:
        """(R-1, 2): each other robot's action from its policy (0 for a robot that left)."""
        sim = self.simulator
        active = sim.robots_active
        return np.array([np.asarray(policy(sim.robot_view(k)), dtype=float) if active[k] else np.zeros(2)
                         for k, policy in enumerate(self._other_policies, start=1)]).reshape(-1, 2)

    def _others_after_step(self, over: bool) -> dict[str, str | None]:
        """Record the other robots that ended this step and take them out of the world (unless the episode is over)."""
        ended = []
        for k, events in enumerate(self.simulator.robot_events[1:], start=1):
            if events is not None and events.terminated:
                self._other_outcomes[self._other_names[k - 1]] = events.outcome
                ended.append(k)
        if ended and not over:
            self.simulator.retire_robots(ended)
        return dict(self._other_outcomes)

    def snapshot(self) -> WorldState:
        """The world now: everything its future depends on given the actions (:class:`crowdnav.envs.engines.world_state.WorldState`, a copy
        that pickles; the state of a callable ``other_robots`` excepted)."""
        return self.core.snapshot(self._other_outcomes)

    def load(self, state: WorldState) -> dict[str, np.ndarray]:
        """Make ``state`` (a :meth:`snapshot` of a world of this scenario and options, or a vector env engine's) this env's world:
        it plays on as the captured world would. Returns the observation (the captured one). A ValueError names what differs."""
        observation, env = self.core.load(state)
        self._np_random = self.simulator.rng
        self._other_outcomes = dict.fromkeys(self._other_names) if env is None else dict(env.other_outcomes)
        return observation

    def render(self) -> np.ndarray | None:
        """The current frame in ``rgb_array`` mode (None in ``human`` mode, which draws at each step)."""
        return self.core.render() if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        self.core.close()


def _other_robot_policy(policy: str | Callable[..., Any]) -> Callable[..., Any]:
    """One other robot's policy from the ``other_robots`` option (a clear ValueError for an unknown name)."""
    if isinstance(policy, str):
        if policy not in OTHER_ROBOT_POLICIES:
            raise ValueError(f"other_robots={policy!r} is not a scripted robot policy; expected one of {OTHER_ROBOT_POLICIES} "
                             "or a callable policy(view) -> action")
        return SCRIPTED_POLICIES[policy]()
    if isinstance(policy, type):
        made: Callable[..., Any] = policy()
        return made
    if not callable(policy):
        raise ValueError(f"other_robots must be a policy name {OTHER_ROBOT_POLICIES} or a callable policy(view) -> action, got {policy!r}")
    return policy
