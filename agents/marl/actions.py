"""How every robot reads the shared network's two action values (``robot_actions`` of ``agents: robots``).

One network acts for every robot of a multi-robot scenario, but each robot's env action means
what its kinematics say: a holonomic robot's ``(vx, vy)`` is a velocity in its own frame, a
unicycle's ``(v, omega)`` a forward speed and a turn rate. :class:`RobotActions` turns the
network's two values into each robot's env action:

* ``native`` (the default): they are each robot's env action as it is, so one network must learn
  two meanings of the same two numbers;
* ``velocity``: every robot is commanded the same way, by a desired velocity in its own frame in
  max-speed units (each value clipped to [-1, 1], the norm capped at 1, as a holonomic robot
  reads its action). A holonomic robot's action is the command itself (the same bits); a
  unicycle **tracks** it: it drives along its heading at the command's projection on it, never
  backwards (``max(0, x)``), and turns toward the command's direction as fast as one step allows
  (turn rate ``bearing / time_step``, clipped to ``max_angular_speed``), the rule the scripted
  baselines use to drive a unicycle at a velocity (:func:`crowdnav.planning.scripted.velocity_to_action`);
* ``goal_velocity``: the same, with the desired velocity in the robot's **goal frame** (x toward
  its goal, y to the left of that), the frame CrowdNav's robot-centric state is rotated into
  (Chen et al., "Crowd-robot interaction", ICRA 2019): ``(1, 0)`` drives any robot straight at
  its goal at full speed, whatever its heading. The goal direction is read from the robot's own
  ``goal`` observation (which must be observed), so training and a loaded policy rotate alike.

The adapter has no state: the action and (``goal_velocity``) the observation the network acted on
give the env action. It is applied where actions enter the env: in training, every world's robots at
once (:meth:`RobotActions.batch` in :class:`crowdnav.agents.marl.vec_env.RobotsVecEnv`, which still records
the network's own actions for an exact resume), in one world's robots-only env
(:class:`crowdnav.agents.marl.env.RobotsTrainingEnv`) and in a loaded policy's ``act``
(:class:`crowdnav.agents.marl.robots.RobotsPolicy`).
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from crowdnav.agents.training.config import ConfigError
from gymnasium import spaces

from crowdnav.batch.scalar_math import cdiv_real, cmul, phase

ROBOT_ACTION_MODES: tuple[str, ...] = ("native", "velocity", "goal_velocity")
"""The values of ``robot_actions`` (the first is the default)."""


def command(action: np.ndarray) -> complex:
    """The network's two values as a velocity command in max-speed units: each clipped to [-1, 1], the norm capped at 1."""
    local = complex(min(1.0, max(-1.0, float(action[0]))), min(1.0, max(-1.0, float(action[1]))))
    return local / abs(local) if abs(local) > 1.0 else local


def unicycle_action(velocity: complex, max_angular_speed: float, dt: float) -> np.ndarray:
    """The unicycle's env action ``(v, omega)`` in [-1, 1] that tracks ``velocity``, a command in its frame (norm at most 1).

    Forward speed: the projection on the heading, not below 0; turn: the bearing over ``dt``
    (reaching that direction within the step), in units of ``max_angular_speed``, clipped.
    """
    bearing = cmath.phase(velocity) if abs(velocity) > 1e-9 else 0.0
    turn = bearing / (max_angular_speed * dt)
    return np.clip(np.array([max(0.0, velocity.real), turn], dtype=np.float32), -1.0, 1.0)


def goal_slot(space: spaces.Dict, frame: str) -> tuple[int, str] | None:
    """Where a flat observation of ``space`` (its keys in order) holds the goal: (first index, ``polar``/``cartesian``); None without it."""
    offset = 0
    for key, part in space.spaces.items():
        if key == "goal":
            return offset, frame
        offset += int(spaces.flatdim(part))
    return None


