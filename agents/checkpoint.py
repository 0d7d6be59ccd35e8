"""Checkpoints: resumable training state, and deterministic policies loaded from them.

A checkpoint folder holds:

* ``model.zip``: the SB3 model (``<Algo>.load``);
* ``policy.json``: ``format``, ``algo``, ``env`` (the :class:`crowdnav.envs.CrowdNavEnv`
  keyword arguments the model needs: scenario, modalities, sensors, overrides,
  reward_weights), ``observation_normalization`` (``{key: {"offset": [...], "scale": [...]}}``,
  the fixed scaling of the model's inputs, or null for raw observations; checkpoints written
  before it existed lack the key and load as raw), ``leog_encoder`` (file of the frozen encoder
  that turns the ``leog`` grid into the latent the model was trained on, or null),
  ``episodes``, ``timesteps``, ``config``;
* ``encoder.pt``: that frozen encoder, when the model was trained on precomputed latents;
* ``replay_buffer.pkl``: the replay buffer (off-policy runs with ``save_replay_buffer``).

:func:`load_policy` accepts a checkpoint folder, its ``policy.json``, or a run folder
(then ``checkpoint/`` inside it).
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from crowdnav.agents.run_folder import CHECKPOINT_DIR, POLICY_FILE, REPLAY_FILE, RNG_FILE, ROLLOUT_FILE
from crowdnav.agents.wrappers import ObservationScales, agent_observation, scales_from_json
from stable_baselines3.common.base_class import BaseAlgorithm

POLICY_FORMAT = "crowdnav-policy/1"
MODEL_FILE = "model.zip"
ENCODER_FILE = "encoder.pt"


def save_checkpoint(
    model: BaseAlgorithm,
    folder: str | Path,
    info: Mapping[str, Any],
    *,
    encoder_file: str | Path | None = None,
    replay_buffer: bool = False,
    rng_state: bool | Mapping[str, Any] = False,
    rollout_state: Mapping[str, Any] | None = None,
) -> Path:
    """Write a checkpoint folder, replacing an existing one only once the new one is complete.

    ``info`` becomes ``policy.json`` (``format`` and ``leog_encoder`` are filled in here);
    ``encoder_file`` is copied in when the model sees precomputed latents.
    """
    folder = Path(folder)
    staging = folder.with_name(folder.name + ".partial")
    if staging.exists():
        shutil.rmtree(staging)
    staging.mkdir(parents=True)
    model.save(staging / MODEL_FILE)
    if replay_buffer and getattr(model, "replay_buffer", None) is not None:
        model.save_replay_buffer(staging / REPLAY_FILE)
    if rng_state is not False:  # a resumable checkpoint: the random streams too, so the resumed run is the same run
        save_rng_state(model, staging / RNG_FILE, rng_state if isinstance(rng_state, Mapping) else None)
    if rollout_state is not None:  # an on-policy run's collected rollout and env, for an exact resume
        import pickle

        (staging / ROLLOUT_FILE).write_bytes(pickle.dumps(dict(rollout_state)))
    if encoder_file is not None:
        shutil.copyfile(encoder_file, staging / ENCODER_FILE)
    document = {"format": POLICY_FORMAT, **info, "leog_encoder": ENCODER_FILE if encoder_file is not None else None}
    (staging / POLICY_FILE).write_text(json.dumps(document, indent=2, default=str) + "\n", encoding="utf-8")
    if folder.exists():
        old = folder.with_name(folder.name + ".old")
        if old.exists():
            shutil.rmtree(old)
        folder.rename(old)
        staging.rename(folder)
        shutil.rmtree(old)
    else:
        staging.rename(folder)
    return folder


def checkpoint_folder(path: str | Path) -> Path:
    """The checkpoint folder meant by ``path`` (a checkpoint folder, its policy.json, or a run folder)."""
    path = Path(path)
    if path.is_file() and path.name == POLICY_FILE:
        return path.parent
    if (path / POLICY_FILE).is_file():
        return path
    if (path / CHECKPOINT_DIR / POLICY_FILE).is_file():
        return path / CHECKPOINT_DIR
    raise FileNotFoundError(f"{path}: no crowdnav checkpoint here (expected {POLICY_FILE}, or checkpoint/{POLICY_FILE} in a run folder)")


def read_policy_info(path: str | Path) -> dict[str, Any]:
    """The ``policy.json`` of a checkpoint, checked."""
    file = checkpoint_folder(path) / POLICY_FILE
    info = json.loads(file.read_text(encoding="utf-8"))
    if info.get("format") != POLICY_FORMAT:
        raise ValueError(f"{file}: unsupported policy format {info.get('format')!r} (expected {POLICY_FORMAT!r})")
    return info


def load_model(path: str | Path, env: Any = None, device: str = "cpu") -> BaseAlgorithm:
    """The SB3 model of a checkpoint (on ``env`` if given, e.g. to resume training)."""
    from crowdnav.agents.factory import ALGORITHMS

    folder = checkpoint_folder(path)
    info = read_policy_info(folder)
    algo = ALGORITHMS.get(info["algo"])
    if algo is None:
        from crowdnav.registry import unknown_name_message

        raise ValueError(f"{folder}: {unknown_name_message('algorithm', info['algo'], ALGORITHMS)}")
    return algo.load(folder / MODEL_FILE, env=env, device=device)


class AgentPolicy:
    """A trained agent as ``policy(observation) -> action`` (deterministic), from :func:`load_policy`.

    ``observation`` is what :class:`crowdnav.envs.CrowdNavEnv` returns (built with
    :attr:`env_options`, or by :meth:`make_env`), one dict or a batch of them stacked per key, in
    raw units: what the model was trained on is applied here (:meth:`preprocess`), i.e. the
    observation normalisation stored with the checkpoint and the frozen LEOG encoder if the model
    was trained on latents. So anything that builds the env from :attr:`env_options` (evaluation,
    rendering) feeds the policy correctly. The action is float32 (2,) in [-1, 1] (or (N, 2) for a
    batch).
    """

    def __init__(self, model: BaseAlgorithm, info: Mapping[str, Any], encoder: Any = None):
        self.model = model
        self.info = dict(info)
        self.env_options: dict[str, Any] = dict(info["env"])
        """Keyword arguments of CrowdNavEnv that give the observations this policy expects."""
        self.encoder = encoder
        normalization = self.info.get("observation_normalization")  # absent: a checkpoint from before normalisation
        self.scales: ObservationScales | None = scales_from_json(normalization) if normalization is not None else None
        """Key -> (offset, scale) applied to raw observations (None: the model saw raw observations)."""

    @property
    def algo(self) -> str:
        return self.info["algo"]

    def preprocess(self, observation: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """A raw CrowdNavEnv observation (or batch) -> the model's input: normalised, LEOG encoded if trained so."""
        return agent_observation(observation, self.scales, self.encoder)

    def __call__(self, observation: Mapping[str, np.ndarray]) -> np.ndarray:
        action, _ = self.model.predict(self.preprocess(observation), deterministic=True)
        return action.astype(np.float32, copy=False)

    def make_env(self, **extra: Any):
        """A CrowdNavEnv configured as in training (``extra`` adds e.g. ``render_mode``).

        Its observations are raw; calling the policy on them applies the normalisation and the
        frozen encoder the model was trained with (:meth:`preprocess`).
        """
        from crowdnav.envs import CrowdNavEnv

        return CrowdNavEnv(**{**self.env_options, **extra})


