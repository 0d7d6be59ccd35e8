"""The Stable-Baselines3 internals crowdnav relies on, in one list (checked by ``tests/agents/test_sb3_coupling.py``).

Exact resume and the faster update loops reach past SB3's public API: they read and restore
private counters (``_episode_num``, ``_n_updates``, ...), fill its buffers' arrays, call its
private helpers, and reproduce some of its methods op for op (:mod:`crowdnav.agents.sb3.algorithms`,
:mod:`crowdnav.agents.runs.resume_point`). A minor SB3 release may rename or change any of these
without notice, so ``pyproject.toml`` bounds SB3 to the versions tested (:data:`TESTED_SB3`) and
the test checks every entry below on the installed SB3, naming the internal and where crowdnav
uses it when one is gone or changed:

* ``attribute``: present on an instance SB3 builds (a model, its buffer, its networks);
* ``method``: callable on the class, taking the listed parameters by those names;
* ``local``: a local variable of the method that a callback reads through ``self.locals``;
* ``copied``: a method whose computation crowdnav reproduces; its fingerprint (the parsed
  source without docstrings or comments, :func:`fingerprint`) must be one of those recorded
  here for the tested versions, so a change upstream is ported (or judged irrelevant) by a
  person, then its fingerprint added.
"""

from __future__ import annotations

import ast
import hashlib
import inspect
import textwrap
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

TESTED_SB3 = ">=2.7,<2.10"
"""The SB3 versions ``pyproject.toml`` allows: 2.7 brought the replay samples' ``discounts`` (n-step returns); sb3-contrib's
(RecurrentPPO) too, whose releases follow SB3's."""

Kind = Literal["attribute", "method", "local", "copied"]

_ALGO = "stable_baselines3.common.base_class.BaseAlgorithm"
_OFF = "stable_baselines3.common.off_policy_algorithm.OffPolicyAlgorithm"
_ON = "stable_baselines3.common.on_policy_algorithm.OnPolicyAlgorithm"
_SAC = "stable_baselines3.sac.sac.SAC"
_TD3 = "stable_baselines3.td3.td3.TD3"
_REPLAY = "stable_baselines3.common.buffers.DictReplayBuffer"
_ROLLOUT = "stable_baselines3.common.buffers.DictRolloutBuffer"
_VEC_ENV = "stable_baselines3.common.vec_env.base_vec_env.VecEnv"
_SAC_ACTOR = "stable_baselines3.sac.policies.Actor"
_SAC_POLICY = "stable_baselines3.sac.policies.SACPolicy"
_TD3_POLICY = "stable_baselines3.td3.policies.TD3Policy"
_CRITIC = "stable_baselines3.common.policies.ContinuousCritic"
_AC_POLICY = "stable_baselines3.common.policies.ActorCriticPolicy"
_BASE_POLICY = "stable_baselines3.common.policies.BasePolicy"
_DISTRIBUTIONS = "stable_baselines3.common.distributions"
_RECURRENT_PPO = "sb3_contrib.ppo_recurrent.ppo_recurrent.RecurrentPPO"
_RECURRENT_ROLLOUT = "sb3_contrib.common.recurrent.buffers.RecurrentDictRolloutBuffer"


@dataclass(frozen=True)
class Internal:
    """One SB3 internal: where it lives, what kind of thing crowdnav expects, and where crowdnav uses it."""

    owner: str
    """Dotted path of the SB3 class (or module, for a function) that defines it."""
    name: str
    kind: Kind
    used_in: str
    parameters: tuple[str, ...] = ()
    """``method``: the parameter names crowdnav passes (after ``self``)."""
    fingerprints: tuple[str, ...] = ()
    """``copied``: :func:`fingerprint` of the method in each tested SB3 version whose computation crowdnav's copy matches."""

    @property
    def label(self) -> str:
        return f"{self.owner.rsplit('.', 1)[-1]}.{self.name}"