class RobotActions:
    """The shared network's actions -> each robot's env action, by ``mode`` (module docstring).

    ``robots``: the scenario's robot specs (its order); ``goal``: where the flat observations hold
    the goal (:func:`goal_slot`), needed by ``goal_velocity`` only.
    """

    def __init__(self, mode: str, robots: Sequence[Any], dt: float, goal: tuple[int, str] | None = None):
        if mode not in ROBOT_ACTION_MODES:
            raise ConfigError(f"robot_actions must be one of {', '.join(ROBOT_ACTION_MODES)}; got {mode!r}")
        if mode == "goal_velocity" and goal is None:
            raise ConfigError("robot_actions: goal_velocity turns commands by the observed goal direction; add goal to the modalities")
        self.mode, self.dt, self.goal = mode, float(dt), goal
        self.turn_limits: list[float | None] = [
            None if robot.kinematics == "holonomic" else float(robot.max_angular_speed) for robot in robots]
        """Per robot (the scenario's order): None for a holonomic robot, else its max angular speed (rad/s)."""

    @classmethod
    def for_env(cls, mode: str, env: Any) -> RobotActions:
        """The adapter of a robots-only, flat-observation env's robots (``env.scenario``, its first robot's observation space)."""
        core = env.core
        goal = goal_slot(core.robot_spaces[0], core.modalities["goal"].frame) if "goal" in core.modalities else None
        return cls(mode, env.scenario.robot_specs, env.scenario.time_step, goal)

    @property
    def changes_actions(self) -> bool:
        """Whether any robot's action is rewritten (native never; velocity only with a unicycle among the robots)."""
        return self.mode == "goal_velocity" or (self.mode == "velocity" and any(limit is not None for limit in self.turn_limits))

    def goal_direction(self, observation: np.ndarray) -> complex:
        """The unit vector toward the goal in the robot frame, from a raw flat ``observation`` (straight ahead at the goal itself)."""
        assert self.goal is not None
        start, frame = self.goal
        if frame == "polar":  # (distance, sin, cos)
            direction = complex(float(observation[start + 2]), float(observation[start + 1]))
        else:  # (x, y)
            direction = complex(float(observation[start]), float(observation[start + 1]))
        length = abs(direction)
        return direction / length if length > 1e-12 and math.isfinite(length) else 1.0 + 0.0j

    def __call__(self, actions: Mapping[str, Any], names: Sequence[str],
                 observations: Mapping[str, np.ndarray] | None = None) -> Mapping[str, Any]:
        """Each robot's env action from the network's ``actions`` (keyed by the robot ``names``, in the scenario's order).

        ``observations``: the raw flat observations the network acted on (``goal_velocity`` reads
        the goal direction there). Native mode, or velocity mode without a unicycle: ``actions``
        itself, untouched. Robots missing from ``actions`` stay missing, and an action that is not
        2 finite values passes as it is, for the env to refuse in its own words.
        """
        if not self.changes_actions:
            return actions
        if self.mode == "goal_velocity" and observations is None:
            raise ValueError("robot_actions: goal_velocity needs the observations the actions answer")
        adapted = dict(actions)
        for name, limit in zip(names, self.turn_limits, strict=True):
            if name not in adapted:
                continue
            action = np.asarray(adapted[name], dtype=np.float64).reshape(-1)
            if action.shape != (2,) or not np.isfinite(action).all():
                continue
            velocity = command(action)
            if self.mode == "goal_velocity":
                assert observations is not None
                velocity *= self.goal_direction(np.asarray(observations[name]))
                if limit is None:
                    adapted[name] = np.array([velocity.real, velocity.imag], dtype=np.float32)
                    continue
            elif limit is None:
                continue
            adapted[name] = unicycle_action(velocity, limit, self.dt)
        return adapted

    def batch(self, actions: np.ndarray, observations: np.ndarray | None = None) -> np.ndarray:
        """:meth:`__call__` of every robot of many worlds: ``actions`` (W, R, 2) float32, ``observations`` the (W, R, D) raw flat
        observations they answer (``goal_velocity``) -> (W, R, 2) float32, each row the bits :meth:`__call__` gives it.

        Python's scalar complex arithmetic written as separately rounded array operations (:mod:`crowdnav.batch.scalar_math`;
        the bearing by libm's ``atan2`` per entry, as ``cmath.phase``), a loop over the robots only. A row that is not
        finite passes as it is (the engine refuses it for a robot in the world, as the env does).
        """
        actions = np.asarray(actions, dtype=np.float32)
        if not self.changes_actions:
            return actions
        if self.mode == "goal_velocity" and observations is None:
            raise ValueError("robot_actions: goal_velocity needs the observations the actions answer")
        wide = actions.astype(np.float64)
        a0, a1 = np.minimum(1.0, np.maximum(-1.0, wide[..., 0])), np.minimum(1.0, np.maximum(-1.0, wide[..., 1]))
        norm = np.hypot(a0, a1)
        over = norm > 1.0
        vr, vi = cdiv_real(a0, a1, np.where(over, norm, 1.0))  # local / abs(local) where the norm is over 1
        vr, vi = np.where(over, vr, a0), np.where(over, vi, a1)
        if self.mode == "goal_velocity":
            assert observations is not None
            vr, vi = cmul(vr, vi, *self._goal_directions(np.asarray(observations)))
        out = actions.copy()
        for k, limit in enumerate(self.turn_limits):  # each robot its own kinematics
            if limit is None:
                if self.mode == "goal_velocity":
                    out[:, k, 0], out[:, k, 1] = vr[:, k], vi[:, k]  # (float32, as np.array([re, im], float32))
                continue
            speed = np.hypot(vr[:, k], vi[:, k])
            bearing = np.where(speed > 1e-9, phase(vr[:, k], vi[:, k]), 0.0)
            forward = np.where(vr[:, k] > 0.0, vr[:, k], 0.0)  # max(0.0, x)
            out[:, k] = np.clip(np.stack([forward, bearing / (limit * self.dt)], axis=1).astype(np.float32), -1.0, 1.0)
        finite = np.isfinite(actions).all(axis=-1, keepdims=True)
        return np.where(finite, out, actions)

    def _goal_directions(self, observations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`goal_direction` of (..., D) raw flat observations: (re, im) of each unit vector toward the goal."""
        assert self.goal is not None
        start, frame = self.goal
        wide = observations.astype(np.float64)
        re, im = (wide[..., start + 2], wide[..., start + 1]) if frame == "polar" else (wide[..., start], wide[..., start + 1])
        length = np.hypot(re, im)
        usable = (length > 1e-12) & np.isfinite(length)
        dr, di = cdiv_real(re, im, np.where(usable, length, 1.0))
        return np.where(usable, dr, 1.0), np.where(usable, di, 0.0)