def load_policy(path: str | Path, device: str = "cpu", *, trusted: bool = False, config: Any = None) -> AgentPolicy:
    """Load a checkpoint as a deterministic policy (see :class:`AgentPolicy`).

    By default only the network parameters are read (:func:`model_from_parameters`): SB3's
    ``model.zip`` also holds cloudpickled objects that run code when unpickled, so a checkpoint
    from elsewhere cannot run code through evaluation or rendering. ``trusted=True`` loads the whole
    SB3 model (``<Algo>.load``), which a checkpoint without its training config needs
    (docs/security.md). ``config``: the run's TrainConfig when the caller holds it already (the
    evaluation runner), so the checkpoint's copy is not validated again.
    """
    folder = checkpoint_folder(path)
    info = read_policy_info(folder)
    encoder = None
    if info.get("leog_encoder"):
        from crowdnav.agents.pretrain import load_encoder

        encoder, _ = load_encoder(folder / info["leog_encoder"])  # torch.load with weights_only=True
    model = load_model(folder, device=device) if trusted else model_from_parameters(folder, info, encoder, device, config)
    return AgentPolicy(model, info, encoder)


class UntrustedCheckpointError(ValueError):
    """A checkpoint that cannot be rebuilt from its config alone; only a trusted full load would read it."""


