"""The Stable-Baselines3 algorithms through the algorithm seam (:mod:`crowdnav.agents.training.algorithm_protocol`).

* :class:`SB3Algorithm`: an SB3 model as an :class:`~crowdnav.agents.training.algorithm_protocol.Algorithm` (``learn``,
  ``save``, ``predict``) and :class:`~crowdnav.agents.training.algorithm_protocol.Exportable` (``export_module``: the
  policy's deterministic action, :class:`crowdnav.agents.runs.onnx_export.SB3Actor`);
* :class:`SB3Builder`: ``builder(env, config)`` (:func:`crowdnav.agents.sb3.factory.make_model`) and ``builder.load(folder)``
  (``model.zip`` read as tensors, no pickle, and ``sb3.json``): an SB3 algorithm trained by crowdnav's episode loop
  (:mod:`crowdnav.agents.training.episode_loop`) like any registered one. ``learn`` calls ``keep_going`` from SB3's step
  callback once an episode ended; a checkpoint holds the weights and optimisers, not the replay buffer or the
  rollout, so a resume through that loop continues close to the interrupted run, not bit for bit;
* :data:`SB3_BUILDER` (:class:`SB3SessionBuilder`), the builder the registry's SB3 specs name
  (:data:`crowdnav.registry.SB3_BUILDER`): the same, and a :class:`~crowdnav.agents.training.algorithm_protocol.RunTrainer`.
  ``crowdnav train`` runs its :class:`~crowdnav.agents.sb3.session.TrainingSession` (SB3's own loop, several worlds at
  once, replay buffers and rollouts restored mid-episode: an exact resume), whose checkpoints hold ``model.zip``
  at their top (:mod:`crowdnav.agents.runs.checkpoint`), read back by :meth:`SB3SessionBuilder.load_checkpoint`.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from crowdnav.agents.runs.checkpoint import MODEL_FILE, load_model, model_from_parameters, resume_model
from crowdnav.agents.runs.result import TrainResult
from crowdnav.agents.sb3.factory import make_env, make_model, observation_normalization
from crowdnav.agents.sb3.session import TrainingSession
from crowdnav.agents.training.algorithm_protocol import SB3Predictor
from crowdnav.agents.training.config import TrainConfig, config_from_mapping, config_to_dict
from crowdnav.agents.training.wrappers import scales_from_json, scales_to_json
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv

if TYPE_CHECKING:
    from torch import nn

SETTINGS_FILE = "sb3.json"
"""Beside ``model.zip`` in :meth:`SB3Algorithm.save`'s folder: the algorithm, its training config and its observation scaling."""


class SB3Algorithm(SB3Predictor):
    """An SB3 ``model`` as an Algorithm; ``settings``: ``algo``, ``config`` (the TrainConfig as a dict) and
    ``observation_normalization`` (as in policy.json), what :meth:`load` rebuilds the network from."""

    def __init__(self, model: BaseAlgorithm, settings: Mapping[str, Any]):
        super().__init__(model)
        self.settings: dict[str, Any] = {key: settings.get(key) for key in ("algo", "config", "observation_normalization")}

    def learn(self, env: VecEnv, keep_going: Callable[[], bool]) -> None:
        """SB3's ``learn`` on ``env``'s worlds for the rest of the config's budget, ``keep_going()`` after every episode that ended."""
        config = config_from_mapping(self.settings["config"])
        if self.model.get_env() is not env:  # a loaded model acts in an env of its own
            self.model.set_env(env)
        steps = int(env.get_attr("scenario")[0].max_steps) * env.num_envs  # every world's episodes as long as the limit
        total = config.timesteps if config.timesteps is not None else config.episodes * steps + 1
        self.model.learn(max(1, total - self.model.num_timesteps), callback=_KeepGoing(keep_going), reset_num_timesteps=False)

    def save(self, folder: Path) -> None:
        """``model.zip`` (tensors, read back without unpickling) and ``sb3.json``."""
        self.model.save(folder / MODEL_FILE)
        (folder / SETTINGS_FILE).write_text(json.dumps(self.settings, indent=2, default=str) + "\n", encoding="utf-8")

    @classmethod
    def load(cls, folder: Path, device: str = "cpu") -> SB3Algorithm:
        """What :meth:`save` wrote: the network rebuilt from the saved config, its tensors loaded (no pickle)."""
        settings = json.loads((folder / SETTINGS_FILE).read_text(encoding="utf-8"))
        config = config_from_mapping({**settings["config"], "device": device})
        saved = settings.get("observation_normalization")
        env = make_env(config, None, 0, scales_from_json(saved) if saved is not None else None)
        return cls(resume_model(folder, config, env), settings)

    def export_module(self, keys: Sequence[str]) -> nn.Module:
        """The policy's deterministic action as a torch module (SAC: tanh of the mean; TD3 / DDPG: the actor; PPO / A2C: the mean;
        an LSTM policy: the mean and its next state, :class:`~crowdnav.agents.runs.onnx_export.RecurrentSB3Actor`)."""
        from crowdnav.agents.runs.onnx_export import sb3_actor

        return sb3_actor(self.model, list(keys))


class _KeepGoing(BaseCallback):
    """Calls ``keep_going()`` once per episode a step ended (world order); SB3's loop stops when it says False."""

    def __init__(self, keep_going: Callable[[], bool]):
        super().__init__()
        self.keep_going = keep_going

    def _on_step(self) -> bool:
        return all([bool(self.keep_going()) for _ in range(int(np.count_nonzero(self.locals["dones"])))])  # every call made


class SB3Builder:
    """``builder(env, config)`` and ``builder.load(folder)`` of :class:`SB3Algorithm`, for any spec with an ``sb3_class``."""

    def __call__(self, env: VecEnv, config: TrainConfig) -> SB3Algorithm:
        scales = observation_normalization(env)
        settings = {"algo": config.algo, "config": config_to_dict(config),
                    "observation_normalization": None if scales is None else scales_to_json(scales)}
        return SB3Algorithm(make_model(config, env), settings)

    def load(self, folder: Path) -> SB3Algorithm:
        return SB3Algorithm.load(folder)


class SB3SessionBuilder(SB3Builder):
    """:class:`SB3Builder` that trains runs in a :class:`~crowdnav.agents.sb3.session.TrainingSession` and reads its checkpoints."""

    def train_run(self, config: TrainConfig, resume: bool, on_checkpoint: Callable[[int], None] | None,
                  trust_pickle: bool) -> TrainResult:
        return TrainingSession(config, resume, on_checkpoint, trust_pickle).run()

    def load_checkpoint(self, folder: Path, info: Mapping[str, Any], *, encoder: Any, device: str, trusted: bool,
                        config: Any) -> SB3Algorithm:
        """The checkpoint's model: its tensors into the network its config describes, or ``trusted``: SB3's full load."""
        model = load_model(folder, device=device) if trusted else model_from_parameters(folder, info, encoder, device, config)
        return SB3Algorithm(model, info)


SB3_BUILDER = SB3SessionBuilder()
"""The builder of the registry's Stable-Baselines3 specs (``crowdnav.registry.SB3_BUILDER`` names it)."""