def _attributes(owner: str, names: str, used_in: str) -> tuple[Internal, ...]:
    return tuple(Internal(owner, name, "attribute", used_in) for name in names.split())


SB3_INTERNALS: tuple[Internal, ...] = (
    # counters and state a resumed run restores (resume_state.save_training_state / restore_training_state)
    *_attributes(_ALGO, "num_timesteps _episode_num _n_updates _current_progress_remaining _stats_window_size "
                 "ep_info_buffer ep_success_buffer", "agents/runs/resume_state.py (training_state.json)"),
    *_attributes(_ALGO, "_last_obs _last_episode_starts _last_original_obs _total_timesteps", "agents/runs/resume_point.py (ResumePoint)"),
    Internal(_ALGO, "_update_current_progress_remaining", "method", "agents/runs/resume_point.py (ResumePoint.continue_run)",
             ("num_timesteps", "total_timesteps")),
    Internal(_ALGO, "_get_torch_save_params", "method", "agents/runs/checkpoint.py (load_parameters)"),
    Internal(_ALGO, "set_parameters", "method", "agents/runs/checkpoint.py (load_parameters)", ("load_path_or_dict", "exact_match", "device")),
    Internal(_ALGO, "_update_learning_rate", "method", "agents/sb3/algorithms.py (train loops)", ("optimizers",)),
    Internal(_ALGO, "_vec_normalize_env", "attribute", "agents/sb3/algorithms.py (train loops)"),
    # the update a resumed run takes first, as SB3's learn loop does after a rollout
    *_attributes(_OFF, "replay_buffer train_freq gradient_steps learning_starts batch_size n_envs",
                 "agents/runs/resume_point.py (ResumePoint.continue_run)"),
    Internal(_OFF, "train", "method", "agents/runs/resume_point.py (ResumePoint.continue_run)", ("gradient_steps", "batch_size")),
    Internal(_OFF, "load_replay_buffer", "method", "agents/sb3/session.py (legacy pickled replay buffer)", ("path",)),
    Internal(_OFF, "learn", "copied", "agents/runs/resume_point.py (ResumePoint.continue_run: the update after a rollout)",
             fingerprints=("4e65b7856177f116",)),
    Internal(_ON, "rollout_buffer", "attribute", "agents/runs/resume_point.py, agents/runs/resume_worlds.py (rollout_state.npz)"),
    Internal(_ON, "train", "method", "agents/runs/resume_point.py (ResumePoint.continue_run)"),
    Internal(_ON, "learn", "copied", "agents/runs/resume_point.py (ResumePoint.continue_run: the update after a rollout)",
             fingerprints=("954306175d9f6255",)),
    # what the episode callback reads from the rollout loop (callbacks.EpisodeCallback._on_step)
    Internal(_OFF, "collect_rollouts", "local", "agents/sb3/callbacks.py (EpisodeCallback._on_step: self.locals)", ("dones", "infos")),
    Internal(_ON, "collect_rollouts", "local", "agents/sb3/callbacks.py (EpisodeCallback._on_step: self.locals)", ("dones", "infos")),
    # the faster SAC / TD3 / DDPG updates, SB3's term for term (algorithms.CrowdNavSAC.train, _FastTD3Train.train)
    *_attributes(_SAC, "actor critic critic_target ent_coef_optimizer log_ent_coef target_entropy ent_coef_tensor "
                 "batch_norm_stats batch_norm_stats_target target_update_interval tau gamma use_sde",
                 "agents/sb3/algorithms.py (CrowdNavSAC.train)"),
    Internal(_SAC, "train", "copied", "agents/sb3/algorithms.py (CrowdNavSAC.train)", fingerprints=("4bd05d8e121f913e",)),
    *_attributes(_TD3, "actor actor_target critic critic_target policy_delay target_policy_noise target_noise_clip "
                 "critic_batch_norm_stats critic_batch_norm_stats_target actor_batch_norm_stats actor_batch_norm_stats_target",
                 "agents/sb3/algorithms.py (_FastTD3Train.train)"),
    Internal(_TD3, "train", "copied", "agents/sb3/algorithms.py (_FastTD3Train.train)", fingerprints=("b24f0217843087e0",)),
    # 2.8 and later; 2.7 (zip_strict for zip(strict=True): the same computation)
    Internal("stable_baselines3.common.utils", "polyak_update", "copied", "agents/sb3/algorithms.py (soft_update)",
             fingerprints=("a85330e78748ad33", "8b036926f2eb07bd")),
    Internal(_SAC_POLICY, "set_training_mode", "copied", "agents/sb3/algorithms.py (FastTrainingMode)", fingerprints=("01ed0cbfe88a116f",)),
    Internal(_TD3_POLICY, "set_training_mode", "copied", "agents/sb3/algorithms.py (FastTrainingMode)", fingerprints=("01ed0cbfe88a116f",)),
    # the SAC actor's squashed Gaussian written out (algorithms.CrowdNavSACActor)
    *_attributes(_SAC_ACTOR, "action_dist use_sde", "agents/sb3/algorithms.py (CrowdNavSACActor)"),
    Internal(_SAC_ACTOR, "get_action_dist_params", "method", "agents/sb3/algorithms.py (CrowdNavSACActor), agents/imitation/cloning.py", ("obs",)),
    Internal(f"{_DISTRIBUTIONS}.SquashedDiagGaussianDistribution", "log_prob", "copied", "agents/sb3/algorithms.py (CrowdNavSACActor)",
             fingerprints=("ac0dc6a923c09dfd",)),
    Internal(f"{_DISTRIBUTIONS}.SquashedDiagGaussianDistribution", "sample", "copied", "agents/sb3/algorithms.py (CrowdNavSACActor)",
             fingerprints=("d063b2c5c83b91ee",)),
    Internal(f"{_DISTRIBUTIONS}.DiagGaussianDistribution", "proba_distribution", "copied", "agents/sb3/algorithms.py (_gaussian_sample)",
             fingerprints=("ae30f2f9e809660a",)),
    # crowdnav's networks plugged into SB3's policies (algorithms.CrowdNavSACPolicy / CrowdNavTD3Policy, SampledObservations)
    Internal(_SAC_POLICY, "_update_features_extractor", "method", "agents/sb3/algorithms.py (make_actor, make_critic)",
             ("net_kwargs", "features_extractor")),
    *_attributes(_SAC_POLICY, "actor_kwargs critic_kwargs", "agents/sb3/algorithms.py (CrowdNavSACPolicy)"),
    *_attributes(_TD3_POLICY, "actor_kwargs critic_kwargs", "agents/sb3/algorithms.py (CrowdNavTD3Policy)"),
    Internal(_SAC_POLICY, "make_actor", "method", "agents/sb3/algorithms.py (CrowdNavSACPolicy)", ("features_extractor",)),
    Internal(_SAC_POLICY, "make_critic", "method", "agents/sb3/algorithms.py (CrowdNavSACPolicy)", ("features_extractor",)),
    Internal(_TD3_POLICY, "make_actor", "method", "agents/sb3/algorithms.py (CrowdNavTD3Policy)", ("features_extractor",)),
    Internal(_TD3_POLICY, "make_critic", "method", "agents/sb3/algorithms.py (CrowdNavTD3Policy)", ("features_extractor",)),
    Internal(_CRITIC, "extract_features", "method", "agents/sb3/algorithms.py (SampledObservations, _q_values_for_actor)",
             ("obs", "features_extractor")),
    *_attributes(_CRITIC, "q_networks features_extractor normalize_images", "agents/sb3/algorithms.py (_q_values_for_actor)"),
    Internal(_CRITIC, "q1_forward", "method", "agents/sb3/algorithms.py (_FastTD3Train.train)", ("obs", "actions")),
    Internal(_BASE_POLICY, "_predict", "method", "agents/runs/onnx_export.py (the exported network)", ("observation", "deterministic")),
    *_attributes(_AC_POLICY, "mlp_extractor action_net value_net log_std", "agents/imitation/cloning.py (behaviour cloning of PPO/A2C)"),
    # buffers filled from a checkpoint's arrays (resume_state.load_replay_buffer, resume_worlds.load_rollout)
    *_attributes(_REPLAY, "observations next_observations actions rewards dones timeouts pos full buffer_size n_envs "
                 "handle_timeout_termination", "agents/runs/resume_state.py (replay_buffer.npz), agents/sb3/replay_buffer.py"),
    Internal(_REPLAY, "_get_samples", "copied", "agents/sb3/replay_buffer.py (PackedGridReplayBuffer._get_samples)",
             fingerprints=("2f3d9f3bcc594d4b",)),
    Internal(_REPLAY, "_normalize_obs", "method", "agents/sb3/replay_buffer.py (PackedGridReplayBuffer._get_samples)", ("obs", "env")),
    Internal(_REPLAY, "_normalize_reward", "method", "agents/sb3/replay_buffer.py (PackedGridReplayBuffer._get_samples)", ("reward", "env")),
    *_attributes(_ROLLOUT, "observations actions rewards returns episode_starts values log_probs advantages pos full buffer_size "
                 "generator_ready", "agents/runs/resume_worlds.py (rollout_state.npz)"),
    Internal(_VEC_ENV, "_reset_seeds", "method", "agents/sb3/vec_env.py (reset, restore_worlds, load_worlds)"),
    # sb3-contrib's RecurrentPPO (same version window): its LSTM memory, stored with a checkpoint's rollout
    Internal(_RECURRENT_PPO, "_last_lstm_states", "attribute", "agents/runs/resume_point.py, agents/runs/resume_worlds.py (rollout_state.npz)"),
    *_attributes(_RECURRENT_ROLLOUT, "hidden_states_pi cell_states_pi hidden_states_vf cell_states_vf",
                 "agents/runs/resume_worlds.py (rollout_state.npz)"),
    Internal(_RECURRENT_PPO, "collect_rollouts", "local", "agents/sb3/callbacks.py (EpisodeCallback._on_step: self.locals)", ("dones", "infos")),
)


