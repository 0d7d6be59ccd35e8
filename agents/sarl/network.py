"""The value network of the SARL-style agent: V(joint state) with attention pooling over the tracked humans.

Every human's row, next to the robot's own features, is embedded by an MLP; a score MLP reads each embedding and
the mean of all of them (the crowd as a whole) and a softmax over the present humans turns the scores into
attention weights; the weighted sum of second-stage features, with the robot's features, goes through a last MLP
to the value (Chen et al. 2019, "Crowd-Robot Interaction", Section IV; written here from the paper's description).
With nobody tracked the crowd feature is zero.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from crowdnav.agents.sarl.lookahead import HUMAN_FEATURES, ROBOT_FEATURES
from torch import nn


def mlp(sizes: Sequence[int], last_activation: bool) -> nn.Sequential:
    layers: list[nn.Module] = []
    for index, (inputs, outputs) in enumerate(zip(sizes[:-1], sizes[1:], strict=False)):
        layers.append(nn.Linear(inputs, outputs))
        if last_activation or index < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


class ValueNetwork(nn.Module):
    """``forward(robot (N, 3), humans (N, k, 7)) -> (N,)`` values; ``width`` sets every hidden layer's size."""

    def __init__(self, width: int = 64):
        super().__init__()
        self.width = width
        half = max(width // 2, 1)
        self.embed = mlp([ROBOT_FEATURES + HUMAN_FEATURES, width, half], last_activation=True)
        self.feature = mlp([half, width, half], last_activation=False)
        self.score = mlp([2 * half, width, 1], last_activation=False)
        self.value = mlp([ROBOT_FEATURES + half, width, width, 1], last_activation=False)

    def forward(self, robot: torch.Tensor, humans: torch.Tensor) -> torch.Tensor:
        return self.attend(robot, humans)[0]

    def attend(self, robot: torch.Tensor, humans: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(values (N,), attention weights (N, k)): the forward pass and how much each human counted."""
        present = humans[..., -1] > 0.5  # (N, k)
        rows = torch.cat([robot[:, None, :].expand(-1, humans.shape[1], -1), humans], dim=-1)
        embedded = self.embed(rows)  # (N, k, h)
        weight = present.to(embedded.dtype)
        count = weight.sum(dim=1, keepdim=True).clamp(min=1.0)
        crowd = (embedded * weight[..., None]).sum(dim=1) / count  # (N, h) mean over the present humans
        scores = self.score(torch.cat([embedded, crowd[:, None, :].expand_as(embedded)], dim=-1))[..., 0]
        scores = scores.masked_fill(~present, -1e9)  # finite: a row with nobody gives no NaN
        attention = torch.softmax(scores, dim=1)
        attention = attention * weight  # nobody tracked: all zero
        pooled = (attention[..., None] * self.feature(embedded)).sum(dim=1)
        return self.value(torch.cat([robot, pooled], dim=-1))[..., 0], attention


class ValueEnsemble(nn.Module):
    """``members`` value networks of one width, each initialised apart; ``forward`` is their mean value.

    Every member regresses on the same minibatches and the same target (the target ensemble's mean); the mean of
    independently initialised networks moves less from one update to the next than any one of them, so the greedy
    action changes less between snapshots (the policy churn of a single network is what moves a seed by a point or
    two over its last 500 episodes).
    """

    def __init__(self, width: int = 64, members: int = 2):
        super().__init__()
        self.width = width
        self.members = nn.ModuleList(ValueNetwork(width) for _ in range(members))

    def forward(self, robot: torch.Tensor, humans: torch.Tensor) -> torch.Tensor:
        return self.each(robot, humans).mean(dim=0)

    def each(self, robot: torch.Tensor, humans: torch.Tensor) -> torch.Tensor:
        """(members, N) values, one row per member."""
        return torch.stack([member(robot, humans) for member in self.members])


def value_network(width: int, members: int) -> ValueNetwork | ValueEnsemble:
    """One network (``members`` 1: the published runs' parameter names and draws) or an ensemble of ``members``."""
    return ValueNetwork(width) if members == 1 else ValueEnsemble(width, members)


def evaluate(network: ValueNetwork | ValueEnsemble, robot: np.ndarray, humans: np.ndarray) -> np.ndarray:
    """Values (float64, leading axes of ``robot``) of feature arrays with any leading axes, without gradients."""
    lead = robot.shape[:-1]
    with torch.no_grad():
        values = network(torch.from_numpy(robot.reshape(-1, robot.shape[-1])),
                         torch.from_numpy(humans.reshape(-1, *humans.shape[-2:])))
    return values.numpy().astype(np.float64).reshape(lead)
