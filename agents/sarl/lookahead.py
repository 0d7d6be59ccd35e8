"""The one-step lookahead of the SARL-style agent: its observation decoded, its 81 actions, and every action's next state.

Everything here is computed from the agent's observation alone (the ``humans``, ``goal`` and ``velocity``
modalities, in the robot frame) and from constants of the task the agent is told once, at construction
(:class:`Physics`: its own radius, speed and step, its goal radius, the reward weights and the social term's
parameters). Nothing reads the simulator.

A joint state is six arrays in one common frame (any rotation of the robot frame), leading axes free:

* ``goal`` (..., 2): the goal relative to the robot (m); ``velocity`` (..., 2): the robot's velocity (m/s);
* ``positions`` (..., k, 2): the k tracked humans' centres relative to the robot (m); ``velocities`` (..., k, 2):
  their velocities (m/s, not relative); ``radii`` (..., k) (m); ``present`` (..., k): 1 for a tracked human;
* ``static`` (..., s, 2): the nearest surface point of each of the s nearest walls and pieces of furniture, relative
  to the robot (m; the ``obstacles`` modality, from the map and the pose); ``static_present`` (..., s). Without the
  ``obstacles`` modality s is 0: the agent sees no walls nor furniture.

* ``geodesic`` (..., g, g): the ``geodesic`` modality's grid of distances to the goal around walls and furniture
  (m, robot frame, centred on where the robot stood when it observed) and ``origin`` (..., 2): where the robot is now
  on that grid (0 when observed; the lookahead moves it). Absent without the modality.

A wall or piece of furniture is predicted by its supporting half-plane at that nearest point (the offset to it is
the surface's normal there): after a move ``m`` its clearance is ``|p| - m . p / |p|``, exact along a flat wall and
never more than the true clearance of a convex shape, so a predicted clear move past a table's corner is clear.

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
STATIC_FEATURES = 4
"""Per wall or piece of furniture: its nearest point (2), the surface gap to the robot, presence; goal frame."""
REQUIRED_KEYS = ("humans", "goal", "velocity")
STATIC_KEY = "obstacles"
"""The optional modality of the static world (:class:`crowdnav.sensors.obstacles.ObstaclesModality`)."""
GEODESIC_KEY = "geodesic"
"""The optional modality of the distance to the goal around obstacles (:class:`crowdnav.sensors.geodesic.GeodesicModality`)."""
OPTIONAL_KEYS = (STATIC_KEY, GEODESIC_KEY)


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
    geodesic_spacing: float = 0.1
    """Metres between the points of the ``geodesic`` modality's grid (its sensor setting)."""

    @classmethod
    def of_scenario(cls, scenario: Any, reward_scale: float) -> Physics:
        """The constants of a crowdnav scenario and its reward weights (read once, before any episode)."""
        reward = scenario.reward
        force = scenario.humans.social_force
        weights = {term: float(getattr(reward, term)) for term in ("step", "goal_progress", "social", "goal_reached", "collision")}
        return cls(float(scenario.robot.radius), float(scenario.robot.max_speed), float(scenario.time_step),
                   float(scenario.robot.goal_radius), float(force.human_strength), float(force.human_range), weights, float(reward_scale),
                   float(scenario.sensors.geodesic.spacing))

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
    keys = (*REQUIRED_KEYS, *(key for key in OPTIONAL_KEYS if key in observation))
    raw = {key: np.asarray(observation[key], dtype=np.float64) for key in keys}
    for key, (offset, scale) in scales.items():
        if key in raw:
            raw[key] = raw[key] * scale + offset
    goal = raw["goal"]
    if goal.shape[-1] == 3:  # polar: distance, sin, cos
        goal = goal[..., :1] * np.stack([goal[..., 2], goal[..., 1]], axis=-1)
    rows, velocity = raw["humans"], raw["velocity"]
    present = (rows[..., 5] > 0.5).astype(np.float64)
    static = raw.get(STATIC_KEY, np.zeros((*velocity.shape[:-1], 0, 3)))
    static_present = (static[..., 2] > 0.5).astype(np.float64)
    state = {"goal": goal, "velocity": velocity, "positions": rows[..., 0:2],
             "velocities": (rows[..., 2:4] + velocity[..., None, :]) * present[..., None], "radii": rows[..., 4], "present": present,
             "static": static[..., 0:2] * static_present[..., None], "static_present": static_present}
    if GEODESIC_KEY in raw:
        state.update(geodesic=raw[GEODESIC_KEY], origin=np.zeros_like(velocity))
    return state


def geodesic_at(grid: np.ndarray, origin: np.ndarray, spacing: float) -> np.ndarray:
    """The distance to the goal (m) at ``origin`` (..., 2) on ``grid`` (..., g, g): bilinear, clamped to the grid's edge."""
    size = grid.shape[-1]
    if size == 1:
        return grid[..., 0, 0].copy()
    centre = size // 2
    u = np.clip(origin[..., 0] / spacing + centre, 0.0, size - 1.0)
    v = np.clip(origin[..., 1] / spacing + centre, 0.0, size - 1.0)
    i, j = np.minimum(np.floor(u), size - 2.0), np.minimum(np.floor(v), size - 2.0)
    fu, fv = u - i, v - j
    i, j = i.astype(np.int64), j.astype(np.int64)
    flat = grid.reshape(*grid.shape[:-2], size * size)

    def at(di: int, dj: int) -> np.ndarray:
        return np.take_along_axis(flat, ((i + di) * size + (j + dj))[..., None], axis=-1)[..., 0]

    return (at(0, 0) * (1 - fu) * (1 - fv) + at(1, 0) * fu * (1 - fv) + at(0, 1) * (1 - fu) * fv + at(1, 1) * fu * fv)