def fingerprint(function: Callable[..., Any]) -> str:
    """16 hex digits of the function's parsed source without docstrings, comments or type annotations.

    Equal unless what the code computes may have changed. The tree is written out field by field,
    leaving out empty fields, so fields a newer Python adds to its nodes (``type_params`` in 3.12)
    do not change the fingerprint.
    """
    return source_fingerprint(inspect.getsource(function))


def source_fingerprint(source: str) -> str:
    """:func:`fingerprint` of a function's source text."""
    tree = ast.parse(textwrap.dedent(source))
    return hashlib.sha256(_dump(tree).encode()).hexdigest()[:16]


_ANNOTATIONS = frozenset({"annotation", "returns", "type_comment"})


def _dump(node: object) -> str:
    if isinstance(node, list):
        return "[" + ",".join(_dump(item) for item in node) + "]"
    if not isinstance(node, ast.AST):
        return repr(node)
    body = getattr(node, "body", None)
    fields = []
    for name in node._fields:
        value = getattr(node, name, None)
        if name == "body" and isinstance(body, list) and body and _is_docstring(body[0]):
            value = body[1:]
        if value is None or value == [] or name in _ANNOTATIONS:
            continue
        fields.append(f"{name}={_dump(value)}")
    return f"{type(node).__name__}({','.join(fields)})"


def _is_docstring(statement: ast.stmt) -> bool:
    return isinstance(statement, ast.Expr) and isinstance(statement.value, ast.Constant) and isinstance(statement.value.value, str)
