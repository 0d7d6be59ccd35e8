"""One network per robot kind inside the shared robot policy (``robot_networks: per_kind`` of ``agents: robots``).

With ``robot_networks: shared`` (the default) every robot's row goes through one SB3 MLP; the
robot's one-hot (``agent_identity``) is its only way to act differently. With ``per_kind`` the
robots are grouped by kinematics (in ``robots_crossing_hall``: the two holonomic robots, and the
unicycle) and each kind has **its own actor and critic hidden layers** (SB3's ``MlpExtractor``
each, ``net_arch`` as for the shared network): :class:`KindNetworks` reads the row's robot from
its one-hot and passes the row through its kind's layers. Kind ``k``'s latent fills the ``k``-th
block of a latent ``kinds`` times as wide, the other blocks zero, so SB3's action and value heads
(linear layers on that latent) hold separate weights per kind as well; only their two biases and
the action log-std are shared. It stays one SB3 PPO on one vector env (one row per robot), one
checkpoint, one ``act`` for every robot.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import torch
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import MlpExtractor
from torch import nn

RobotNetworks = Literal["shared", "per_kind"]
ROBOT_NETWORKS: tuple[str, ...] = ("shared", "per_kind")
"""The values of ``robot_networks`` (the first is the default)."""


def robot_kinds(scenario: Any) -> list[int]:
    """Each robot's kind index (the scenario's order): robots of the same kinematics share one, numbered by first appearance."""
    seen: dict[str, int] = {}
    return [seen.setdefault(robot.kinematics, len(seen)) for robot in scenario.robot_specs]


class KindNetworks(nn.Module):
    """SB3's ``mlp_extractor`` with one ``MlpExtractor`` per robot kind, chosen per row by the robot one-hot (its last columns)."""

    routing: torch.Tensor
    """(robots, kinds): row k is robot k's kind as a one-hot."""

    def __init__(self, feature_dim: int, net_arch: Any, activation_fn: type[nn.Module], device: torch.device | str, kinds: Sequence[int]):
        super().__init__()
        count = max(kinds) + 1
        extractors = [MlpExtractor(feature_dim, net_arch, activation_fn, device) for _ in range(count)]
        self.extractors = nn.ModuleList(extractors)
        self.robots = len(kinds)
        routing = torch.zeros(len(kinds), count)
        routing[torch.arange(len(kinds)), torch.as_tensor(list(kinds))] = 1.0
        self.register_buffer("routing", routing.to(device), persistent=False)  # not a parameter: rebuilt from the scenario
        self.latent_dim_pi = count * extractors[0].latent_dim_pi
        self.latent_dim_vf = count * extractors[0].latent_dim_vf

    def _route(self, features: torch.Tensor, part: str) -> torch.Tensor:
        mask = features[:, -self.robots :] @ self.routing  # (rows, kinds): the row's kind, from its robot's one-hot
        return torch.cat([getattr(extractor, part)(features) * mask[:, k : k + 1] for k, extractor in enumerate(self.extractors)], dim=1)

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.forward_actor(features), self.forward_critic(features)

    def forward_actor(self, features: torch.Tensor) -> torch.Tensor:
        return self._route(features, "forward_actor")

    def forward_critic(self, features: torch.Tensor) -> torch.Tensor:
        return self._route(features, "forward_critic")


class KindActorCriticPolicy(ActorCriticPolicy):
    """SB3's actor-critic policy whose hidden layers are :class:`KindNetworks` (``robot_kinds``: each robot's kind index)."""

    def __init__(self, *args: Any, robot_kinds: Sequence[int], **kwargs: Any):
        self.robot_kinds = [int(kind) for kind in robot_kinds]
        super().__init__(*args, **kwargs)

    def _build_mlp_extractor(self) -> None:
        # SB3 declares an MlpExtractor; KindNetworks answers the same calls (forward, forward_actor/critic, latent_dim_pi/vf)
        self.mlp_extractor = KindNetworks(  # type: ignore[assignment]
            self.features_dim, self.net_arch, self.activation_fn, self.device, self.robot_kinds)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        return {**super()._get_constructor_parameters(), "robot_kinds": self.robot_kinds}
