"""The value network of the SARL-style agent: V(joint state) with attention pooling over the tracked humans.

Every human's row, next to the robot's own features, is embedded by an MLP; a score MLP reads each embedding and
the mean of all of them (the crowd as a whole) and a softmax over the present humans turns the scores into
attention weights; the weighted sum of second-stage features, with the robot's features, goes through a last MLP
to the value (Chen et al. 2019, "Crowd-Robot Interaction", Section IV; written here from the paper's description).
With nobody tracked the crowd feature is zero.

An agent that reads the room (the ``obstacles`` modality) has a second pool of the same form over the nearest walls
and pieces of furniture (:class:`StaticPool`); the last MLP then reads the robot's features, the crowd's pooled
feature and the room's. Without it the network is the published one, parameter for parameter.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from crowdnav.agents.sarl.lookahead import HUMAN_FEATURES, ROBOT_FEATURES, STATIC_FEATURES
from torch import nn


def mlp(sizes: Sequence[int], last_activation: bool) -> nn.Sequential:
    layers: list[nn.Module] = []
    for index, (inputs, outputs) in enumerate(zip(sizes[:-1], sizes[1:], strict=False)):
        layers.append(nn.Linear(inputs, outputs))
        if last_activation or index < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


def attention_pool(embed: nn.Module, feature: nn.Module, score: nn.Module, robot: torch.Tensor,
                   entities: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(pooled (N, h), attention (N, k)) of entity rows (N, k, f) whose last column is presence, beside the robot's features."""
    present = entities[..., -1] > 0.5  # (N, k)
    rows = torch.cat([robot[:, None, :].expand(-1, entities.shape[1], -1), entities], dim=-1)
    embedded = embed(rows)  # (N, k, h)
    weight = present.to(embedded.dtype)
    count = weight.sum(dim=1, keepdim=True).clamp(min=1.0)
    crowd = (embedded * weight[..., None]).sum(dim=1) / count  # (N, h) mean over the present entities
    scores = score(torch.cat([embedded, crowd[:, None, :].expand_as(embedded)], dim=-1))[..., 0]
    scores = scores.masked_fill(~present, -1e9)  # finite: a row with nobody gives no NaN
    attention = torch.softmax(scores, dim=1)
    attention = attention * weight  # nobody present: all zero
    return (attention[..., None] * feature(embedded)).sum(dim=1), attention


class StaticPool(nn.Module):
    """The attention pool over the nearest walls and pieces of furniture (rows of STATIC_FEATURES)."""

    def __init__(self, width: int, robot_features: int = ROBOT_FEATURES):
        super().__init__()
        half = max(width // 2, 1)
        self.embed = mlp([robot_features + STATIC_FEATURES, width, half], last_activation=True)
        self.feature = mlp([half, width, half], last_activation=False)
        self.score = mlp([2 * half, width, 1], last_activation=False)

    def forward(self, robot: torch.Tensor, statics: torch.Tensor) -> torch.Tensor:
        return attention_pool(self.embed, self.feature, self.score, robot, statics)[0]


class ValueNetwork(nn.Module):
    """``forward(robot (N, 3), humans (N, k, 7), statics (N, s, 4)) -> (N,)`` values; ``width`` sets every hidden layer's size.

    ``room``: the network reads the walls and furniture (a :class:`StaticPool`); without it ``statics`` is ignored.
    ``robot_features``: the width of the robot's row (4 with the distance to the goal around obstacles).
    """

    def __init__(self, width: int = 64, room: bool = False, robot_features: int = ROBOT_FEATURES):
        super().__init__()
        self.width = width
        half = max(width // 2, 1)
        self.embed = mlp([robot_features + HUMAN_FEATURES, width, half], last_activation=True)
        self.feature = mlp([half, width, half], last_activation=False)
        self.score = mlp([2 * half, width, 1], last_activation=False)
        self.value = mlp([robot_features + half * (2 if room else 1), width, width, 1], last_activation=False)
        self.room = StaticPool(width, robot_features) if room else None

    def forward(self, robot: torch.Tensor, humans: torch.Tensor, statics: torch.Tensor | None = None) -> torch.Tensor:
        return self.attend(robot, humans, statics)[0]

    def attend(self, robot: torch.Tensor, humans: torch.Tensor,
               statics: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """(values (N,), attention weights (N, k)): the forward pass and how much each human counted."""
        pooled, attention = attention_pool(self.embed, self.feature, self.score, robot, humans)
        parts = [robot, pooled]
        if self.room is not None:
            assert statics is not None, "a network that reads the room needs the statics' features"
            parts.append(self.room(robot, statics))
        return self.value(torch.cat(parts, dim=-1))[..., 0], attention


class ValueEnsemble(nn.Module):
    """``members`` value networks of one width, each initialised apart; ``forward`` is their mean value.

    Every member regresses on the same minibatches and the same target (the target ensemble's mean); the mean of
    independently initialised networks moves less from one update to the next than any one of them, so the greedy
    action changes less between snapshots (the policy churn of a single network is what moves a seed by a point or
    two over its last 500 episodes).
    """

    def __init__(self, width: int = 64, members: int = 2, room: bool = False, robot_features: int = ROBOT_FEATURES):
        super().__init__()
        self.width = width
        self.members = nn.ModuleList(ValueNetwork(width, room, robot_features) for _ in range(members))

    def forward(self, robot: torch.Tensor, humans: torch.Tensor, statics: torch.Tensor | None = None) -> torch.Tensor:
        return self.each(robot, humans, statics).mean(dim=0)

    def each(self, robot: torch.Tensor, humans: torch.Tensor, statics: torch.Tensor | None = None) -> torch.Tensor:
        """(members, N) values, one row per member."""
        return torch.stack([member(robot, humans, statics) for member in self.members])


def value_network(width: int, members: int, room: bool = False, robot_features: int = ROBOT_FEATURES) -> ValueNetwork | ValueEnsemble:
    """One network (``members`` 1: the published runs' parameter names and draws) or an ensemble of ``members``.

    ``room``: it reads the walls and furniture too (its static pool is built after the crowd's layers, so the crowd's
    initial weights are those of a network without it).
    """
    return ValueNetwork(width, room, robot_features) if members == 1 else ValueEnsemble(width, members, room, robot_features)


def evaluate(network: ValueNetwork | ValueEnsemble, robot: np.ndarray, humans: np.ndarray,
             statics: np.ndarray | None = None) -> np.ndarray:
    """Values (float64, leading axes of ``robot``) of feature arrays with any leading axes, without gradients."""
    lead = robot.shape[:-1]
    rows = int(np.prod(lead))  # explicit: a batch with 0 slots has no -1 to infer
    with torch.no_grad():
        values = network(torch.from_numpy(robot.reshape(rows, robot.shape[-1])),
                         torch.from_numpy(humans.reshape(rows, *humans.shape[-2:])),
                         None if statics is None else torch.from_numpy(statics.reshape(rows, *statics.shape[-2:])))
    return values.numpy().astype(np.float64).reshape(lead)
