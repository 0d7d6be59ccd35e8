"""crowdnav's SAC, TD3 and DDPG: Stable-Baselines3's algorithms with less overhead per gradient step.

The updates are SB3's own, term for term (same losses, optimizers, update-to-data ratio, target
updates and random draws: a fixed seed gives the same networks to the last bit, see
``tests/agents/test_agents_training.py``). What changes is the work around them, which dominates with
crowdnav's small networks on a CPU (measured in docs/agents.md#performance):

* **actor backward pass restricted to the actor's parameters.** SB3 back-propagates the actor
  loss into the critic too (it runs through ``Q(s, pi(s))``), computing critic weight gradients
  that the next critic update discards unused (``zero_grad`` before every critic backward pass).
  ``backward(inputs=...)`` skips them: about a third of the actor's backward pass;
* **target networks updated with two ``torch._foreach`` calls** over all parameters instead of
  two Python-level ops per tensor (the same ``mul_`` then ``add(alpha=tau)`` as SB3's
  ``polyak_update``, so the same values);
* **``set_training_mode`` without the recursive ``Module.train``**, which SB3 calls three times per
  env step (train, rollout, predict): the policies here set the ``training`` flag of the same
  modules from a list made once (:class:`FastTrainingMode`);
* the SAC actor's squashed Gaussian written out (:class:`CrowdNavSACActor`), the critic's features
  for the actor loss computed without an autograd graph, gradients reset without the optimizer's
  profiler wrapper, and the losses logged from tensors gathered over the gradient steps instead
  of one ``.item()`` per loss and step;
* the networks read the sampled tensors as they are (:class:`SampledObservations`): no
  ``float() / 255`` copy of the grid per network call.

The registry entries of ``sac``, ``td3`` and ``ddpg`` name these classes (``model_class`` of
:class:`crowdnav.registry.AlgorithmSpec`; :func:`crowdnav.agents.sb3.factory.model_class`). Models saved with SB3's own
classes load into them (and the other way round).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, ClassVar

import torch
import torch.nn.functional as F
from crowdnav.agents.networks.extractor import MultiModalExtractor
from stable_baselines3 import DDPG, SAC, TD3
from stable_baselines3.common.distributions import SquashedDiagGaussianDistribution
from stable_baselines3.common.policies import BasePolicy, ContinuousCritic
from stable_baselines3.common.utils import polyak_update
from stable_baselines3.sac.policies import Actor as SACActor
from stable_baselines3.sac.policies import MultiInputPolicy as SACMultiInputPolicy
from stable_baselines3.td3.policies import Actor as TD3Actor
from stable_baselines3.td3.policies import MultiInputPolicy as TD3MultiInputPolicy
from torch import nn


def soft_update(params: Sequence[torch.Tensor], target_params: Sequence[torch.Tensor], tau: float) -> None:
    """SB3's ``polyak_update`` (``target = target * (1 - tau) + tau * param``, in place) in two foreach calls.

    The same two elementwise ops per tensor in the same order, so the same values to the last bit.
    """
    params, target_params = list(params), list(target_params)
    if len(params) != len(target_params):
        raise ValueError(f"soft_update: {len(params)} parameters but {len(target_params)} target parameters")
    if not params:
        return
    with torch.no_grad():
        torch._foreach_mul_(target_params, 1 - tau)
        torch._foreach_add_(target_params, params, alpha=tau)


def zero_grad(optimizer: torch.optim.Optimizer) -> None:
    """``optimizer.zero_grad()`` (``set_to_none=True``, SB3's call) without its profiler and dynamo wrappers."""
    for group in optimizer.param_groups:
        for parameter in group["params"]:
            parameter.grad = None


def optimized_parameters(optimizer: torch.optim.Optimizer) -> list[torch.Tensor]:
    """The parameters ``optimizer`` steps that can receive a gradient (the ``inputs`` of its backward pass)."""
    return [p for group in optimizer.param_groups for p in group["params"] if p.requires_grad]


class FastTrainingMode:
    """Policy mixin: ``set_training_mode`` sets the ``training`` flag of the modules SB3's would, without recursion.

    SB3's version calls ``Module.train`` on the actor and the critic, a recursive walk through
    about 40 modules that costs ~0.1 ms, three times per env step. This one sets the same flags
    from a list of those modules gathered on first use (again if the actor or critic object is
    replaced). A policy with a module that overrides ``train`` keeps SB3's version.
    """

    def _training_mode_roots(self) -> tuple[nn.Module, ...]:
        return (self.actor, self.critic)  # type: ignore[attr-defined]

    def set_training_mode(self, mode: bool) -> None:
        roots = self._training_mode_roots()
        cached = self.__dict__.get("_training_mode_cache")
        if cached is None or len(cached[0]) != len(roots) or any(a is not b for a, b in zip(cached[0], roots, strict=True)):
            found = [module for root in roots for module in root.modules()]
            # a module with its own train() needs SB3's call of it: None means "the plain way"
            cached = (roots, found if all(type(module).train is nn.Module.train for module in found) else None)
            self.__dict__["_training_mode_cache"] = cached
        modules = cached[1]
        if modules is None:
            super().set_training_mode(mode)  # type: ignore[misc]
            return
        if not isinstance(mode, bool):
            raise ValueError("training mode is expected to be boolean")
        for module in modules:
            module.__dict__["training"] = mode
        self.__dict__["training"] = mode


class SampledObservations:
    """Network mixin: a :class:`~crowdnav.agents.networks.extractor.MultiModalExtractor` gets the sampled tensors as they are.

    SB3's ``extract_features`` first runs ``preprocess_obs``, which copies a uint8 grid into floats
    divided by 255 (on every network call: five times per SAC gradient step); the LEOG branch only
    asks which cells are non-zero, so :meth:`~crowdnav.agents.networks.extractor.MultiModalExtractor.prepare` skips
    that copy, and the branches share one binarized grid per batch. Same features, to the last bit.
    """

    def extract_features(self, obs: Any, features_extractor: nn.Module) -> torch.Tensor:
        if isinstance(features_extractor, MultiModalExtractor) and isinstance(obs, dict) and not features_extractor.reference:
            return features_extractor(features_extractor.prepare(obs, self.normalize_images))  # type: ignore[attr-defined]
        return super().extract_features(obs, features_extractor)  # type: ignore[misc]


_LOG_SQRT_2PI = math.log(math.sqrt(2 * math.pi))


class CrowdNavSACActor(SampledObservations, SACActor):
    """SB3's SAC actor with :class:`SampledObservations`, and its squashed Gaussian written out.

    ``forward`` and ``action_log_prob`` compute what SB3's ``SquashedDiagGaussianDistribution``
    does, op for op (same random draw, same values to the last bit), without building a
    ``torch.distributions.Normal`` per call: its argument checks (a NaN test of the mean and a
    positivity test of the std, each with a host sync) and the distribution object's Python layers
    cost about as much as the rest of the distribution. gSDE actors keep SB3's code.
    """

    def _plain_gaussian(self) -> bool:
        # SB3 annotates action_dist with its gSDE branch's class only
        return not self.use_sde and type(self.action_dist) is SquashedDiagGaussianDistribution  # type: ignore[comparison-overlap]

    def forward(self, obs: Any, deterministic: bool = False) -> torch.Tensor:
        if not self._plain_gaussian():
            return super().forward(obs, deterministic)
        mean_actions, log_std, _ = self.get_action_dist_params(obs)
        if deterministic:
            return torch.tanh(mean_actions)
        return torch.tanh(_gaussian_sample(mean_actions, log_std)[0])

    def action_log_prob(self, obs: Any) -> tuple[torch.Tensor, torch.Tensor]:
        if not self._plain_gaussian():
            return super().action_log_prob(obs)
        mean_actions, log_std, _ = self.get_action_dist_params(obs)
        gaussian_actions, action_std = _gaussian_sample(mean_actions, log_std)
        actions = torch.tanh(gaussian_actions)
        # Normal(mean, std).log_prob(gaussian_actions), summed over the action dimensions, then the tanh correction
        log_prob = -((gaussian_actions - mean_actions) ** 2) / (2 * action_std**2) - action_std.log() - _LOG_SQRT_2PI
        log_prob = log_prob.sum(dim=1) if log_prob.dim() > 1 else log_prob.sum()
        log_prob -= torch.sum(torch.log(1 - actions**2 + self.action_dist.epsilon), dim=1)
        return actions, log_prob


def _gaussian_sample(mean_actions: torch.Tensor, log_std: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """SB3's ``DiagGaussianDistribution`` std and ``Normal.rsample`` (the same standard normal draw): (sample, std)."""
    action_std = torch.ones_like(mean_actions) * log_std.exp()
    noise = torch.empty(mean_actions.shape, dtype=mean_actions.dtype, device=mean_actions.device).normal_()
    return mean_actions + noise * action_std, action_std


class CrowdNavTD3Actor(SampledObservations, TD3Actor):
    """SB3's TD3/DDPG actor with :class:`SampledObservations`."""


class CrowdNavCritic(SampledObservations, ContinuousCritic):
    """SB3's Q-networks with :class:`SampledObservations`."""


class CrowdNavSACPolicy(FastTrainingMode, SACMultiInputPolicy):
    """SB3's SAC ``MultiInputPolicy`` with :class:`FastTrainingMode` and :class:`SampledObservations` networks."""

    def make_actor(self, features_extractor: Any = None) -> SACActor:
        actor_kwargs = self._update_features_extractor(self.actor_kwargs, features_extractor)
        return CrowdNavSACActor(**actor_kwargs).to(self.device)

    def make_critic(self, features_extractor: Any = None) -> ContinuousCritic:
        critic_kwargs = self._update_features_extractor(self.critic_kwargs, features_extractor)
        return CrowdNavCritic(**critic_kwargs).to(self.device)


class CrowdNavTD3Policy(FastTrainingMode, TD3MultiInputPolicy):
    """SB3's TD3/DDPG ``MultiInputPolicy`` with :class:`FastTrainingMode` and :class:`SampledObservations` networks."""

    def make_actor(self, features_extractor: Any = None) -> TD3Actor:
        actor_kwargs = self._update_features_extractor(self.actor_kwargs, features_extractor)
        return CrowdNavTD3Actor(**actor_kwargs).to(self.device)

    def make_critic(self, features_extractor: Any = None) -> ContinuousCritic:
        critic_kwargs = self._update_features_extractor(self.critic_kwargs, features_extractor)
        return CrowdNavCritic(**critic_kwargs).to(self.device)


def _log_mean(values: list[torch.Tensor]) -> float:
    return float(torch.stack(values).double().mean())


def _q_values_for_actor(critic: ContinuousCritic, observations: Any, actions: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """``critic(observations, actions)`` for the actor loss: the same values, the features without a graph.

    The actor loss only back-propagates into the actions (the critic's gradients are not computed,
    see ``backward(inputs=...)``), so the critic's features need no autograd graph; a shared
    extractor (``share_features_extractor``) never gets one from the critic anyway.
    """
    if type(critic).forward is not ContinuousCritic.forward:
        return critic(observations, actions)
    with torch.no_grad():
        features = critic.extract_features(observations, critic.features_extractor)
    q_input = torch.cat([features, actions], dim=1)
    return tuple(q_net(q_input) for q_net in critic.q_networks)


class CrowdNavSAC(SAC):
    """SB3's SAC with the same update and less overhead (see the module docstring)."""

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {**SAC.policy_aliases, "MultiInputPolicy": CrowdNavSACPolicy}

    def train(self, gradient_steps: int, batch_size: int = 64) -> None:
        # SB3 2.x SAC.train, with the changes listed in the module docstring
        self.policy.set_training_mode(True)
        optimizers = [self.actor.optimizer, self.critic.optimizer]
        if self.ent_coef_optimizer is not None:
            optimizers += [self.ent_coef_optimizer]
        self._update_learning_rate(optimizers)
        actor_parameters = optimized_parameters(self.actor.optimizer)
        critic_parameters, target_parameters = list(self.critic.parameters()), list(self.critic_target.parameters())

        ent_coef_losses, ent_coefs, actor_losses, critic_losses = [], [], [], []
        for gradient_step in range(gradient_steps):
            replay_data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            discounts = replay_data.discounts if replay_data.discounts is not None else self.gamma
            if self.use_sde:
                self.actor.reset_noise()

            actions_pi, log_prob = self.actor.action_log_prob(replay_data.observations)
            log_prob = log_prob.reshape(-1, 1)

            ent_coef_loss = None
            if self.ent_coef_optimizer is not None and self.log_ent_coef is not None:
                ent_coef = torch.exp(self.log_ent_coef.detach())
                assert isinstance(self.target_entropy, float)
                ent_coef_loss = -(self.log_ent_coef * (log_prob + self.target_entropy).detach()).mean()
                ent_coef_losses.append(ent_coef_loss.detach())
            else:
                ent_coef = self.ent_coef_tensor
            ent_coefs.append(ent_coef.detach())

            if ent_coef_loss is not None and self.ent_coef_optimizer is not None:
                zero_grad(self.ent_coef_optimizer)
                ent_coef_loss.backward()
                self.ent_coef_optimizer.step()

            with torch.no_grad():
                next_actions, next_log_prob = self.actor.action_log_prob(replay_data.next_observations)
                next_q_values = torch.cat(self.critic_target(replay_data.next_observations, next_actions), dim=1)
                next_q_values, _ = torch.min(next_q_values, dim=1, keepdim=True)
                next_q_values = next_q_values - ent_coef * next_log_prob.reshape(-1, 1)
                target_q_values = replay_data.rewards + (1 - replay_data.dones) * discounts * next_q_values

            current_q_values = self.critic(replay_data.observations, replay_data.actions)
            critic_loss = 0.5 * sum(F.mse_loss(current_q, target_q_values) for current_q in current_q_values)
            assert isinstance(critic_loss, torch.Tensor)
            critic_losses.append(critic_loss.detach())
            zero_grad(self.critic.optimizer)
            critic_loss.backward()
            self.critic.optimizer.step()

            q_values_pi = torch.cat(_q_values_for_actor(self.critic, replay_data.observations, actions_pi), dim=1)
            min_qf_pi, _ = torch.min(q_values_pi, dim=1, keepdim=True)
            actor_loss = (ent_coef * log_prob - min_qf_pi).mean()
            actor_losses.append(actor_loss.detach())
            zero_grad(self.actor.optimizer)
            actor_loss.backward(inputs=actor_parameters)  # not into the critic: its next update zeroes those gradients
            self.actor.optimizer.step()

            if gradient_step % self.target_update_interval == 0:
                soft_update(critic_parameters, target_parameters, self.tau)
                polyak_update(self.batch_norm_stats, self.batch_norm_stats_target, 1.0)

        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        if gradient_steps > 0:
            self.logger.record("train/ent_coef", _log_mean(ent_coefs))
            self.logger.record("train/actor_loss", _log_mean(actor_losses))
            self.logger.record("train/critic_loss", _log_mean(critic_losses))
        if ent_coef_losses:
            self.logger.record("train/ent_coef_loss", _log_mean(ent_coef_losses))


class _FastTD3Train:
    """SB3 2.x ``TD3.train`` (also DDPG's) with the changes listed in the module docstring."""

    def train(self: Any, gradient_steps: int, batch_size: int = 100) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate([self.actor.optimizer, self.critic.optimizer])
        actor_parameters = optimized_parameters(self.actor.optimizer)
        critic_pairs = (list(self.critic.parameters()), list(self.critic_target.parameters()))
        actor_pairs = (list(self.actor.parameters()), list(self.actor_target.parameters()))

        actor_losses, critic_losses = [], []
        for _ in range(gradient_steps):
            self._n_updates += 1
            replay_data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)
            discounts = replay_data.discounts if replay_data.discounts is not None else self.gamma

            with torch.no_grad():
                noise = replay_data.actions.clone().data.normal_(0, self.target_policy_noise)
                noise = noise.clamp(-self.target_noise_clip, self.target_noise_clip)
                next_actions = (self.actor_target(replay_data.next_observations) + noise).clamp(-1, 1)
                next_q_values = torch.cat(self.critic_target(replay_data.next_observations, next_actions), dim=1)
                next_q_values, _ = torch.min(next_q_values, dim=1, keepdim=True)
                target_q_values = replay_data.rewards + (1 - replay_data.dones) * discounts * next_q_values

            current_q_values = self.critic(replay_data.observations, replay_data.actions)
            critic_loss = sum(F.mse_loss(current_q, target_q_values) for current_q in current_q_values)
            assert isinstance(critic_loss, torch.Tensor)
            critic_losses.append(critic_loss.detach())
            zero_grad(self.critic.optimizer)
            critic_loss.backward()
            self.critic.optimizer.step()

            if self._n_updates % self.policy_delay == 0:
                actor_loss = -self.critic.q1_forward(replay_data.observations, self.actor(replay_data.observations)).mean()
                actor_losses.append(actor_loss.detach())
                zero_grad(self.actor.optimizer)
                actor_loss.backward(inputs=actor_parameters)  # not into the critic: its next update zeroes those gradients
                self.actor.optimizer.step()

                soft_update(*critic_pairs, self.tau)
                soft_update(*actor_pairs, self.tau)
                polyak_update(self.critic_batch_norm_stats, self.critic_batch_norm_stats_target, 1.0)
                polyak_update(self.actor_batch_norm_stats, self.actor_batch_norm_stats_target, 1.0)

        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        if actor_losses:
            self.logger.record("train/actor_loss", _log_mean(actor_losses))
        if critic_losses:
            self.logger.record("train/critic_loss", _log_mean(critic_losses))


class CrowdNavTD3(_FastTD3Train, TD3):
    """SB3's TD3 with the same update and less overhead (see the module docstring)."""

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {**TD3.policy_aliases, "MultiInputPolicy": CrowdNavTD3Policy}


class CrowdNavDDPG(_FastTD3Train, DDPG):
    """SB3's DDPG with the same update and less overhead (see the module docstring)."""

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {**DDPG.policy_aliases, "MultiInputPolicy": CrowdNavTD3Policy}


__all__ = ["CrowdNavCritic", "CrowdNavDDPG", "CrowdNavSAC", "CrowdNavSACActor", "CrowdNavSACPolicy", "CrowdNavTD3", "CrowdNavTD3Actor",
           "CrowdNavTD3Policy", "FastTrainingMode", "SampledObservations", "optimized_parameters", "soft_update", "zero_grad"]
