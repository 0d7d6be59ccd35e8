"""Checkpoints: resumable training state, and deterministic policies loaded from them.

A checkpoint folder holds:

* ``model.zip``: the SB3 model (parameters and optimizers as tensors; read without unpickling,
  :mod:`crowdnav.agents.sb3.model_zip`);
* ``policy.json``: ``format``, ``algo``, ``env`` (the :class:`crowdnav.envs.CrowdNavEnv`
  keyword arguments the model needs: scenario, modalities, sensors, overrides,
  reward_weights), ``observation_normalization`` (``{key: {"offset": [...], "scale": [...]}}``,
  the fixed scaling of the model's inputs, or null for raw observations; checkpoints written
  before it existed lack the key and load as raw), ``leog_encoder`` (file of the frozen encoder
  that turns the ``leog`` grid into the latent the model was trained on, or null),
  ``episodes``, ``timesteps``, ``config``;
* ``encoder.pt``: that frozen encoder, when the model was trained on precomputed latents;
* resumable checkpoints: ``training_state.json``, ``replay_buffer.npz`` (off-policy runs with
  ``save_replay_buffer``) and ``rollout_state.npz`` (:mod:`crowdnav.agents.runs.resume_state`): JSON and
  arrays, no pickle. Checkpoints of older crowdnav versions hold pickles instead
  (``rng_state.pkl``, ``replay_buffer.pkl``, ``rollout_state.pkl``), read only on request.

:func:`load_policy` accepts a checkpoint folder, its ``policy.json``, or a run folder
(then ``checkpoint/`` inside it).
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np
from crowdnav.agents.runs.folder import CHECKPOINT_DIR, POLICY_FILE, REPLAY_FILE, RNG_FILE, ROLLOUT_FILE
from crowdnav.agents.runs.resume_state import (
    REPLAY_ARRAYS,
    ROLLOUT_ARRAYS,
    STATE_FILE,
    check_format,
    save_replay_buffer,
    save_training_state,
)
from crowdnav.agents.runs.resume_state import rng_state as streams_now
from crowdnav.agents.sb3.model_zip import ModelZipError, check_layers, check_model_zip, read_model_zip
from crowdnav.agents.training.wrappers import ObservationScales, agent_observation, scales_from_json
from stable_baselines3.common.base_class import BaseAlgorithm

from crowdnav.errors import CrowdNavError
from crowdnav.files import discard_leftovers, staging_beside, swap_folder
from crowdnav.registry import algorithm_spec

if TYPE_CHECKING:
    from crowdnav.agents.training.algorithm_protocol import Algorithm

    from crowdnav.envs import CrowdNavEnv

POLICY_FORMAT = "crowdnav-policy/1"
"""``policy.json``'s ``format``: a name and a version, raised when the checkpoint layout changes incompatibly."""
MODEL_FILE = "model.zip"
ENCODER_FILE = "encoder.pt"
MAX_POLICY_BYTES = 16 << 20


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
    ``encoder_file`` is copied in when the model sees precomputed latents. ``rng_state`` (True:
    the streams now; a mapping: those streams) makes it resumable: ``training_state.json``;
    ``rollout_state``: :meth:`ResumePoint.rollout_state`'s dict, written as ``rollout_state.npz``.
    """
    folder = Path(folder)
    staging = staging_folder(folder)
    model.save(staging / MODEL_FILE)
    buffer = getattr(model, "replay_buffer", None)  # off-policy models only
    if replay_buffer and buffer is not None:
        save_replay_buffer(buffer, staging / REPLAY_ARRAYS)
    if rng_state is not False:  # a resumable checkpoint: counters and random streams, so the resumed run is the same run
        save_training_state(model, staging / STATE_FILE, rng_state if isinstance(rng_state, Mapping) else streams_now(model))
    if rollout_state is not None:  # an on-policy or batched run's collected rollout and worlds, for an exact resume
        from crowdnav.agents.runs.resume_worlds import save_rollout

        save_rollout(staging / ROLLOUT_ARRAYS, rollout_state)
    if encoder_file is not None:
        shutil.copyfile(encoder_file, staging / ENCODER_FILE)
    document = {"format": POLICY_FORMAT, **info, "leog_encoder": ENCODER_FILE if encoder_file is not None else None}
    (staging / POLICY_FILE).write_text(json.dumps(document, indent=2, default=str) + "\n", encoding="utf-8")
    replace_folder(staging, folder)
    return folder


def staging_folder(folder: Path) -> Path:
    """A new empty hidden folder beside ``folder`` to write a checkpoint into (:func:`replace_folder` then swaps it in)."""
    discard_leftovers(folder)  # a killed save's copies (links removed, not followed); the run's lock keeps other writers out
    return staging_beside(folder)


def replace_folder(staging: Path, folder: Path) -> None:
    """Put the complete ``staging`` folder in ``folder``'s place (a kill leaves a complete copy for ``recover_checkpoint``)."""
    swap_folder(staging, folder)


