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

The maths is written once for two array libraries: every function that computes takes ``xp``
(:class:`~crowdnav.agents.sarl.ops.Ops`), numpy's by default (:data:`~crowdnav.agents.sarl.ops.NUMPY`, float64, as
the agent acts in training, evaluation and the published runs), torch's in the ONNX export
(:class:`crowdnav.agents.sarl.export.TorchOps`, traced into the graph). Arrays are ``np.ndarray`` with numpy and
``torch.Tensor`` with torch (:data:`~crowdnav.agents.sarl.ops.Array`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from crowdnav.agents.sarl.ops import NUMPY, Array, Ops

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


def value_ceiling(distance: Array, physics: Physics, discount: float, xp: Ops = NUMPY) -> Array:
    """The largest discounted return any policy can collect from a state whose episode goes on, at goal ``distance`` (m).

    At least ``k = ceil((distance - goal_radius) / (max_speed * dt))`` more steps (1 at least), each paying the step
    cost; the discounted goal progress sums to at most ``w_goal_progress * distance`` (sum of ``discount^t (d_t -
    d_t+1)`` is ``d_0`` minus non-negative terms); the goal bonus at best on the k-th step; social and collision terms
    only cost. Valid when :func:`bounded_weights` holds; times the reward scale, as the lookahead's rewards.
    """
    w = physics.weights
    steps = xp.maximum(xp.ceil((distance - physics.goal_radius) / (physics.max_speed * physics.time_step) - 1e-9), 1.0)
    paid = w["step"] * (1.0 - xp.power(discount, steps)) / (1.0 - discount)
    return (paid + w["goal_progress"] * distance + xp.power(discount, steps - 1.0) * w["goal_reached"]) * physics.reward_scale


def action_set(max_speed: float) -> np.ndarray:
    """(81, 2) velocities (m/s) in the goal frame: stop, then 5 speeds x 16 headings (heading 0 toward the goal)."""
    speeds = (np.exp(np.arange(1, SPEEDS + 1) / SPEEDS) - 1.0) / (np.e - 1.0) * max_speed
    angles = np.arange(HEADINGS) * (2.0 * np.pi / HEADINGS)
    moves = (speeds[:, None] * np.exp(1j * angles)[None, :]).ravel()
    moves = np.concatenate([[0.0], moves])
    return np.stack([moves.real, moves.imag], axis=-1)


def decode(observation: Mapping[str, Array], scales: Mapping[str, tuple[Array, Array]], xp: Ops = NUMPY,
           empty_static: bool = True) -> dict[str, Array]:
    """The joint state (robot frame, float64) of a raw or normalised observation, batched (leading axis) or not.

    Without the ``obstacles`` modality the state's ``static`` is empty (s = 0: the replay memory and the network take
    (..., 0, 4) features), or absent with ``empty_static=False`` (the exported graph then holds no zero-size tensor).
    """
    keys = (*REQUIRED_KEYS, *(key for key in OPTIONAL_KEYS if key in observation))
    raw = {key: xp.float64(observation[key]) for key in keys}
    for key, (offset, scale) in scales.items():
        if key in raw:
            raw[key] = raw[key] * scale + offset
    goal = raw["goal"]
    if xp.size(goal.shape[-1]) == 3:  # polar: distance, sin, cos
        goal = goal[..., :1] * xp.stack([goal[..., 2], goal[..., 1]])
    rows, velocity = raw["humans"], raw["velocity"]
    batch: tuple[Any, ...] = velocity.shape[:-1]
    present = xp.float64(rows[..., 5] > 0.5)
    state = {"goal": goal, "velocity": velocity, "positions": rows[..., 0:2],
             "velocities": (rows[..., 2:4] + velocity[..., None, :]) * present[..., None], "radii": rows[..., 4], "present": present}
    static = raw.get(STATIC_KEY)
    if static is None and empty_static:
        static = xp.zeros((*batch, 0, 3))
    if static is not None:
        static_present = xp.float64(static[..., 2] > 0.5)
        state.update(static=static[..., 0:2] * static_present[..., None], static_present=static_present)
    if GEODESIC_KEY in raw:
        state.update(geodesic=raw[GEODESIC_KEY], origin=xp.zeros_like(velocity))
    return state


def geodesic_at(grid: Array, origin: Array, spacing: float, xp: Ops = NUMPY) -> Array:
    """The distance to the goal (m) at ``origin`` (..., 2) on ``grid`` (..., g, g): bilinear, clamped to the grid's edge."""
    size = xp.size(grid.shape[-1])
    if size == 1:
        return xp.copy(grid[..., 0, 0])
    centre = size // 2
    u = xp.clip(origin[..., 0] / spacing + centre, 0.0, size - 1.0)
    v = xp.clip(origin[..., 1] / spacing + centre, 0.0, size - 1.0)
    i, j = xp.minimum(xp.floor(u), size - 2.0), xp.minimum(xp.floor(v), size - 2.0)
    fu, fv = u - i, v - j
    i, j = xp.int64(i), xp.int64(j)
    flat = grid.reshape(*grid.shape[:-2], size * size)

    def at(di: int, dj: int) -> Array:
        return xp.take(flat, ((i + di) * size + (j + dj))[..., None])[..., 0]

    return (at(0, 0) * (1 - fu) * (1 - fv) + at(1, 0) * fu * (1 - fv) + at(0, 1) * (1 - fu) * fv + at(1, 1) * fu * fv)


def _rotate(vectors: Array, cos: Array, sin: Array, xp: Ops = NUMPY) -> Array:
    """``vectors`` (..., 2) rotated by minus the angle of (cos, sin) (..., 1)."""
    x, y = vectors[..., 0], vectors[..., 1]
    return xp.stack([x * cos + y * sin, y * cos - x * sin])


def goal_direction(goal: Array, xp: Ops = NUMPY) -> tuple[Array, Array, Array]:
    """(distance, cos, sin) of the goal vectors (..., 2); at the goal itself the x axis."""
    distance = xp.norm(goal)
    safe = xp.where(distance > 1e-9, distance, 1.0)
    return distance, xp.where(distance > 1e-9, goal[..., 0] / safe, 1.0), xp.where(distance > 1e-9, goal[..., 1] / safe, 0.0)


def features(state: Mapping[str, Array], physics: Physics, xp: Ops = NUMPY) -> tuple[Array, Array, Array]:
    """The value network's input of joint states: robot (..., 3), humans (..., k, 7), static (..., s, 4) float32, goal frame.

    With the ``geodesic`` grid the robot's row has a fourth entry: the distance to the goal around obstacles. The
    static features are None where the state has no ``static`` (:func:`decode` with ``empty_static=False``).
    """
    radius = physics.radius
    distance, cos, sin = goal_direction(state["goal"], xp)
    parts = [distance[..., None], _rotate(state["velocity"], cos, sin, xp)]
    if "geodesic" in state:
        parts.append(geodesic_at(state["geodesic"], state["origin"], physics.geodesic_spacing, xp)[..., None])
    robot = xp.concatenate(parts) * FEATURE_SCALE
    c, s = cos[..., None], sin[..., None]
    positions, present = state["positions"], state["present"]
    gap = xp.norm(positions) - radius - state["radii"]
    humans = xp.concatenate([_rotate(positions, c, s, xp) * FEATURE_SCALE, _rotate(state["velocities"], c, s, xp) * FEATURE_SCALE,
                             state["radii"][..., None], gap[..., None] * FEATURE_SCALE, present[..., None]])
    statics: Any = None
    if "static" in state:
        static, here = state["static"], state["static_present"]
        static_gap = xp.norm(static) - radius
        statics = xp.concatenate([_rotate(static, c, s, xp) * FEATURE_SCALE, static_gap[..., None] * FEATURE_SCALE, here[..., None]])
        statics = xp.float32(statics * here[..., None])
    return xp.float32(robot), xp.float32(humans * present[..., None]), statics


def lookahead(state: Mapping[str, Array], physics: Physics, actions: Array, human_margin: float = 0.0, xp: Ops = NUMPY) -> dict[str, Any]:
    """Every action's next joint state, predicted reward and end, for B joint states (leading axis B) and M actions.

    ``actions`` (M, 2): velocities in the goal frame (:func:`action_set`). The robot moves at the action's velocity
    for one step, the humans at their observed velocities (constant velocity). Returns ``next`` (the joint states,
    axes (B, M, ...)), ``reward`` (B, M): the env's reward terms as the agent predicts them (step, goal progress,
    the social term at the next positions, goal reached, collision = a tracked human's disc, grown by ``human_margin``
    (m), touched at any time during the step, or the half-plane of a wall or a piece of furniture reached), times the
    reward scale; ``done``
    (B, M): a predicted collision or goal; ``commands`` (B, M, 2): the env actions in [-1, 1] (robot frame).
    """
    _, cos, sin = goal_direction(state["goal"], xp)
    # goal frame -> robot frame: rotate the actions by the goal's angle
    ax, ay = actions[None, :, 0], actions[None, :, 1]
    c, s = cos[:, None], sin[:, None]
    velocity = xp.stack([ax * c - ay * s, ax * s + ay * c])  # (B, M, 2) m/s, robot frame
    dt = physics.time_step
    goal = state["goal"][:, None, :] - velocity * dt
    relative = state["velocities"][:, None, :, :] - velocity[:, :, None, :]  # (B, M, k, 2)
    positions = state["positions"][:, None, :, :]
    after = positions + relative * dt
    # closest approach during the step (relative motion is a straight segment)
    speed2 = xp.sum(relative * relative, axis=-1)
    toward = -xp.sum(positions * relative, axis=-1)
    moving = speed2 > 1e-12
    t = xp.clip(xp.where(moving, toward / xp.where(moving, speed2, 1.0), 0.0), 0.0, dt)
    closest = xp.norm(positions + relative * t[..., None])
    present = xp.broadcast_to(state["present"][:, None, :], closest.shape)
    radii = xp.broadcast_to(state["radii"][:, None, :], closest.shape)
    # the margin: people leave the constant-velocity line within a step (by ~0.1 m in the figure4 room), so a move
    # predicted to pass closer than that is a collision to the chooser, not a near miss
    collision = xp.any((closest <= physics.radius + radii + human_margin) & (present > 0))
    # walls and furniture: the supporting half-plane at each nearest point (linear in time: the end of the step is closest)
    if "static" in state:  # absent only in the exported graph of an agent that reads no obstacles
        static, here = state["static"][:, None, :, :], state["static_present"][:, None, :]
        gap = xp.norm(static)
        normal = static / xp.where(gap > 1e-12, gap, 1.0)[..., None]
        clearance = gap - xp.sum(velocity[:, :, None, :] * normal, axis=-1) * dt  # (B, M, s)
        collision = collision | xp.any((clearance <= physics.radius) & (here > 0))
    distance_before = xp.norm(state["goal"])[:, None]
    distance_after = xp.norm(goal)
    reached = distance_after <= physics.goal_radius
    centre = xp.maximum(xp.norm(after), 1e-9)
    push = physics.social_strength * xp.exp((physics.radius + radii - centre) / physics.social_range) * present / centre
    social = xp.norm(-xp.sum(after * push[..., None], axis=-2))
    w = physics.weights
    reward = w["step"] + w["goal_progress"] * (distance_before - distance_after) + w["social"] * social
    reward = reward + xp.where(collision, w["collision"], xp.where(reached, w["goal_reached"], 0.0))
    commands = velocity / physics.max_speed
    commands = commands / xp.maximum(xp.norm(commands), 1.0)[..., None]
    shape: tuple[Any, ...] = velocity.shape[:2]  # (B, M)
    next_state = {"goal": goal, "velocity": velocity, "positions": after,
                  "velocities": xp.broadcast_to(state["velocities"][:, None], (*shape, *state["velocities"].shape[1:])),
                  "radii": radii, "present": present}
    if "static" in state:
        next_state.update(static=normal * (clearance * here)[..., None], static_present=xp.broadcast_to(here, clearance.shape))
    if "geodesic" in state:  # the grid stays where it was observed; the robot moves on it
        next_state.update(geodesic=xp.broadcast_to(state["geodesic"][:, None], (*shape, *state["geodesic"].shape[1:])),
                          origin=state["origin"][:, None, :] + velocity * dt)
    return {"next": next_state, "reward": reward * physics.reward_scale, "done": collision | reached, "commands": xp.float32(commands)}


def backup(ahead: Mapping[str, Any], value: Callable[[Mapping[str, Array]], Array], discount: float, xp: Ops = NUMPY) -> Array:
    """``r + discount * V(next)`` of every action (B, M) of a :func:`lookahead` (no value after a predicted collision or goal).

    ``value``: the joint states (B, M, ...) -> V (B, M) (the agent's network on :func:`features`, bounded or not).
    """
    return ahead["reward"] + discount * value(ahead["next"]) * xp.keep(ahead["done"])


def deepen(ahead: Mapping[str, Any], scores: Array, width: int, value: Callable[[Mapping[str, Array]], Array], physics: Physics,
           actions: Array, human_margin: float, discount: float, xp: Ops = NUMPY) -> Array:
    """Depth 2 (as SG-D3QN's pruned tree): the ``width`` best of :func:`backup`'s ``scores`` score ``r + discount * max_a' score'``.

    The other actions score -inf (the choice is among the expanded ones); an expanded action predicted to end the
    episode keeps its one-step reward.
    """
    width = min(width, xp.size(scores.shape[1]))
    best = xp.best(scores, width)  # (B, w)
    flat = {key: xp.rows(item, best) for key, item in ahead["next"].items()}  # (B * w, ...)
    second = xp.row_max(backup(lookahead(flat, physics, actions, human_margin, xp), value, discount, xp)).reshape(-1, width)
    refined = xp.rows(ahead["reward"], best).reshape(-1, width) + discount * second * xp.keep(xp.rows(ahead["done"], best).reshape(-1, width))
    return xp.spread(scores, best, refined)
