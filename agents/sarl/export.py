"""ONNX export of the SARL-style agent: :meth:`SarlAgent.predict` (deterministic) as one torch module.

:class:`SarlPolicyModule` is what :meth:`crowdnav.agents.sarl.agent.SarlAgent.export_module` returns (the
``export_module`` side of :class:`crowdnav.agents.training.algorithm_protocol.Exportable`): the observation as ``predict``
receives it (crowdnav's normalisation already applied, batch first) in, the action ``(batch, 2)`` float32 out.
Inside, the numpy of :mod:`~crowdnav.agents.sarl.lookahead` written again in torch, step for step and in the same
precision (float64, the value network in float32):

* :func:`~crowdnav.agents.sarl.lookahead.decode`: the agent's stored scales undone, a polar goal made cartesian,
  the humans' absolute velocities;
* :func:`~crowdnav.agents.sarl.lookahead.lookahead`: the 81 actions, the humans at constant velocity, the closest
  approach during the step, the predicted reward and end;
* :func:`~crowdnav.agents.sarl.lookahead.features` and the value network, then ``r + discount * V * (not done)``;
  with ``lookahead_depth: 2`` the ``lookahead_width`` best actions looked ahead once more (``SarlAgent._deepen``);
* the first best action (``argmax`` as numpy's) and its command.

The only differences left are those of the kernels: ``hypot`` is ``sqrt(x * x + y * y)`` here, and onnxruntime's
float32 matrix products and ``exp`` may round otherwise than torch's. They move a score by about 1e-7 of its size,
which changes the chosen action only where two actions score that close (tests/agents/test_sarl_export.py; none
seen so far: the graph's actions have equalled ``predict``'s bit for bit).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import torch
from crowdnav.agents.sarl.lookahead import FEATURE_SCALE, GEODESIC_KEY, REQUIRED_KEYS, STATIC_KEY
from torch import nn

F64 = torch.float64


def _norm(vectors: torch.Tensor) -> torch.Tensor:
    """Length of ``vectors`` (..., 2) (numpy's ``hypot`` of the two components)."""
    x, y = vectors[..., 0], vectors[..., 1]
    return torch.sqrt(x * x + y * y)


def _rotate(vectors: torch.Tensor, cos: torch.Tensor, sin: torch.Tensor) -> torch.Tensor:
    """``vectors`` (..., 2) rotated by minus the angle of (cos, sin), as :func:`~crowdnav.agents.sarl.lookahead._rotate`."""
    x, y = vectors[..., 0], vectors[..., 1]
    return torch.stack([x * cos + y * sin, y * cos - x * sin], dim=-1)


def _direction(goal: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(distance, cos, sin) of goal vectors, as :func:`~crowdnav.agents.sarl.lookahead.goal_direction`."""
    distance = _norm(goal)
    far = distance > 1e-9
    safe = torch.where(far, distance, torch.ones_like(distance))
    cos = torch.where(far, goal[..., 0] / safe, torch.ones_like(distance))
    sin = torch.where(far, goal[..., 1] / safe, torch.zeros_like(distance))
    return distance, cos, sin


def _geodesic_at(grid: torch.Tensor, origin: torch.Tensor, spacing: float) -> torch.Tensor:
    """:func:`~crowdnav.agents.sarl.lookahead.geodesic_at`: bilinear on the grid (..., g, g) at ``origin`` (..., 2)."""
    size = int(grid.shape[-1])
    if size == 1:
        return grid[..., 0, 0]
    centre = size // 2
    u = torch.clamp(origin[..., 0] / spacing + centre, 0.0, size - 1.0)
    v = torch.clamp(origin[..., 1] / spacing + centre, 0.0, size - 1.0)
    i, j = torch.clamp(torch.floor(u), max=size - 2.0), torch.clamp(torch.floor(v), max=size - 2.0)
    fu, fv = u - i, v - j
    i, j = i.to(torch.int64), j.to(torch.int64)
    flat = grid.reshape(*grid.shape[:-2], size * size)

    def at(di: int, dj: int) -> torch.Tensor:
        return torch.gather(flat, -1, ((i + di) * size + (j + dj))[..., None])[..., 0]

    return at(0, 0) * (1 - fu) * (1 - fv) + at(1, 0) * fu * (1 - fv) + at(0, 1) * (1 - fu) * fv + at(1, 1) * fu * fv


class SarlPolicyModule(nn.Module):
    """``forward(*observation)`` (tensors in :attr:`keys` order, batch first) -> the agent's deterministic actions (batch, 2)."""

    actions: torch.Tensor  # (81, 2) goal-frame velocities, float64 (a buffer)

    def __init__(self, agent: Any, keys: Sequence[str]):
        super().__init__()
        missing = [key for key in REQUIRED_KEYS if key not in keys]
        if missing:
            raise ValueError(f"algorithm 'sarl' reads humans, goal and velocity; the observation has no {', '.join(missing)}")
        self.depth, self.width = int(agent.options["lookahead_depth"]), int(agent.options["lookahead_width"])
        if self.depth not in (1, 2):
            raise ValueError(f"algorithm 'sarl' with lookahead_depth {self.depth}: ONNX export covers depths 1 and 2")
        self.keys = list(keys)
        self.room = bool(agent.statics)  # it reads the walls and furniture (no static tensors in the graph otherwise)
        self.geodesic = bool(agent.geodesic)  # the distance to the goal around obstacles, on the modality's grid
        self.read = (*REQUIRED_KEYS, *((STATIC_KEY,) if self.room else ()), *((GEODESIC_KEY,) if self.geodesic else ()))
        missing = [key for key in self.read if key not in self.keys]
        if missing:
            raise ValueError(f"algorithm 'sarl' trained on {', '.join(missing)} reads it; the observation has no {', '.join(missing)}")
        self.index = {key: self.keys.index(key) for key in self.read}
        self.physics = agent.physics
        self.discount = float(agent.discount)
        self.register_buffer("actions", torch.as_tensor(agent.actions, dtype=F64))
        self.count = len(agent.actions)
        self.scaled = [key for key in self.read if key in agent.scales]
        for key in self.scaled:
            offset, scale = agent.scales[key]
            self.register_buffer(f"offset_{key}", torch.as_tensor(offset, dtype=F64))
            self.register_buffer(f"scale_{key}", torch.as_tensor(scale, dtype=F64))
        self.network = agent.network
        self.bounded = bool(agent.options["value_bound"])
        self.human_margin = float(agent.options["human_margin"])

    def decode(self, inputs: Sequence[torch.Tensor]) -> dict[str, torch.Tensor]:
        """The joint states (robot frame, float64), as :func:`~crowdnav.agents.sarl.lookahead.decode`."""
        raw = {key: inputs[self.index[key]].to(F64) for key in self.read}
        for key in self.scaled:
            raw[key] = raw[key] * getattr(self, f"scale_{key}") + getattr(self, f"offset_{key}")
        goal = raw["goal"]
        with warnings.catch_warnings():  # the tracer fixes this branch: only the batch axis of the graph's inputs varies
            warnings.filterwarnings("ignore", message="Converting a tensor to a Python boolean")  # torch's TracerWarning
            polar = bool(goal.shape[-1] == 3)
        if polar:  # distance, sin, cos
            goal = goal[..., :1] * torch.stack([goal[..., 2], goal[..., 1]], dim=-1)
        rows, velocity = raw["humans"], raw["velocity"]
        present = (rows[..., 5] > 0.5).to(F64)
        state = {"goal": goal, "velocity": velocity, "positions": rows[..., 0:2],
                 "velocities": (rows[..., 2:4] + velocity[..., None, :]) * present[..., None], "radii": rows[..., 4],
                 "present": present}
        if self.room:
            static = raw[STATIC_KEY]
            here = (static[..., 2] > 0.5).to(F64)
            state.update(static=static[..., 0:2] * here[..., None], static_present=here)
        if self.geodesic:
            state.update(geodesic=raw[GEODESIC_KEY], origin=torch.zeros_like(velocity))
        return state

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        ahead = self.lookahead(self.decode(inputs))
        scores = self.backup(ahead)
        if self.depth > 1:
            scores = self.deepen(ahead, scores)
        choice = torch.argmax(scores, dim=1)  # the first best, as numpy's
        return torch.gather(ahead["commands"], 1, choice[:, None, None].expand(-1, 1, 2))[:, 0, :]

    def lookahead(self, state: dict[str, torch.Tensor]) -> dict[str, Any]:
        """Every action's next joint state, reward, end and command, as :func:`~crowdnav.agents.sarl.lookahead.lookahead`."""
        p, w = self.physics, self.physics.weights
        _, cos, sin = _direction(state["goal"])
        ax, ay = self.actions[None, :, 0], self.actions[None, :, 1]
        c, s = cos[:, None], sin[:, None]
        velocity = torch.stack([ax * c - ay * s, ax * s + ay * c], dim=-1)  # (B, M, 2) m/s, robot frame
        dt = p.time_step
        goal = state["goal"][:, None, :] - velocity * dt
        relative = state["velocities"][:, None, :, :] - velocity[:, :, None, :]  # (B, M, k, 2)
        positions = state["positions"][:, None, :, :]
        after = positions + relative * dt
        speed2 = torch.sum(relative * relative, dim=-1)
        toward = -torch.sum(positions * relative, dim=-1)
        moving = speed2 > 1e-12
        t = torch.where(moving, toward / torch.where(moving, speed2, torch.ones_like(speed2)), torch.zeros_like(speed2))
        t = torch.clamp(t, 0.0, dt)
        closest = _norm(positions + relative * t[..., None])
        present = state["present"][:, None, :].expand_as(closest)
        radii = state["radii"][:, None, :].expand_as(closest)
        hits = (closest <= p.radius + radii + self.human_margin) & (present > 0)
        collision = hits.to(F64).sum(dim=-1) > 0
        if self.room:  # walls and furniture: the supporting half-plane at each nearest point (lookahead.lookahead)
            static, here = state["static"][:, None, :, :], state["static_present"][:, None, :]
            gap = _norm(static)
            normal = static / torch.where(gap > 1e-12, gap, torch.ones_like(gap))[..., None]
            clearance = gap - torch.sum(velocity[:, :, None, :] * normal, dim=-1) * dt
            collision = collision | (((clearance <= p.radius) & (here > 0)).to(F64).sum(dim=-1) > 0)
        distance_before = _norm(state["goal"])[:, None]
        distance_after = _norm(goal)
        reached = distance_after <= p.goal_radius
        centre = torch.clamp(_norm(after), min=1e-9)
        push = p.social_strength * torch.exp((p.radius + radii - centre) / p.social_range) * present / centre
        social = _norm(-torch.sum(after * push[..., None], dim=-2))
        reward = w["step"] + w["goal_progress"] * (distance_before - distance_after) + w["social"] * social
        zero = torch.zeros_like(reward)
        reward = reward + torch.where(collision, zero + w["collision"], torch.where(reached, zero + w["goal_reached"], zero))
        commands = velocity / p.max_speed
        commands = (commands / torch.clamp(_norm(commands), min=1.0)[..., None]).to(torch.float32)
        velocities = state["velocities"][:, None, :, :].expand_as(after)
        following = {"goal": goal, "velocity": velocity, "positions": after, "velocities": velocities, "radii": radii,
                     "present": present}
        if self.room:
            following.update(static=normal * (clearance * here)[..., None], static_present=here.expand_as(clearance))
        if self.geodesic:  # the grid stays where it was observed; the robot moves on it
            grid = state["geodesic"]
            following.update(geodesic=grid[:, None].expand(-1, velocity.shape[1], *grid.shape[1:]),
                             origin=state["origin"][:, None, :] + velocity * dt)
        return {"next": following, "reward": reward * p.reward_scale, "done": collision | reached, "commands": commands}

    def backup(self, ahead: dict[str, Any]) -> torch.Tensor:
        """``r + discount * V(next)`` of every action (B, M), V left out after a predicted end (``SarlAgent.scores``)."""
        values = self.value(ahead["next"])
        result: torch.Tensor = ahead["reward"] + self.discount * values * (~ahead["done"]).to(F64)
        return result

    def deepen(self, ahead: dict[str, Any], scores: torch.Tensor) -> torch.Tensor:
        """Depth 2: the ``width`` best actions score ``r + discount * max_a' score'``, the others -inf (``SarlAgent._deepen``).

        ``topk`` keeps the lower index of equal scores first in onnxruntime, as numpy's stable sort does (in the graph
        only which actions are expanded matters, not their order).
        """
        width = min(self.width, self.count)
        best = torch.topk(scores, width, dim=1).indices  # (B, w)

        def take(value: torch.Tensor) -> torch.Tensor:  # value (B, M, ...) -> (B, w, ...) at the best actions
            index = best.reshape(*best.shape, *([1] * (value.dim() - 2))).expand(-1, -1, *value.shape[2:])
            return torch.gather(value, 1, index)

        flat = {key: take(value).reshape(-1, *value.shape[2:]) for key, value in ahead["next"].items()}
        second = self.backup(self.lookahead(flat)).max(dim=1).values.reshape(-1, width)
        refined = take(ahead["reward"]) + self.discount * second * (~take(ahead["done"])).to(F64)
        return torch.full_like(scores, float("-inf")).scatter(1, best, refined)

    def value(self, state: dict[str, torch.Tensor]) -> torch.Tensor:
        """V of joint states (B, M) in float64: :func:`~crowdnav.agents.sarl.lookahead.features`, then the network."""
        distance, cos, sin = _direction(state["goal"])
        parts = [distance[..., None], _rotate(state["velocity"], cos, sin)]
        if self.geodesic:
            parts.append(_geodesic_at(state["geodesic"], state["origin"], self.physics.geodesic_spacing)[..., None])
        robot = torch.cat(parts, dim=-1) * FEATURE_SCALE
        c, s = cos[..., None], sin[..., None]
        positions, present, radii = state["positions"], state["present"], state["radii"]
        gap = _norm(positions) - self.physics.radius - radii
        humans = torch.cat([_rotate(positions, c, s) * FEATURE_SCALE, _rotate(state["velocities"], c, s) * FEATURE_SCALE,
                            radii[..., None], gap[..., None] * FEATURE_SCALE, present[..., None]], dim=-1)
        robot32, humans32 = robot.to(torch.float32), (humans * present[..., None]).to(torch.float32)
        statics32 = None
        if self.room:  # as lookahead.features
            static, here = state["static"], state["static_present"]
            statics = torch.cat([_rotate(static, c, s) * FEATURE_SCALE, (_norm(static) - self.physics.radius)[..., None] * FEATURE_SCALE,
                                 here[..., None]], dim=-1)
            statics32 = (statics * here[..., None]).to(torch.float32)
            statics32 = statics32.reshape(-1, *statics32.shape[-2:])
        values = self.network(robot32.reshape(-1, robot32.shape[-1]), humans32.reshape(-1, *humans32.shape[-2:]), statics32)
        values = values.reshape(-1, self.count).to(F64)
        return torch.minimum(values, self.ceiling(distance)) if self.bounded else values

    def ceiling(self, distance: torch.Tensor) -> torch.Tensor:
        """:func:`~crowdnav.agents.sarl.lookahead.value_ceiling` of goal distances (float64)."""
        p, w = self.physics, self.physics.weights
        steps = torch.clamp(torch.ceil((distance - p.goal_radius) / (p.max_speed * p.time_step) - 1e-9), min=1.0)
        paid = w["step"] * (1.0 - torch.pow(torch.full_like(steps, self.discount), steps)) / (1.0 - self.discount)
        bonus = torch.pow(torch.full_like(steps, self.discount), steps - 1.0) * w["goal_reached"]
        return (paid + w["goal_progress"] * distance + bonus) * p.reward_scale