def find_checkpoint(path: str | Path) -> Path:
    """The existing checkpoint folder meant by ``path`` (a checkpoint folder, its policy.json, or a run folder).

    It looks on disk; :func:`crowdnav.agents.runs.folder.checkpoint_dir` only names where a run's
    checkpoint goes.
    """
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
    file = find_checkpoint(path) / POLICY_FILE
    if file.stat().st_size > MAX_POLICY_BYTES:
        raise ValueError(f"{file}: {file.stat().st_size:,} bytes, more than a policy.json holds ({MAX_POLICY_BYTES:,})")
    try:
        info = json.loads(file.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as error:
        raise ValueError(f"{file}: not JSON ({str(error).splitlines()[0]})") from None
    try:
        check_format(info.get("format") if isinstance(info, dict) else None, POLICY_FORMAT)
    except ValueError as error:
        raise ValueError(f"{file}: unsupported policy {error}") from None
    check_policy_fields(info, file)
    return info


class PolicyFileError(CrowdNavError, ValueError):
    """A ``policy.json`` whose fields are not what crowdnav writes (damaged or edited); one line naming the field."""


def check_policy_fields(info: Mapping[str, Any], file: Path) -> None:
    """PolicyFileError unless the fields every loader reads have the kinds crowdnav writes (checked before any is used).

    ``algo`` a name; ``env`` a mapping whose ``scenario`` is a library name or a file's path (a text),
    its other options mappings or lists; ``config`` and ``observation_normalization`` mappings or
    null; ``leog_encoder`` a file name or null.
    """
    def refuse(field: str, expected: str, value: Any) -> NoReturn:
        raise PolicyFileError(f"{file}: {field}: expected {expected}, got {str(value)[:60]!r}")

    if not isinstance(info.get("algo"), str):
        refuse("algo", "the algorithm's name", info.get("algo"))
    env = info.get("env")
    if not isinstance(env, Mapping):
        refuse("env", "a mapping of environment options", env)
    if "scenario" in env and (not isinstance(env["scenario"], str) or not env["scenario"].strip()):
        refuse("env.scenario", "a library scenario name or a scenario file's path", env.get("scenario"))
    for key in ("sensors", "overrides", "reward_weights"):
        if key in env and not isinstance(env[key], Mapping):
            refuse(f"env.{key}", "a mapping", env[key])
    if "modalities" in env and not (isinstance(env["modalities"], list) and all(isinstance(key, str) for key in env["modalities"])):
        refuse("env.modalities", "a list of modality names", env["modalities"])
    for key in ("config", "observation_normalization"):
        if info.get(key) is not None and not isinstance(info[key], Mapping):
            refuse(key, "a mapping or null", info[key])
    if info.get("leog_encoder") is not None and not isinstance(info["leog_encoder"], str):
        refuse("leog_encoder", "a file name or null", info["leog_encoder"])


def load_model(path: str | Path, env: Any = None, device: str = "cpu") -> BaseAlgorithm:
    """The SB3 model of a checkpoint by SB3's own ``<Algo>.load`` (on ``env`` if given).

    That unpickles the zip's ``data``, which can run code: only for checkpoints you trust
    (``load_policy(..., trusted=True)``, ``train(..., trust_pickle=True)``).
    """
    from crowdnav.agents.sb3.factory import model_class

    folder = find_checkpoint(path)
    info = read_policy_info(folder)
    try:
        algo = model_class(info["algo"])
    except ValueError as error:  # an unknown name, or an algorithm outside SB3 (ConfigError)
        raise ValueError(f"{folder}: {error}") from None
    check_model_zip(folder / MODEL_FILE)  # SB3's load decompresses every .pth member: only SB3's own names, sizes bounded
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

    def __init__(self, model: BaseAlgorithm | Algorithm, info: Mapping[str, Any], encoder: Any = None):
        from crowdnav.agents.training.algorithm_protocol import SB3Predictor, as_predictor, is_recurrent

        self.agent = as_predictor(model)
        """The agent that acts (crowdnav.agents.training.algorithm_protocol): an SB3 model through its SB3Algorithm (or SB3Predictor)."""
        self.model = self.agent.model if isinstance(self.agent, SB3Predictor) else self.agent
        """The SB3 model of an SB3 algorithm, else the agent itself."""
        self.recurrent = is_recurrent(self.agent)
        """Whether the agent carries a state between steps (an LSTM policy): play it with :meth:`predict`, not a call."""
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

    def predict(self, observation: Mapping[str, np.ndarray], state: Any = None,
                episode_start: np.ndarray | None = None) -> tuple[np.ndarray, Any]:
        """(actions, next state), deterministic: :meth:`Predictor.predict` on the preprocessed observation.

        Keep the state and give it back at the next step with ``episode_start`` True for the rows whose episode has
        just begun (a memoryless agent returns None and ignores both); the rows of a batch stay the same worlds.
        """
        action, state = self.agent.predict(self.preprocess(observation), state, episode_start, deterministic=True)
        return np.asarray(action).astype(np.float32, copy=False), state

    def __call__(self, observation: Mapping[str, np.ndarray]) -> np.ndarray:
        if self.recurrent:  # a call keeps no state: each step would start a fresh memory
            raise RecurrentPolicyError(f"{self.algo} carries a state between steps: play it with "
                                       "policy.predict(observation, state, episode_start), keeping the state it returns")
        return self.predict(observation)[0]

    def make_env(self, **extra: Any) -> CrowdNavEnv:
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
    folder = find_checkpoint(path)
    info = read_policy_info(folder)
    if info.get("agents") == "robots":  # crowdnav.agents.marl.robots's shared policy: not one robot's policy, whatever its zip holds
        raise SharedRobotPolicyError(f"{folder} is a shared robot policy (agents: robots), one network driving every robot of its "
                                     "scenario at once, not one robot's policy: "
                                     "play it with `crowdnav render`, score it with `crowdnav evaluate` (one row per robot), rank it "
                                     "in an experiment with agents: robots, or load it with crowdnav.agents.load_robots_policy "
                                     "(docs/agents.md#several-robots-shared-parameter-ppo)")
    encoder = None
    if info.get("leog_encoder"):
        from crowdnav.agents.networks.pretrain import load_encoder

        encoder, _ = load_encoder(folder / info["leog_encoder"])  # torch.load with weights_only=True
    try:
        algorithm_spec(info["algo"])
    except ValueError as error:  # e.g. an algorithm registered by a module this process has not imported
        raise PolicyFileError(f"{folder}: trained with {error.args[0]} (register it, or install the package that provides it)") from None
    from crowdnav.agents.training.algorithm_protocol import load_agent

    # every algorithm by its registered builder (arrays and JSON, no pickle unless trusted): SB3's reads model.zip here
    return AgentPolicy(load_agent(folder, info, encoder=encoder, device=device, trusted=trusted, config=config), info, encoder)


class RecurrentPolicyError(CrowdNavError, TypeError):
    """A recurrent policy called as ``policy(observation)``, which would drop its memory at every step."""


class SharedRobotPolicyError(CrowdNavError, ValueError):
    """A shared robot policy (``agents: robots``) given where one robot's policy is expected."""


class UntrustedCheckpointError(CrowdNavError, ValueError):
    """A checkpoint that cannot be rebuilt from its config alone; only a trusted full load would read it."""


def model_from_parameters(folder: Path, info: Mapping[str, Any], encoder: Any = None, device: str = "cpu",
                          config: Any = None) -> BaseAlgorithm:
    """The checkpoint's model rebuilt from its training config, then its parameters loaded.

    The network sizes are checked first (:func:`check_network_size`), so a hostile config is one
    line, not gigabytes; the zip is read by :func:`load_parameters` (tensors only, never its
    pickled ``data``). The replay buffer gets one transition and the rollout a few steps: a
    policy does not learn.
    """
    from crowdnav.agents.sb3.factory import make_env, make_model
    from crowdnav.agents.training.config import ConfigError, config_from_mapping

    document = info.get("config")
    if config is None and not isinstance(document, Mapping):
        raise UntrustedCheckpointError(f"{folder}: the checkpoint holds no training config to rebuild its network from; "
                                       "load it with trusted=True only if you trust where it came from")
    try:
        if config is None and isinstance(document, Mapping):  # (no config and no document was refused above)
            config = config_from_mapping({**document, "device": device})
        # one env to act in: the collection settings (worlds, rollout sizes) do not shape the network
        small = {key: value for key, value in config.algo_kwargs.items() if key not in ("n_steps", "buffer_size", "batch_size")}
        config = config.model_copy(update={"device": device, "progress": False, "tensorboard": False, "num_envs": 1,
                                           "updates_per_step": None, "n_steps": None, "algo_kwargs": small})
        spec = algorithm_spec(config.algo)
        off_policy = "buffer_size" in type(config).model_fields and spec.off_policy
        config = config.model_copy(update={"buffer_size": 1, "learning_starts": 0} if off_policy else
                                   {"n_steps": 8, **({"batch_size": 8} if "batch_size" in spec.defaults else {})})
        check_network_size(config, str(folder))
        saved_encoder = None
        if config.encoder.mode == "finetune":  # the network's LEOG layers take the pre-trained architecture
            from crowdnav.agents.sb3.factory import load_leog_weights

            _, saved_encoder = load_leog_weights(config)
        env = make_env(config, encoder, scales=scales_from_json(info["observation_normalization"])
                       if info.get("observation_normalization") is not None else None)
        model = make_model(config, env, saved_encoder)
    except ConfigError as error:
        raise UntrustedCheckpointError(f"{folder}: cannot rebuild the network from the checkpoint's config ({error})") from None
    try:
        load_parameters(model, folder / MODEL_FILE, device)
    except (ValueError, RuntimeError, KeyError) as error:
        raise UntrustedCheckpointError(f"{folder}: the parameters in {MODEL_FILE} do not fit the network its config describes "
                                       f"({str(error).splitlines()[0][:300]})") from None
    return model


def check_network_size(config: Any, label: str) -> None:
    """UntrustedCheckpointError unless every layer the config asks for is within :data:`crowdnav.agents.sb3.model_zip.MAX_UNITS`.

    Checked before the network is built: ``net_arch: [20000, 20000]`` would otherwise allocate
    gigabytes before the parameters are found not to fit.
    """
    from crowdnav.agents.sb3.factory import hyperparameters

    extractor = config.extractor
    try:
        check_layers(f"{label}: net_arch", hyperparameters(config)["net_arch"])
        for name in ("leog_channels", "leog_kernels", "leog_strides", "leog_head", "lidar_hidden", "lidar_conv_channels",
                     "lowdim_hidden", "table_hidden"):
            check_layers(f"{label}: extractor.{name}", list(getattr(extractor, name)))
        check_layers(f"{label}: extractor.leog_latent", [extractor.leog_latent])
        check_layers(f"{label}: extractor.rbf_centres", [extractor.rbf_centres] if extractor.rbf_centres else [])
        critics = config.policy_kwargs.get("n_critics", 2)
        if not isinstance(critics, int) or not 1 <= critics <= 16:
            raise ModelZipError(f"{label}: policy_kwargs.n_critics must be 1..16, got {str(critics)[:40]}")
    except ModelZipError as error:
        raise UntrustedCheckpointError(str(error)) from None


def load_parameters(model: BaseAlgorithm, path: Path, device: str = "cpu") -> None:
    """The zip's tensors into ``model`` (built from the run's config): networks, optimizers, SB3's variables.

    The same tensors SB3's ``load`` restores (SAC's entropy coefficient is such a variable),
    read by :func:`crowdnav.agents.sb3.model_zip.read_model_zip`: nothing in the zip is unpickled.
    """
    import torch
    from stable_baselines3.common.utils import get_device

    objects, _ = model._get_torch_save_params()  # the state dicts this model has: any other member is refused unread
    zipped = read_model_zip(path, str(get_device(device)), objects=objects)
    # SB3 annotates a dict of tensors; it takes (and its own load passes) a dict of state dicts, one per object, as here
    model.set_parameters(zipped.parameters, exact_match=True, device=device)  # type: ignore[arg-type]
    expected = set(model._get_torch_save_params()[1])
    if set(zipped.variables) != expected:
        raise ModelZipError(f"{path}: variables {sorted(zipped.variables)}, the network has {sorted(expected)}")
    from stable_baselines3.common.save_util import recursive_getattr

    with torch.no_grad():
        for name, value in zipped.variables.items():
            target = recursive_getattr(model, name)
            if not isinstance(value, torch.Tensor) or value.shape != target.shape or value.dtype != target.dtype:
                raise ModelZipError(f"{path}: variable {name} does not fit the network")
            target.copy_(value)


def resume_model(folder: Path, config: Any, env: Any, saved_encoder: Any = None, tensorboard_log: str | None = None) -> BaseAlgorithm:
    """A resumed run's model: built from the run's config on ``env``, the checkpoint's tensors loaded (no pickle)."""
    from crowdnav.agents.sb3.factory import make_model

    check_network_size(config, str(folder))
    model = make_model(config, env, saved_encoder, tensorboard_log)
    try:
        load_parameters(model, folder / MODEL_FILE, config.device)
    except (ValueError, RuntimeError, KeyError) as error:
        from crowdnav.agents.training.config import ConfigError

        raise ConfigError(f"cannot resume: the parameters in {folder / MODEL_FILE} do not fit the network the config describes "
                          f"({str(error).splitlines()[0][:300]})") from None
    return model


LEGACY_FILES = (RNG_FILE, REPLAY_FILE, ROLLOUT_FILE)
"""What checkpoints of older crowdnav versions pickled; read only with ``trust_pickle``."""


def restore_pickled_rng_state(model: BaseAlgorithm, path: Path) -> dict[str, Any] | None:
    """An older checkpoint's pickled random streams (``rng_state.pkl``): runs code; only with ``trust_pickle``."""
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