def _rotate(vectors: np.ndarray, cos: np.ndarray, sin: np.ndarray) -> np.ndarray:
    """``vectors`` (..., 2) rotated by minus the angle of (cos, sin) (..., 1)."""
    x, y = vectors[..., 0], vectors[..., 1]
    return np.stack([x * cos + y * sin, y * cos - x * sin], axis=-1)


def goal_direction(goal: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(distance, cos, sin) of the goal vectors (..., 2); at the goal itself the x axis."""
    distance = np.hypot(goal[..., 0], goal[..., 1])
    safe = np.where(distance > 1e-9, distance, 1.0)
    return distance, np.where(distance > 1e-9, goal[..., 0] / safe, 1.0), np.where(distance > 1e-9, goal[..., 1] / safe, 0.0)


def features(state: Mapping[str, np.ndarray], physics: Physics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The value network's input of joint states: robot (..., 3), humans (..., k, 7), static (..., s, 4) float32, goal frame.

    With the ``geodesic`` grid the robot's row has a fourth entry: the distance to the goal around obstacles.
    """
    radius = physics.radius
    distance, cos, sin = goal_direction(state["goal"])
    parts = [distance[..., None], _rotate(state["velocity"], cos, sin)]
    if "geodesic" in state:
        parts.append(geodesic_at(state["geodesic"], state["origin"], physics.geodesic_spacing)[..., None])
    robot = np.concatenate(parts, axis=-1) * FEATURE_SCALE
    c, s = cos[..., None], sin[..., None]
    positions, present = state["positions"], state["present"]
    gap = np.hypot(positions[..., 0], positions[..., 1]) - radius - state["radii"]
    humans = np.concatenate([_rotate(positions, c, s) * FEATURE_SCALE, _rotate(state["velocities"], c, s) * FEATURE_SCALE,
                             state["radii"][..., None], gap[..., None] * FEATURE_SCALE, present[..., None]], axis=-1)
    static, here = state["static"], state["static_present"]
    static_gap = np.hypot(static[..., 0], static[..., 1]) - radius
    statics = np.concatenate([_rotate(static, c, s) * FEATURE_SCALE, static_gap[..., None] * FEATURE_SCALE, here[..., None]], axis=-1)
    return robot.astype(np.float32), (humans * present[..., None]).astype(np.float32), (statics * here[..., None]).astype(np.float32)


def lookahead(state: Mapping[str, np.ndarray], physics: Physics, actions: np.ndarray, human_margin: float = 0.0) -> dict[str, Any]:
    """Every action's next joint state, predicted reward and end, for B joint states (leading axis B) and M actions.

    ``actions`` (M, 2): velocities in the goal frame (:func:`action_set`). The robot moves at the action's velocity
    for one step, the humans at their observed velocities (constant velocity). Returns ``next`` (the joint states,
    axes (B, M, ...)), ``reward`` (B, M): the env's reward terms as the agent predicts them (step, goal progress,
    the social term at the next positions, goal reached, collision = a tracked human's disc, grown by ``human_margin``
    (m), touched at any time during the step, or the half-plane of a wall or a piece of furniture reached), times the
    reward scale; ``done``
    (B, M): a predicted collision or goal; ``commands`` (B, M, 2): the env actions in [-1, 1] (robot frame).
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
    # the margin: people leave the constant-velocity line within a step (by ~0.1 m in the figure4 room), so a move
    # predicted to pass closer than that is a collision to the chooser, not a near miss
    collision = np.any((closest <= physics.radius + radii + human_margin) & (present > 0), axis=-1)
    # walls and furniture: the supporting half-plane at each nearest point (linear in time: the end of the step is closest)
    static, here = state["static"][:, None, :, :], state["static_present"][:, None, :]
    gap = np.hypot(static[..., 0], static[..., 1])
    normal = static / np.where(gap > 1e-12, gap, 1.0)[..., None]
    clearance = gap - np.sum(velocity[:, :, None, :] * normal, axis=-1) * dt  # (B, M, s)
    collision |= np.any((clearance <= physics.radius) & (here > 0), axis=-1)
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
                  "radii": radii, "present": present, "static": normal * (clearance * here)[..., None],
                  "static_present": np.broadcast_to(here, clearance.shape)}
    if "geodesic" in state:  # the grid stays where it was observed; the robot moves on it
        next_state.update(geodesic=np.broadcast_to(state["geodesic"][:, None], (*shape, *state["geodesic"].shape[1:])),
                          origin=state["origin"][:, None, :] + velocity * dt)
    return {"next": next_state, "reward": reward * physics.reward_scale, "done": collision | reached,
            "commands": commands.astype(np.float32)}
