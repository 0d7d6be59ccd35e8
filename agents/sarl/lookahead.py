"""The one-step lookahead of the SARL-style agent: its observation decoded, its 81 actions, and every action's next state.

Everything here is computed from the agent's observation alone (the ``humans``, ``goal`` and ``velocity``
modalities, in the robot frame) and from constants of the task the agent is told once, at construction
(:class:`Physics`: its own radius, speed and step, its goal radius, the reward weights and the social term's
parameters). Nothing reads the simulator.

A joint state is six arrays in one common frame (any rotation of the robot frame), leading axes free:

* ``goal`` (..., 2): the goal relative to the robot (m); ``velocity`` (..., 2): the robot's velocity (m/s);
* ``positions`` (..., k, 2): the k tracked humans' centres relative to the robot (m); ``velocities`` (..., k, 2):
  their velocities (m/s, not relative); ``radii`` (..., k) (m); ``present`` (..., k): 1 for a tracked human.

:func:`features` turns one into the value network's input, rotated so that the goal lies on the x axis (the
value of a state does not depend on which way the robot frame points).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

SPEEDS = 5
"""Speeds of the action set, exponentially spaced up to the robot's max speed."""
HEADINGS = 16
"""Headings of the action set, evenly spaced, the first one toward the goal."""
ROBOT_FEATURES = 3
"""Per joint state: goal distance, the robot's velocity along and across the goal direction."""
HUMAN_FEATURES = 7
"""Per human: position (2), velocity (2), radius, surface gap to the robot, presence; goal frame."""
FEATURE_SCALE = 0.25
"""Metres and m/s are multiplied by this in the features (the circle crossing's 8 m become 2)."""
REQUIRED_KEYS = ("humans", "goal", "velocity")


