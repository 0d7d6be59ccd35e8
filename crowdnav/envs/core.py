"""What both environments share: env options -> validated scenario, one simulator, the robot's
sensors and reward, action checks and the end-of-episode info.

The Gymnasium env (:mod:`crowdnav.envs.single`) and the PettingZoo env
(:mod:`crowdnav.envs.parallel`) are thin adapters around one :class:`EnvCore`; the only
difference is who commands the humans (the simulator's social-force model, or the actions of
the ``human_<i>`` agents).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from functools import cached_property, partial
from typing import Any, cast

import numpy as np
from gymnasium import spaces

from crowdnav.envs.engines.world_state import EnvState, WorldKey, WorldState, check_state, make_state, world_key
from crowdnav.envs.reward import Reward
from crowdnav.planning.shield import validate_shield
from crowdnav.rendering.episode_view import RENDER_MODES, EpisodeView, RenderOptions
from crowdnav.scenario import ScenarioIssue, library
from crowdnav.scenario.loader import LoadedScenario
from crowdnav.sensors import Modality, build_modalities
from crowdnav.sensors.tracked import TrackedView, attach
from crowdnav.sensors.tracker import make_tracker
from crowdnav.sim.episode_state import capture, restore
from crowdnav.sim.robot_view import RobotWorld
from crowdnav.sim.simulator import Simulator, StepEvents
from crowdnav.worlds.compiled import CompiledWorld, WorldSource, load_world
from crowdnav.yaml_input import check_value

ScenarioSource = WorldSource
"""A library name (``"room_furniture"``), a YAML path, a :class:`Scenario` or a parsed mapping."""
WORLD = np.zeros(1, dtype=np.intp)
"""The one world of an env's tracker (:class:`crowdnav.sensors.tracker.PeopleTracker` rows)."""