def model_from_parameters(folder: Path, info: Mapping[str, Any], encoder: Any = None, device: str = "cpu",
                          config: Any = None) -> BaseAlgorithm:
    """The checkpoint's model rebuilt from its training config, then its parameters loaded.

    SB3's ``set_parameters`` reads only the zip's ``.pth`` tensors (``torch.load`` with
    ``weights_only=True``), never its pickled ``data``. The replay buffer gets one transition:
    a policy does not learn.
    """
    from crowdnav.agents.config import ConfigError, config_from_mapping
    from crowdnav.agents.factory import make_env, make_model

    document = info.get("config")
    if config is None and not isinstance(document, Mapping):
        raise UntrustedCheckpointError(f"{folder}: the checkpoint holds no training config to rebuild its network from; "
                                       "load it with trusted=True only if you trust where it came from")
    try:
        if config is None:
            config = config_from_mapping({**document, "device": device})
        # one env to act in: the collection settings (worlds, rollout sizes) do not shape the network
        config = config.model_copy(update={"device": device, "progress": False, "tensorboard": False, "num_envs": 1,
                                           "updates_per_step": None, "n_steps": None})
        off_policy = "buffer_size" in type(config).model_fields and config.algo in ("sac", "td3", "ddpg")
        config = config.model_copy(update={"buffer_size": 1, "learning_starts": 0} if off_policy else {})
        saved_encoder = None
        if config.encoder.mode == "finetune":  # the network's LEOG layers take the pre-trained architecture
            from crowdnav.agents.factory import load_leog_weights

            _, saved_encoder = load_leog_weights(config)
        env = make_env(config, encoder, scales=scales_from_json(info["observation_normalization"])
                       if info.get("observation_normalization") is not None else None)
        model = make_model(config, env, saved_encoder)
    except ConfigError as error:
        raise UntrustedCheckpointError(f"{folder}: cannot rebuild the network from the checkpoint's config ({error})") from None
    try:
        model.set_parameters(str(folder / MODEL_FILE), exact_match=True, device=device)
    except (ValueError, RuntimeError, KeyError) as error:
        raise UntrustedCheckpointError(f"{folder}: the parameters in {MODEL_FILE} do not fit the network its config describes ({error})") from None
    return model


def rng_state(model: BaseAlgorithm) -> dict[str, Any]:
    """The random streams training draws from: torch, numpy, Python and the action space's."""
    import random

    import torch

    space = getattr(model, "action_space", None)
    return {"torch": torch.get_rng_state(), "numpy": np.random.get_state(), "random": random.getstate(),
            "action_space": space.np_random.bit_generator.state if space is not None and space._np_random is not None else None}


def save_rng_state(model: BaseAlgorithm, path: Path, state: Mapping[str, Any] | None = None) -> None:
    """The random streams (now, or the given ``state``) as a pickle.

    SB3 re-seeds all of them when a model is loaded, so without this a resumed run would draw other
    exploration noise and other replay batches than the run it continues.
    """
    import pickle

    path.write_bytes(pickle.dumps(dict(state) if state is not None else rng_state(model)))


def restore_rng_state(model: BaseAlgorithm, path: Path) -> dict[str, Any] | None:
    """Put back what :func:`save_rng_state` saved (a resumed run's own file: trusted); returns it, None without it."""
    import pickle
    import random

    import torch

    if not path.is_file():
        return None
    state = pickle.loads(path.read_bytes())
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    random.setstate(state["random"])
    if state.get("action_space") is not None:
        model.action_space.np_random.bit_generator.state = state["action_space"]
    return state
