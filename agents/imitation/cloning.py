"""Demonstrations (the transitions) and behaviour cloning of an SB3 model on them (:mod:`crowdnav.agents.imitation.demonstrations` collects them).

What is trained, per algorithm (see :mod:`crowdnav.agents.imitation.demonstrations` for the whole warm start): PPO / A2C
the Gaussian's mean (then ``log_std`` set to ``log(action_std)``), SAC ``tanh(mean)`` and its log-std
head, TD3 / DDPG the actor's action; with ``value_pretraining`` the value function or both critics
on the demonstrations' discounted returns-to-go. A fresh Adam; the minibatch order is the only
randomness, drawn from ``seed``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from crowdnav.agents.training.config import ConfigError, DemonstrationConfig, config_from_mapping
from stable_baselines3 import SAC, TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.distributions import DiagGaussianDistribution
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.policies import ActorCriticPolicy


@dataclass
class Demonstrations:
    """Transitions of demonstration episodes, in episode order then step order, as the agent sees them."""

    observations: dict[str, np.ndarray]
    """Key -> (N, ...) agent-view observations (normalised; the frozen encoder's latent for a precomputed LEOG)."""
    next_observations: dict[str, np.ndarray]
    """Key -> (N, ...) the observation after each step (the episode's last one at its end)."""
    actions: np.ndarray
    """(N, 2) float32: the action executed (the expert's, or the clone's in DAgger episodes)."""
    expert_actions: np.ndarray
    """(N, 2) float32: the expert's action in each state (the cloning target)."""
    rewards: np.ndarray
    """(N,) float32 in env units (not scaled by ``reward_scale``)."""
    terminated: np.ndarray
    """(N,) bool: the episode ended by an event (goal, collision, out of bounds)."""
    truncated: np.ndarray
    """(N,) bool: the episode ended by the time limit."""
    episode: np.ndarray
    """(N,) int64: demonstration episode index (its seed: ``demonstration_seed(config.seed, index)``)."""
    outcomes: dict[int, str] = field(default_factory=dict)
    """Episode index -> outcome (success, collision, out_of_bounds, truncated)."""
    driver: dict[int, str] = field(default_factory=dict)
    """Episode index -> who drove it: ``social-force`` or ``clone`` (DAgger)."""

    def __len__(self) -> int:
        return len(self.actions)

    @property
    def dones(self) -> np.ndarray:
        return self.terminated | self.truncated

    @property
    def episodes(self) -> int:
        return len(self.outcomes)

    def returns(self, gamma: float, scale: float = 1.0) -> np.ndarray:
        """(N,) float32 discounted return-to-go of each step within its episode (rewards times ``scale``)."""
        out = np.zeros(len(self), dtype=np.float64)
        running = 0.0
        for t in range(len(self) - 1, -1, -1):
            if self.dones[t] or t == len(self) - 1 or self.episode[t] != self.episode[t + 1]:
                running = 0.0
            running = float(self.rewards[t]) * scale + gamma * running
            out[t] = running
        return out.astype(np.float32)

    def success_rate(self, driver: str | None = None) -> float:
        outcomes = [o for e, o in self.outcomes.items() if driver is None or self.driver.get(e) == driver]
        return sum(o == "success" for o in outcomes) / len(outcomes) if outcomes else 0.0

    def __add__(self, other: Demonstrations) -> Demonstrations:
        def join(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
            return {key: np.concatenate([a[key], b[key]]) for key in a}

        return Demonstrations(
            join(self.observations, other.observations), join(self.next_observations, other.next_observations),
            np.concatenate([self.actions, other.actions]), np.concatenate([self.expert_actions, other.expert_actions]),
            np.concatenate([self.rewards, other.rewards]), np.concatenate([self.terminated, other.terminated]),
            np.concatenate([self.truncated, other.truncated]), np.concatenate([self.episode, other.episode]),
            {**self.outcomes, **other.outcomes}, {**self.driver, **other.driver},
        )


# ---------------------------------------------------------------------------------------------- collection


class _Heads:
    """What cloning trains in one SB3 model: the predicted action, the value / Q estimates, and after-care."""

    def __init__(self, model: BaseAlgorithm, action_std: float):
        self.model = model
        self.log_std = math.log(action_std)
        # the model seen as what its kind is: an actor-critic policy (PPO, A2C) or an actor and critics (SAC, TD3, DDPG)
        self.policy: ActorCriticPolicy | None = None
        self.off_policy: SAC | TD3 | None = None
        if not isinstance(model, OffPolicyAlgorithm):
            policy = model.policy
            if not isinstance(policy, ActorCriticPolicy) or not isinstance(policy.action_dist, DiagGaussianDistribution) \
                    or getattr(policy, "use_sde", False):
                raise ConfigError("demonstrations: on-policy cloning needs a diagonal Gaussian policy (no gSDE)")
            self.policy = policy
            self.actor_parameters = [p for name, p in policy.named_parameters() if p.requires_grad and name != "log_std"]
            self.critic_parameters: list[torch.nn.Parameter] = []
        else:
            if not isinstance(model, (SAC, TD3)):  # DDPG is a TD3
                raise ConfigError(f"demonstrations: cloning an off-policy {type(model).__name__} is not supported (SAC, TD3, DDPG are)")
            self.off_policy = model
            self.actor_parameters = [p for p in model.actor.parameters() if p.requires_grad]
            shared = getattr(model.policy, "share_features_extractor", False)
            self.critic_parameters = [p for name, p in model.critic.named_parameters()
                                      if p.requires_grad and not (shared and name.startswith("features_extractor"))]

    def losses(self, obs: dict[str, torch.Tensor], targets: torch.Tensor, actions: torch.Tensor,
               returns: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor | None]:
        """(action loss, value loss or None) on one minibatch."""
        value_loss = None
        if self.policy is not None:
            policy = self.policy
            features = policy.extract_features(obs)
            if isinstance(features, torch.Tensor):  # a shared extractor (SB3 returns one tensor then, a pair otherwise)
                pi_features, vf_features = features, features.detach()
            else:
                pi_features, vf_features = features
            mean = policy.action_net(policy.mlp_extractor.forward_actor(pi_features))
            action_loss = torch.nn.functional.mse_loss(mean, targets)
            if returns is not None:
                values = policy.value_net(policy.mlp_extractor.forward_critic(vf_features)).flatten()
                value_loss = torch.nn.functional.mse_loss(values, returns)
            return action_loss, value_loss
        model = self._off_policy()
        if isinstance(model, SAC):  # squashed Gaussian
            mean, log_std, _ = model.actor.get_action_dist_params(obs)
            action_loss = torch.nn.functional.mse_loss(torch.tanh(mean), targets)
            action_loss = action_loss + torch.nn.functional.mse_loss(log_std, torch.full_like(log_std, self.log_std))
        else:  # TD3 / DDPG: deterministic tanh actor
            action_loss = torch.nn.functional.mse_loss(model.actor(obs), targets)
        if returns is not None:
            q_values = model.critic(obs, actions)
            # (q1 + q2 + ...) / n: what sum() gives, without its leading 0
            value_loss = functools.reduce(torch.add, [torch.nn.functional.mse_loss(q.flatten(), returns) for q in q_values]) / len(q_values)
        return action_loss, value_loss

    def _off_policy(self) -> SAC | TD3:
        if self.off_policy is None:
            raise TypeError(f"{type(self.model).__name__} has no actor and critics")
        return self.off_policy

    def predicted_actions(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """The deterministic action, before the env's clipping (PPO/A2C: the Gaussian's mean)."""
        if self.policy is not None:
            return self.policy.get_distribution(obs).mode()  # a diagonal Gaussian's (checked in __init__): its mean
        model = self._off_policy()
        return model.actor(obs, deterministic=True) if isinstance(model, SAC) else model.actor(obs)

    def finish(self) -> None:
        """Set the on-policy std, sync the target networks."""
        if self.policy is not None:
            with torch.no_grad():
                self.policy.log_std.fill_(self.log_std)
            return
        model = self._off_policy()
        if isinstance(model, TD3):  # SAC has no actor target
            model.actor_target.load_state_dict(model.actor.state_dict())
        model.critic_target.load_state_dict(model.critic.state_dict())


def _tensors(model: BaseAlgorithm, demonstrations: Demonstrations, gamma: float, scale: float) -> dict[str, Any]:
    device = model.device
    return {
        "obs": {key: torch.as_tensor(values, device=device) for key, values in demonstrations.observations.items()},
        "targets": torch.as_tensor(demonstrations.expert_actions, device=device),
        "actions": torch.as_tensor(demonstrations.actions, device=device),
        "returns": torch.as_tensor(demonstrations.returns(gamma, scale), device=device),
    }


def _evaluate(heads: _Heads, data: dict[str, Any], value: bool) -> tuple[float, float | None]:
    """(action MSE of the deterministic action against the expert's, value MSE or None) over all demonstrations."""
    n = len(data["targets"])
    action_error, value_error = 0.0, 0.0
    with torch.no_grad():
        for start in range(0, n, 4096):
            rows = slice(start, start + 4096)
            obs = {key: values[rows] for key, values in data["obs"].items()}
            predicted = heads.predicted_actions(obs).clamp(-1.0, 1.0)
            action_error += float(((predicted - data["targets"][rows]) ** 2).sum()) / 2
            if value:
                _, loss = heads.losses(obs, data["targets"][rows], data["actions"][rows], data["returns"][rows])
                if loss is None:  # losses() gives a value loss whenever it is given returns
                    raise RuntimeError("no value loss with returns given")
                value_error += float(loss) * len(data["targets"][rows])
    return action_error / n, (value_error / n if value else None)


def behaviour_cloning(model: BaseAlgorithm, demonstrations: Demonstrations, *, epochs: int = 30, batch_size: int = 256,
                      learning_rate: float = 1e-3, action_std: float = 0.3, value_pretraining: bool = True, gamma: float = 0.95,
                      reward_scale: float = 1.0, seed: int = 0) -> dict[str, Any]:
    """Clone the expert's actions into ``model``'s actor (and fit its value / critics); the losses before and after.

    ``action_mse``: mean over the demonstrations of the squared error per action value between
    the policy's deterministic action (clipped to [-1, 1], as the env applies it) and the expert's.
    """
    _check_settings(epochs=epochs, batch_size=batch_size, learning_rate=learning_rate, action_std=action_std)
    heads = _Heads(model, action_std)
    data = _tensors(model, demonstrations, gamma, reward_scale)
    action_before, value_before = _evaluate(heads, data, value_pretraining)
    parameters = heads.actor_parameters + (heads.critic_parameters if value_pretraining else [])
    optimizer = torch.optim.Adam(parameters, lr=learning_rate)
    rng = np.random.default_rng(seed)
    n = len(demonstrations)
    for _ in range(epochs):
        order = torch.as_tensor(rng.permutation(n), device=model.device)
        for start in range(0, n, batch_size):
            rows = order[start : start + batch_size]
            obs = {key: values[rows] for key, values in data["obs"].items()}
            action_loss, value_loss = heads.losses(obs, data["targets"][rows], data["actions"][rows],
                                                   data["returns"][rows] if value_pretraining else None)
            loss = action_loss if value_loss is None else action_loss + value_loss
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
    heads.finish()
    action_after, value_after = _evaluate(heads, data, value_pretraining)
    report: dict[str, float | None] = {"transitions": n, "epochs": epochs, "action_mse_before": action_before, "action_mse_after": action_after}
    if value_pretraining:
        report.update(value_mse_before=value_before, value_mse_after=value_after)
    return report


def _check_settings(**settings: Any) -> None:
    """ConfigError (one line) unless the settings are within :class:`~crowdnav.agents.training.config.DemonstrationConfig`'s bounds.

    A config file's are checked when it loads; this checks a direct call before any work (``learning_rate: 1e300``
    or ``action_std: 1e-300`` would otherwise end in a NaN deep inside torch).
    """
    from pydantic import ValidationError

    try:
        DemonstrationConfig.model_validate(settings)
    except ValidationError:
        config_from_mapping({"demonstrations": settings}, "behaviour_cloning")  # raises the ConfigError naming the field