def option_overrides(
    modalities: Sequence[str] | None = None,
    sensors: Mapping[str, Any] | None = None,
    reward_weights: Mapping[str, float] | None = None,
    overrides: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Turn the env options into dotted scenario overrides, so they are validated like the file.

    ``{"lidar": {"beams": 180}}`` becomes ``{"sensors.lidar.beams": 180}``, reward weights become
    ``reward.<term>``, modalities ``sensors.modalities``. Options win over the same path in
    ``overrides``.
    """
    for option, value in (("modalities", modalities), ("sensors", sensors), ("reward_weights", reward_weights), ("overrides", overrides)):
        check_value(value, option)  # the limits of a file, before anything walks the value (ValueError)
    merged: dict[str, Any] = dict(_mapping("overrides", overrides))
    if modalities is not None:
        if isinstance(modalities, str) or not isinstance(modalities, Sequence):
            raise ValueError(f"modalities must be a list of observation keys, e.g. ['goal', 'lidar'], got {modalities!r}")
        merged["sensors.modalities"] = list(modalities)
    merged.update(_flatten("sensors", _mapping("sensors", sensors)))
    for term, weight in _mapping("reward_weights", reward_weights).items():
        merged[f"reward.{term}"] = weight
    return merged


def _mapping(option: str, value: Mapping[str, Any] | None) -> Mapping[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ValueError(f"{option} must be a mapping, got {type(value).__name__}: {value!r}")
    return value


def _flatten(prefix: str, tree: Mapping[str, Any]) -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        path = f"{prefix}.{key}"
        if isinstance(value, Mapping):
            flat.update(_flatten(path, value))
        else:
            flat[path] = value
    return flat


def load_env_world(scenario: ScenarioSource | None, overrides: Mapping[str, Any]) -> tuple[CompiledWorld, dict[str, Modality]]:
    """Load ``scenario`` with ``overrides``, compile its world and build its modalities, each once.

    Every problem is a ScenarioError naming the path (and the file's line where there is one):
    the scenario's (:func:`crowdnav.worlds.compiled.load_world`) and the modality names (checked by
    :func:`crowdnav.sensors.build_modalities`, the one place that knows the registered ones).
    """
    if scenario is None:
        raise ValueError(
            "a scenario is required: a library name "
            f"({', '.join(library.library_names())}) or the path to a YAML file"
        )
    world = load_world(scenario, overrides)
    sensors = world.scenario.sensors
    try:
        modalities = build_modalities(sensors.modalities, world, sensors)
    except ValueError as error:  # unknown or duplicate keys: report them like any other scenario field
        raise _source(world).error([ScenarioIssue("sensors.modalities", str(error))]) from None
    return world, modalities


def _source(world: CompiledWorld) -> LoadedScenario:
    """The file ``world`` was loaded from, for errors with file and line (:func:`crowdnav.worlds.compiled.load_world` records it)."""
    if world.source is None:
        raise RuntimeError("the world was compiled without load_world, so it has no source to name in an error")
    return world.source


def real_array(value: Any, what: str) -> np.ndarray:
    """``value`` as a float64 array, refusing what only looks numeric.

    Strings ("1"), booleans and complex numbers would convert silently (a complex action would
    lose its imaginary part), so they are a clear ValueError naming ``what``.
    """
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError):  # ragged nesting
        raise ValueError(f"{what} must be 2 numbers in [-1, 1], got {value!r}") from None
    if raw.dtype.kind not in "iuf":
        kind = {"b": "booleans", "c": "complex numbers", "U": "strings", "S": "bytes", "O": "Python objects"}.get(raw.dtype.kind, str(raw.dtype))
        raise ValueError(f"{what} must be 2 numbers (real, not {kind}), got {value!r}")
    return raw.astype(np.float64, copy=False)


def checked_residual(residual: Any, modalities: Mapping[str, Any]) -> bool:
    """The env option ``residual`` (a bool; it needs the ``plan`` modality among the observation keys)."""
    if not isinstance(residual, bool):
        raise ValueError(f"residual must be true or false, got {residual!r}")
    if residual and "plan" not in modalities:
        raise ValueError(f"residual: the action corrects the planner's move, so the observation keys must include plan; got {sorted(modalities)}")
    return residual


def checked_robot_action(action: Any) -> np.ndarray:
    """The robot action as a (2,) float64 array; a clear ValueError for a wrong type or shape, NaN or inf.

    Values outside [-1, 1] are valid and get clipped by the simulator.
    """
    values = real_array(action, "the robot action")
    if values.shape != (2,):
        raise ValueError(f"the robot action must have shape (2,), got shape {values.shape}: {action!r}")
    if not (math.isfinite(values[0]) and math.isfinite(values[1])):
        raise ValueError(f"the robot action must be finite (no NaN or inf), got {values.tolist()}")
    return values


class EnvCore:
    """One simulator with the robot's sensors and reward, configured from env options.

    ``modalities``: observation keys (default ``scenario.sensors.modalities``); ``sensors``:
    sensor-setting overrides (``{"lidar": {"beams": 180}}``); ``reward_weights``: reward-weight
    overrides (``{"social": -50}``); ``overrides``: dotted scenario paths to values
    (``{"humans.count": 10}``). All of them are validated like the scenario file. ``shield``:
    the action-time safety shield (:mod:`crowdnav.planning.shield`; True or its settings);
    ``residual``: the executed action is the ``plan`` observation plus the policy's action.
    """

    def __init__(
        self,
        scenario: ScenarioSource | None,
        *,
        modalities: Sequence[str] | None = None,
        sensors: Mapping[str, Any] | None = None,
        reward_weights: Mapping[str, float] | None = None,
        overrides: Mapping[str, Any] | None = None,
        render_mode: str | None = None,
        render_options: RenderOptions | Mapping[str, Any] | None = None,
        shield: bool | Mapping[str, Any] | None = None,
        residual: bool = False,
    ):
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(f"render_mode={render_mode!r} is not supported; expected None or one of {RENDER_MODES}")
        world, self.modalities = load_env_world(scenario, option_overrides(modalities, sensors, reward_weights, overrides))
        self.scenario = world.scenario
        self.simulator = Simulator(world)
        self.tracker = make_tracker(world, 1)
        """The robot's people tracker (``sensors.tracker``; None: ``perfect``), stepped with the simulator."""
        if self.tracker is not None:  # a scripted policy called with the simulator reads these tracks too
            attach(self.simulator, partial(self.tracker.columns, WORLD))
        self.shield = validate_shield(dict(shield) if isinstance(shield, Mapping) else shield, world)
        self.shielded = False
        """Whether the shield replaced the last step's action (docs/agents.md#the-safety-shield)."""
        self.residual = checked_residual(residual, self.modalities)
        self.observation_space = spaces.Dict({key: modality.space() for key, modality in self.modalities.items()})
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.reward = Reward(self.scenario.reward)
        # Observe in the space's key order so observations print like the space.
        self._sensors = tuple((key, self.modalities[key]) for key in self.observation_space.spaces)
        # the tracker's view is built only where an observation reads it (a profile with, e.g., goal + lidar reads none)
        self._reads_tracker = self.tracker is not None and any(modality.reads_tracker for _, modality in self._sensors)
        self._running = False
        self.render_mode = render_mode
        self.view = EpisodeView(self.simulator, render_mode, render_options) if render_mode else None
        self._observation: dict[str, np.ndarray] = {}
        self.plain = self.simulator.team is None and self.shield is None and not self.residual and self.view is None and self.tracker is None
        """One robot, no shield, residual plan, render_mode or tracker: :meth:`step_plain` steps it (the envs' common case)."""
        self.robot_names: list[str] = self.scenario.robot_names
        """Every robot's agent name, the ego robot first (``["robot"]`` for one robot)."""
        self.robot_spaces: list[spaces.Dict] = [self.observation_space]
        """Every robot's observation space, the ego robot first."""
        self.robot_rewards = [self.reward]
        """Every robot's reward, the ego robot first."""
        if self.simulator.team is not None:
            self._build_robot_sensors(world)

    def _build_robot_sensors(self, world: CompiledWorld) -> None:
        """Each robot's own modalities (``robots.<i>.modalities``, default ``sensors.modalities``), built with its own spec."""
        scenario, sensors = self.scenario, self.scenario.sensors
        self._robot_sensors = []
        for k, robot in enumerate(scenario.robot_specs):
            own = getattr(robot, "modalities", None)
            keys = own if own is not None else sensors.modalities
            try:
                built = build_modalities(keys, dataclasses.replace(world, scenario=self.simulator.robot_scenario(k)), sensors)
            except ValueError as error:
                field = f"robots.{k}.modalities" if own is not None else "sensors.modalities"
                raise _source(world).error([ScenarioIssue(field, str(error))]) from None
            space = spaces.Dict({key: modality.space() for key, modality in built.items()})
            self._robot_sensors.append(tuple((key, built[key]) for key in space.spaces))
            if k == 0:
                self.modalities, self.observation_space = built, space
            else:
                self.robot_spaces.append(space)
                self.robot_rewards.append(Reward(scenario.reward))
        self.robot_spaces[0] = self.observation_space
        self._sensors = self._robot_sensors[0]

    def reset(self, seed: int | None) -> dict[str, np.ndarray]:
        self.simulator.reset(seed=seed)
        if self.tracker is not None:
            sim = self.simulator
            self.tracker.start(WORLD, [seed])
            self.tracker.update(WORLD, sim.positions[None], sim.velocities[:1], np.array([sim.robot_heading]), sim.radii)
        self.reward.reset(self.simulator)
        for k, reward in enumerate(self.robot_rewards[1:], start=1):
            reward.reset(self.simulator.robot_view(k))
        self._running = True
        if self.view is not None:
            self.view.on_reset()
        return self.observe()

    def observe_robot(self, index: int, view: RobotWorld | None = None,
                      given: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
        """Robot ``index``'s observation of the current state (several robots; new arrays every call).

        Its range sensors see the other robots among the humans; a modality that tracks people
        (``sees_robots`` False, e.g. ``humans``) sees the humans only. ``view``: ``sim.robot_view(index)``
        if the caller already made it; ``given``: readings the caller already made of this state
        (the native vector env's batched LIDAR), taken as they are.
        """
        sim = self.simulator
        view = view if view is not None else sim.robot_view(index)
        people: RobotWorld | None = None
        observation = {}
        for key, modality in self._robot_sensors[index]:
            if given is not None and key in given:
                observation[key] = given[key]
            elif modality.sees_robots:
                observation[key] = modality.observe(view)
            else:
                people = people if people is not None else sim.robot_view(index, with_robots=False)
                observation[key] = modality.observe(people)
        return observation

    def observe(self, view: RobotWorld | None = None, given: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
        """The robot's observation of the current state (new arrays every call).

        The envs call it once per reset/step, which is when ``human`` mode draws its window.
        ``view`` / ``given`` (several robots): as for :meth:`observe_robot`.
        """
        sim = self.simulator
        if self._reads_tracker:
            people = self.people()
            self._observation = {key: modality.observe(people if modality.reads_tracker else sim) for key, modality in self._sensors}
        elif sim.team is None:
            self._observation = {key: modality.observe(sim) for key, modality in self._sensors}
        else:
            self._observation = self.observe_robot(0, view, given)
        if self.render_mode == "human" and self.view is not None:  # (human mode always has a view)
            self.view.render(self._observation)
        return self._observation

    def step(self, action: Any, human_actions: np.ndarray | None = None,
             other_robot_actions: np.ndarray | None = None) -> tuple[StepEvents, float, dict[str, float]]:
        """Advance the simulator; returns the ego robot's (events, reward, reward terms).

        ``other_robot_actions``: with several robots, the (R-1, 2) actions of the others (None: they stand still).
        """
        if not self._running:
            raise RuntimeError("the episode is over or has not started: call reset() before step()")
        action = checked_robot_action(action)
        if self.residual:  # the policy's action corrects the plan it observed
            action = action + self._observation["plan"]
        if self.shield is not None:
            action, self.shielded = self.shield.single(self.people(), action)
        events = self.simulator.step(action, human_actions, other_robot_actions)
        if self.tracker is not None:
            sim = self.simulator
            self.tracker.update(WORLD, sim.positions[None], sim.velocities[:1], np.array([sim.robot_heading]), sim.radii)
        reward, terms = self.reward(self.simulator, events)
        if events.terminated or events.truncated:
            self._running = False
        if self.view is not None:
            self.view.on_step(reward, events)
        return events, reward, terms

    def step_plain(self, action: Any, checked: bool = False) -> tuple[dict[str, np.ndarray], StepEvents, float, dict[str, float]]:
        """:meth:`step` then :meth:`observe` of a :attr:`plain` core, in one call: (observation, events, reward, terms).

        The same work in the same order, without the branches a plain core never takes: each call layer costs the
        single env about half a microsecond a step, about 0.5% of a light step (docs/environments.md#performance).
        ``checked``: ``action`` is already what :func:`checked_robot_action` makes of it (the vector env checked it).
        """
        if not self._running:
            raise RuntimeError("the episode is over or has not started: call reset() before step()")
        sim = self.simulator
        events = sim.step(action if checked else checked_robot_action(action))
        reward, terms = self.reward(sim, events)
        if events.terminated or events.truncated:
            self._running = False
        self._observation = {key: modality.observe(sim) for key, modality in self._sensors}
        return self._observation, events, reward, terms

    def step_robots(
        self, actions: Sequence[np.ndarray | None], human_actions: np.ndarray | None = None
    ) -> list[tuple[StepEvents, float, dict[str, float]] | None]:
        """Advance the simulator with every robot's action (None: a robot that left); each robot's (events, reward, terms).

        A robot that had left gets None. The episode is over once every robot's is over (or at the time limit).
        """
        if not self._running:
            raise RuntimeError("the episode is over or has not started: call reset() before step()")
        sim = self.simulator
        still = np.zeros(2)
        ego = checked_robot_action(actions[0]) if actions[0] is not None else still
        others = np.array([checked_robot_action(a) if a is not None else still for a in actions[1:]]).reshape(-1, 2)
        sim.step(ego, human_actions, others)
        results: list[tuple[StepEvents, float, dict[str, float]] | None] = []
        for k, events in enumerate(sim.robot_events):
            if events is None:
                results.append(None)
                continue
            reward, terms = self.robot_rewards[k](sim.robot_view(k), events)
            results.append((events, reward, terms))
        if all(result is None or result[0].terminated or result[0].truncated for result in results):
            self._running = False
        if self.view is not None and results[0] is not None:
            self.view.on_step(results[0][1], results[0][0])
        return results

    @cached_property
    def world_key(self) -> WorldKey:
        """What a world state must match to load here (:func:`crowdnav.envs.engines.world_state.world_key`, made on first use)."""
        return world_key(self.scenario)

    def snapshot(self, other_outcomes: dict[str, str | None]) -> WorldState:
        """The world now (:class:`crowdnav.envs.engines.world_state.WorldState`, copies), the env's ``other_outcomes`` with it."""
        observation = {key: values.copy() for key, values in self._observation.items()}
        return make_state(self.world_key, capture(self.simulator), tuple(reward.previous_distance for reward in self.robot_rewards),
                          None if self.tracker is None else self.tracker.row_state(0), EnvState(self._running, dict(other_outcomes), observation))

    def load(self, state: WorldState) -> tuple[dict[str, np.ndarray], EnvState | None]:
        """Make ``state`` (checked: :func:`crowdnav.envs.engines.world_state.check_state`) the world's, on copies: (the observation, its env
        part). Without one (the stacked engine's) it runs on, observed again, a tracker waiting for its first detections making them."""
        state = check_state(state, self.world_key)
        sim, env = self.simulator, state.env
        restore(sim, state.episode)
        for reward, distance in zip(self.robot_rewards, state.rewards, strict=True):
            reward.previous_distance = distance
        if self.tracker is not None and state.tracker is not None:  # (the same sensors: checked)
            self.tracker.load_row(0, state.tracker)
            if len(self.tracker.pending):  # as reset() does
                self.tracker.update(WORLD, sim.positions[None], sim.velocities[:1], np.array([sim.robot_heading]), sim.radii)
        self._running = True if env is None else env.running
        self._observation = self.observe() if env is None else {key: values.copy() for key, values in env.observation.items()}
        return self._observation, env

    def people(self) -> RobotWorld:
        """The world as the robot's tracker reports the people now (:mod:`crowdnav.sensors.tracked`; ``perfect``: the simulator)."""
        if self.tracker is None:
            return self.simulator
        return cast(RobotWorld, TrackedView(self.simulator, self.tracker.columns(WORLD, self.simulator.n_humans)))

    def render(self) -> np.ndarray | None:
        """The current frame (``rgb_array``), a window update (``human``) or None without a render_mode."""
        if self.view is None:
            return None
        return self.view.render(self._observation)

    def close(self) -> None:
        if self.view is not None:
            self.view.close()


def step_info(events: StepEvents, terms: dict[str, float]) -> dict[str, Any]:
    """The robot's info: reward terms every step; outcome, is_success, collision kind/partner at the end.

    ``info["outcome"]`` is one of :data:`crowdnav.sim.simulator.OUTCOMES`: ``success``, ``collision``,
    ``out_of_bounds`` (the robot's centre left the world of a scenario without boundary walls) or
    ``truncated``; ``is_success`` is True only for ``success``. ``collision_kind`` and
    ``collision_partner`` are there after a collision only.
    """
    info: dict[str, Any] = {"reward_terms": terms}
    outcome = events.outcome
    if outcome is not None:
        info["outcome"] = outcome
        info["is_success"] = outcome == "success"
        if events.collision is not None:
            info["collision_kind"] = events.collision.kind
            info["collision_partner"] = events.collision.partner
    return info