@dataclass(frozen=True)
class Physics:
    """What the agent knows of its task: constants of the scenario and the reward weights, never the state."""

    radius: float
    max_speed: float
    time_step: float
    goal_radius: float
    social_strength: float
    social_range: float
    weights: dict[str, float]
    """Reward weights: step, goal_progress, social, goal_reached, collision."""
    reward_scale: float = 1.0

    @classmethod
    def of_scenario(cls, scenario: Any, reward_scale: float) -> Physics:
        """The constants of a crowdnav scenario and its reward weights (read once, before any episode)."""
        reward = scenario.reward
        force = scenario.humans.social_force
        weights = {term: float(getattr(reward, term)) for term in ("step", "goal_progress", "social", "goal_reached", "collision")}
        return cls(float(scenario.robot.radius), float(scenario.robot.max_speed), float(scenario.time_step),
                   float(scenario.robot.goal_radius), float(force.human_strength), float(force.human_range), weights, float(reward_scale))

    def to_json(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_json(cls, document: Mapping[str, Any]) -> Physics:
        return cls(**{**document, "weights": dict(document["weights"])})


def bounded_weights(physics: Physics) -> bool:
    """Whether the reward's signs bound every return from above (:func:`value_ceiling`): costs <= 0, goal terms >= 0."""
    w = physics.weights
    return w["step"] <= 0 and w["social"] <= 0 and w["collision"] <= 0 and w["goal_progress"] >= 0 and w["goal_reached"] >= 0


def value_ceiling(distance: np.ndarray, physics: Physics, discount: float) -> np.ndarray:
    """The largest discounted return any policy can collect from a state whose episode goes on, at goal ``distance`` (m).

    At least ``k = ceil((distance - goal_radius) / (max_speed * dt))`` more steps (1 at least), each paying the step
    cost; the discounted goal progress sums to at most ``w_goal_progress * distance`` (sum of ``discount^t (d_t -
    d_t+1)`` is ``d_0`` minus non-negative terms); the goal bonus at best on the k-th step; social and collision terms
    only cost. Valid when :func:`bounded_weights` holds; times the reward scale, as the lookahead's rewards.
    """
    w = physics.weights
    steps = np.maximum(np.ceil((distance - physics.goal_radius) / (physics.max_speed * physics.time_step) - 1e-9), 1.0)
    paid = w["step"] * (1.0 - discount ** steps) / (1.0 - discount)
    return (paid + w["goal_progress"] * distance + discount ** (steps - 1.0) * w["goal_reached"]) * physics.reward_scale


def action_set(max_speed: float) -> np.ndarray:
    """(81, 2) velocities (m/s) in the goal frame: stop, then 5 speeds x 16 headings (heading 0 toward the goal)."""
    speeds = (np.exp(np.arange(1, SPEEDS + 1) / SPEEDS) - 1.0) / (np.e - 1.0) * max_speed
    angles = np.arange(HEADINGS) * (2.0 * np.pi / HEADINGS)
    moves = (speeds[:, None] * np.exp(1j * angles)[None, :]).ravel()
    moves = np.concatenate([[0.0], moves])
    return np.stack([moves.real, moves.imag], axis=-1)


def decode(observation: Mapping[str, np.ndarray], scales: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> dict[str, np.ndarray]:
    """The joint state (robot frame, float64) of a raw or normalised observation, batched (leading axis) or not."""
    raw = {key: np.asarray(observation[key], dtype=np.float64) for key in REQUIRED_KEYS}
    for key, (offset, scale) in scales.items():
        if key in raw:
            raw[key] = raw[key] * scale + offset
    goal = raw["goal"]
    if goal.shape[-1] == 3:  # polar: distance, sin, cos
        goal = goal[..., :1] * np.stack([goal[..., 2], goal[..., 1]], axis=-1)
    rows, velocity = raw["humans"], raw["velocity"]
    present = (rows[..., 5] > 0.5).astype(np.float64)
    return {"goal": goal, "velocity": velocity, "positions": rows[..., 0:2],
            "velocities": (rows[..., 2:4] + velocity[..., None, :]) * present[..., None], "radii": rows[..., 4], "present": present}


def _rotate(vectors: np.ndarray, cos: np.ndarray, sin: np.ndarray) -> np.ndarray:
    """``vectors`` (..., 2) rotated by minus the angle of (cos, sin) (..., 1)."""
    x, y = vectors[..., 0], vectors[..., 1]
    return np.stack([x * cos + y * sin, y * cos - x * sin], axis=-1)


def goal_direction(goal: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(distance, cos, sin) of the goal vectors (..., 2); at the goal itself the x axis."""
    distance = np.hypot(goal[..., 0], goal[..., 1])
    safe = np.where(distance > 1e-9, distance, 1.0)
    return distance, np.where(distance > 1e-9, goal[..., 0] / safe, 1.0), np.where(distance > 1e-9, goal[..., 1] / safe, 0.0)


def features(state: Mapping[str, np.ndarray], radius: float) -> tuple[np.ndarray, np.ndarray]:
    """The value network's input of joint states: robot (..., 3) and humans (..., k, 7) float32, in the goal frame."""
    distance, cos, sin = goal_direction(state["goal"])
    robot = np.concatenate([distance[..., None], _rotate(state["velocity"], cos, sin)], axis=-1) * FEATURE_SCALE
    c, s = cos[..., None], sin[..., None]
    positions, present = state["positions"], state["present"]
    gap = np.hypot(positions[..., 0], positions[..., 1]) - radius - state["radii"]
    humans = np.concatenate([_rotate(positions, c, s) * FEATURE_SCALE, _rotate(state["velocities"], c, s) * FEATURE_SCALE,
                             state["radii"][..., None], gap[..., None] * FEATURE_SCALE, present[..., None]], axis=-1)
    return robot.astype(np.float32), (humans * present[..., None]).astype(np.float32)


def lookahead(state: Mapping[str, np.ndarray], physics: Physics, actions: np.ndarray) -> dict[str, Any]:
    """Every action's next joint state, predicted reward and end, for B joint states (leading axis B) and M actions.

    ``actions`` (M, 2): velocities in the goal frame (:func:`action_set`). The robot moves at the action's velocity
    for one step, the humans at their observed velocities (constant velocity). Returns ``next`` (the joint states,
    axes (B, M, ...)), ``reward`` (B, M): the env's reward terms as the agent predicts them (step, goal progress,
    the social term at the next positions, goal reached, collision = a tracked human's disc touched at any time
    during the step), times the reward scale; ``done`` (B, M): a predicted collision or goal; ``commands`` (B, M, 2):
    the env actions in [-1, 1] (robot frame).
    """
    _, cos, sin = goal_direction(state["goal"])
    # goal frame -> robot frame: rotate the actions by the goal's angle
    ax, ay = actions[None, :, 0], actions[None, :, 1]
    c, s = cos[:, None], sin[:, None]
    velocity = np.stack([ax * c - ay * s, ax * s + ay * c], axis=-1)  # (B, M, 2) m/s, robot frame
    dt = physics.time_step
    goal = state["goal"][:, None, :] - velocity * dt
    relative = state["velocities"][:, None, :, :] - velocity[:, :, None, :]  # (B, M, k, 2)
    positions = state["positions"][:, None, :, :]
    after = positions + relative * dt
    # closest approach during the step (relative motion is a straight segment)
    speed2 = np.sum(relative * relative, axis=-1)
    toward = -np.sum(positions * relative, axis=-1)
    t = np.clip(np.divide(toward, speed2, out=np.zeros_like(speed2), where=speed2 > 1e-12), 0.0, dt)
    closest = np.hypot(*np.moveaxis(positions + relative * t[..., None], -1, 0))
    present = np.broadcast_to(state["present"][:, None, :], closest.shape)
    radii = np.broadcast_to(state["radii"][:, None, :], closest.shape)
    collision = np.any((closest <= physics.radius + radii) & (present > 0), axis=-1)
    distance_before = np.hypot(state["goal"][:, 0], state["goal"][:, 1])[:, None]
    distance_after = np.hypot(goal[..., 0], goal[..., 1])
    reached = distance_after <= physics.goal_radius
    centre = np.maximum(np.hypot(after[..., 0], after[..., 1]), 1e-9)
    push = physics.social_strength * np.exp((physics.radius + radii - centre) / physics.social_range) * present / centre
    social = np.hypot(*np.moveaxis(-np.sum(after * push[..., None], axis=-2), -1, 0))
    w = physics.weights
    reward = w["step"] + w["goal_progress"] * (distance_before - distance_after) + w["social"] * social
    reward = reward + np.where(collision, w["collision"], np.where(reached, w["goal_reached"], 0.0))
    commands = velocity / physics.max_speed
    commands /= np.maximum(np.hypot(commands[..., 0], commands[..., 1]), 1.0)[..., None]
    shape = velocity.shape[:2]
    next_state = {"goal": goal, "velocity": velocity, "positions": after,
                  "velocities": np.broadcast_to(state["velocities"][:, None], (*shape, *state["velocities"].shape[1:])),
                  "radii": radii, "present": present}
    return {"next": next_state, "reward": reward * physics.reward_scale, "done": collision | reached,
            "commands": commands.astype(np.float32)}
