"""An SB3 ``model.zip`` read without running any of its code: parameters and plain JSON only.

SB3's own ``<Algo>.load`` unpickles (cloudpickle) the zip's ``data`` entry, so a zip from
elsewhere can run code. Here the zip is opened with :mod:`zipfile`, every ``*.pth`` member is
read with ``torch.load(..., weights_only=True)`` (tensors only), and ``data`` is parsed as JSON:
its entries SB3 could not write as JSON are base64 pickles (``{":type:": ..., ":serialized:":
...}``), which are never decoded; only the plain JSON values beside them are read.

Only the members SB3 writes are accepted (:data:`SB3_FILES`, ``<object>.pth`` of the objects the
caller expects, :data:`SB3_OBJECTS` by default), refused in one line before anything is decompressed;
of those, only the members a caller names are read (a policy alone reads ``policy.pth``).

:func:`read_model_zip` is used by every parameter-only load (crowdnav checkpoints, resumes);
:func:`zip_policy` rebuilds the policy network of a zip saved by Stable-Baselines3 itself
(SAC, TD3, DDPG, PPO, A2C on a Dict observation) from that JSON, with every network size
bounded before anything is allocated.
"""

from __future__ import annotations

import io
import json
import re
import zipfile
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from crowdnav.errors import CrowdNavError

MAX_MEMBERS = 64
"""SB3 writes 5-8 members."""
MAX_MEMBER_BYTES = 1 << 30
"""A member's uncompressed size."""
MAX_TOTAL_BYTES = 1 << 30
"""All members' uncompressed sizes together, checked before any is read: the checkpoint of the biggest model
:data:`crowdnav.agents.networks.size.MAX_PARAMETERS` allows (its parameters and Adam's two moments) is under 700 MB."""
MAX_DATA_BYTES = 16 << 20
SB3_FILES = ("data", "_stable_baselines3_version", "system_info.txt", "pytorch_variables.pth", "tensors.pth")
"""The members of an SB3 zip besides its objects' state dicts (``tensors.pth``: SB3 before 0.9)."""
SB3_OBJECTS = ("policy", "policy.optimizer", "actor.optimizer", "critic.optimizer", "ent_coef_optimizer")
"""The objects whose state dicts SB3's algorithms save (``<name>.pth``; ``_get_torch_save_params``)."""
VARIABLES = ("pytorch_variables", "tensors")
MAX_UNITS = 4096
"""Widest hidden layer a loaded network may declare."""
MAX_LAYERS = 16
MAX_CRITICS = 16


class ModelZipError(CrowdNavError, ValueError):
    """A model zip that cannot be read as parameters and JSON, or whose network cannot be rebuilt; one line."""


@dataclass
class ModelZip:
    """What :func:`read_model_zip` reads: ``data`` (JSON, pickled values left encoded) and tensors."""

    path: Path
    data: dict[str, Any]
    parameters: dict[str, dict[str, Any]]
    """Object name (``policy``, ``actor.optimizer``, ...) -> its state dict, as SB3's ``set_parameters`` takes it."""
    variables: dict[str, Any]
    """``pytorch_variables.pth``: e.g. SAC's ``log_ent_coef``."""

    def plain(self, key: str, default: Any = None) -> Any:
        """``data[key]`` when SB3 wrote it as plain JSON; ``default`` when absent or pickled."""
        value = self.data.get(key, default)
        return default if _pickled(value) else value


def _pickled(value: Any) -> bool:
    return isinstance(value, dict) and ":serialized:" in value


def read_model_zip(path: str | Path, device: str = "cpu", objects: Collection[str] = SB3_OBJECTS,
                   read: Collection[str] | None = None) -> ModelZip:
    """The zip's JSON ``data`` and its ``.pth`` tensors; nothing pickled is decoded. ModelZipError on a bad file.

    ``objects``: the state dicts the zip may hold (any other member is refused before anything is read); ``read``: the
    ``.pth`` members to read, by name without ``.pth`` (``"policy"``, ``"pytorch_variables"``; None: all it holds).
    """
    import torch

    path = Path(path)
    try:
        with zipfile.ZipFile(path) as archive:
            names = _checked_members(archive, path, objects)
            try:
                data = json.loads(archive.read("data").decode("utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as error:
                raise ModelZipError(f"{path}: its data entry is not JSON ({str(error).splitlines()[0]})") from None
            if not isinstance(data, dict):
                raise ModelZipError(f"{path}: its data entry is not a JSON object")
            parameters, variables = {}, {}
            for name in names:
                stem = name[: -len(".pth")]
                if not name.endswith(".pth") or (read is not None and stem not in read):  # unused: never decompressed
                    continue
                try:
                    tensors = torch.load(io.BytesIO(archive.read(name)), map_location=device, weights_only=True)
                except Exception as error:  # noqa: BLE001 - whatever torch's restricted unpickler refuses: one line
                    raise ModelZipError(f"{path}: {name} holds more than tensors ({str(error).splitlines()[0][:200]})") from None
                if stem in VARIABLES:
                    variables = dict(tensors)
                else:
                    parameters[stem] = tensors
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, EOFError, NotImplementedError) as error:
        raise ModelZipError(f"{path}: cannot read it as a zip ({str(error).splitlines()[0]})") from None
    return ModelZip(path, data, parameters, variables)


def check_model_zip(path: str | Path, objects: Collection[str] = SB3_OBJECTS) -> None:
    """ModelZipError (one line) unless ``path`` holds only the members SB3 writes, within the sizes: checked from the zip's
    directory before SB3's own ``load`` decompresses every ``.pth`` member it finds."""
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as archive:
            _checked_members(archive, path, objects)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, EOFError, NotImplementedError) as error:
        raise ModelZipError(f"{path}: cannot read it as a zip ({str(error).splitlines()[0]})") from None


def _checked_members(archive: zipfile.ZipFile, path: Path, objects: Collection[str]) -> list[str]:
    """The members' names, once their count, names and uncompressed sizes (the zip's directory: what zipfile reads at most,
    whatever is compressed) are within the bounds; nothing is decompressed here."""
    members = archive.infolist()
    if len(members) > MAX_MEMBERS:
        raise ModelZipError(f"{path}: {len(members)} entries, more than an SB3 model zip holds ({MAX_MEMBERS})")
    allowed = set(SB3_FILES) | {f"{name}.pth" for name in objects}
    for member in members:
        if member.filename not in allowed:
            raise ModelZipError(f"{path}: entry {member.filename[:80]!r} is not one an SB3 model zip holds (data, "
                                f"{', '.join(f'{name}.pth' for name in objects)}, pytorch_variables.pth, _stable_baselines3_version, "
                                "system_info.txt); refused before anything is read")
        limit = MAX_DATA_BYTES if member.filename == "data" else MAX_MEMBER_BYTES
        if member.file_size > limit:
            raise ModelZipError(f"{path}: entry {member.filename} is {member.file_size:,} bytes (at most {limit:,})")
    total = sum(member.file_size for member in members)
    if total > MAX_TOTAL_BYTES:
        raise ModelZipError(f"{path}: its {len(members)} entries hold {total:,} bytes uncompressed, more than a model zip "
                            f"may ({MAX_TOTAL_BYTES:,}, crowdnav.agents.sb3.model_zip)")
    names = archive.namelist()
    if "data" not in names or "policy.pth" not in names:
        raise ModelZipError(f"{path}: not an SB3 model zip (no data or policy.pth entry)")
    return names


def check_layers(label: str, layers: Any) -> None:
    """ModelZipError unless ``layers`` (a list of widths, or a dict of such lists) is within the bounds."""
    lists = layers.values() if isinstance(layers, Mapping) else [layers]
    for widths in lists:
        if not isinstance(widths, (list, tuple)) or len(widths) > MAX_LAYERS or not all(
                isinstance(width, int) and not isinstance(width, bool) and 1 <= width <= MAX_UNITS for width in widths):
            raise ModelZipError(f"{label}: expected at most {MAX_LAYERS} layers of 1..{MAX_UNITS} units, got {str(widths)[:80]}")


# ------------------------------------------------------------------ a zip saved by SB3 itself

_POLICIES = {("stable_baselines3.common.policies", "MultiInputActorCriticPolicy"),
             ("stable_baselines3.sac.policies", "MultiInputPolicy"), ("stable_baselines3.td3.policies", "MultiInputPolicy")}
"""(module, class) a zip's JSON may name: SB3's own policies for Dict observations (DDPG's is TD3's)."""

_ACTIVATIONS = ("ReLU", "Tanh", "ELU", "LeakyReLU", "GELU", "SiLU", "Sigmoid", "Softplus", "Identity")
_FLAGS: dict[str, type | tuple[type, ...]] = {
    "use_sde": bool, "ortho_init": bool, "share_features_extractor": bool, "squash_output": bool, "full_std": bool,
    "use_expln": bool, "normalize_images": bool, "log_std_init": (int, float), "clip_mean": (int, float)}
_IGNORED = {"optimizer_class", "optimizer_kwargs"}
"""Only training uses them; a loaded policy does not."""


def zip_policy(path: str | Path, observation_space: Any,
               action_space: Any) -> tuple[Callable[..., Any] | None, dict[str, tuple[int, ...]] | None]:
    """(act, observation shapes the zip was trained on) for a zip saved by Stable-Baselines3 (act None: the shapes differ).

    The policy class, ``net_arch``, activation and flags come from the JSON ``data``; the
    network is built on ``observation_space`` (the scenario's, which the caller checks against
    the returned shapes) and gets the zip's tensors. Custom classes (a features extractor,
    sb3-contrib's policies) would need the zip's code: refused with one line.
    """
    model = read_model_zip(path, read=("policy",))  # the optimizers and variables are training's: never decompressed
    cls = _policy_class(model)
    kwargs = _policy_kwargs(model)
    shapes = observation_shapes(model)
    if shapes is not None and shapes != {key: tuple(space.shape) for key, space in observation_space.spaces.items()}:
        return None, shapes  # the caller says which modalities differ before anything is built
    _check_size(path, cls, kwargs, observation_space, action_space)
    try:
        policy = cls(observation_space, action_space, lambda _: 0.0, **kwargs)
    except (TypeError, ValueError) as error:
        raise ModelZipError(f"{path}: cannot rebuild its policy ({str(error).splitlines()[0]})") from None
    try:
        policy.load_state_dict(model.parameters["policy"])
    except (RuntimeError, KeyError, TypeError) as error:
        raise ModelZipError(f"{path}: its parameters do not fit the network its data describes ({str(error).splitlines()[0][:200]})") from None
    policy.set_training_mode(False)
    return lambda batch: policy.predict(batch, deterministic=True)[0], shapes


def _policy_class(model: ModelZip) -> type:
    import importlib

    entry = model.data.get("policy_class")
    module = entry.get("__module__") if isinstance(entry, dict) else None
    match = re.match(r"<function (\w+)\.__init__", str(entry.get("__init__", ""))) if isinstance(entry, dict) else None
    key = (module, match.group(1) if match else None)
    if key not in _POLICIES:
        raise ModelZipError(f"{model.path}: policy class {key[1] or '?'} from {key[0] or '?'} cannot be rebuilt from parameters "
                            "(supported: SB3's SAC, TD3, DDPG, PPO and A2C MultiInputPolicy); loading it would run the zip's code")
    return getattr(importlib.import_module(key[0]), key[1])


def _policy_kwargs(model: ModelZip) -> dict[str, Any]:
    import torch

    raw = model.data.get("policy_kwargs") or {}
    if not isinstance(raw, dict):
        raise ModelZipError(f"{model.path}: policy_kwargs is not a JSON object")
    kwargs: dict[str, Any] = {}
    for key, value in raw.items():
        if key.startswith(":") or key in _IGNORED:
            continue
        if key == "net_arch":
            check_layers(f"{model.path}: net_arch", value)
            kwargs[key] = value
        elif key == "n_critics":
            if not isinstance(value, int) or not 1 <= value <= MAX_CRITICS:
                raise ModelZipError(f"{model.path}: n_critics must be 1..{MAX_CRITICS}, got {str(value)[:40]}")
            kwargs[key] = value
        elif key == "activation_fn":
            match = re.fullmatch(r"<class 'torch\.nn\.modules\.activation\.(\w+)'>", str(value))
            if match is None or match.group(1) not in _ACTIVATIONS:
                raise ModelZipError(f"{model.path}: activation {str(value)[:80]} cannot be rebuilt from parameters")
            kwargs[key] = getattr(torch.nn, match.group(1))
        elif key == "features_extractor_class":
            if "CombinedExtractor" not in str(value):
                raise ModelZipError(f"{model.path}: features extractor {str(value)[:80]} is custom code; only SB3's "
                                    "CombinedExtractor can be rebuilt from parameters")
        elif key in _FLAGS and isinstance(value, _FLAGS[key]):
            kwargs[key] = value
        else:
            raise ModelZipError(f"{model.path}: policy_kwargs {key!r} cannot be rebuilt from parameters")
    return kwargs


def _check_size(path: str | Path, cls: type, kwargs: Mapping[str, Any], observation_space: Any, action_space: Any) -> None:
    """ModelZipError if the policy the zip describes would hold more than the parameters a model may (counted, not built)."""
    from crowdnav.agents.networks.size import NetworkSizeError, check_parameters, describe_layers

    total, net_arch = zip_parameters(cls, kwargs, observation_space, action_space)
    try:
        critics = f", n_critics {kwargs['n_critics']}" if "n_critics" in kwargs else ""
        check_parameters(total, str(path), f"net_arch {describe_layers(net_arch)}{critics}")
    except NetworkSizeError as error:
        raise ModelZipError(str(error)) from None


def zip_parameters(cls: type, kwargs: Mapping[str, Any], observation_space: Any, action_space: Any) -> tuple[int, Any]:
    """(parameters, net_arch) of SB3's policy ``cls`` built with ``kwargs`` on these spaces, counted by arithmetic."""
    from crowdnav.agents.networks.size import heads, mlp, policy_kind

    kind = policy_kind(cls)
    defaults: Any = {"actor_critic": {"pi": [64, 64], "vf": [64, 64]}, "sac": [256, 256], "td3": [400, 300]}[kind]
    net_arch = kwargs.get("net_arch", defaults)
    extractor = features = 0
    for space in observation_space.spaces.values():  # SB3's CombinedExtractor: NatureCNN for images, flattened otherwise
        if _is_image(space, kwargs.get("normalize_images", True)):
            channels, height, width = space.shape
            convs = channels * 32 * 64 + 32 + 32 * 64 * 16 + 64 + 64 * 64 * 9 + 64
            height, width = ((height - 8) // 4 + 1 - 4) // 2 + 1 - 2, ((width - 8) // 4 + 1 - 4) // 2 + 1 - 2
            extractor += convs + mlp(64 * max(height, 0) * max(width, 0), [256])[0]
            features += 256
        else:
            features += int(np.prod(space.shape))
    options = {name: bool(kwargs[name]) for name in ("share_features_extractor", "use_sde", "full_std") if name in kwargs}
    total = heads(kind, features, extractor, int(np.prod(action_space.shape)), net_arch, n_critics=int(kwargs.get("n_critics", 2)),
                  **options)
    return total, net_arch


def _is_image(space: Any, normalize_images: bool) -> bool:
    from stable_baselines3.common.preprocessing import is_image_space

    return bool(is_image_space(space, normalized_image=not normalize_images))


_BOX = re.compile(r"'([^']+)': Box\(.*?, \(([0-9, ]*)\), \w+\)")


def observation_shapes(model: ModelZip) -> dict[str, tuple[int, ...]] | None:
    """The Dict observation's key -> shape, read from the text SB3 writes beside the pickled space (None if absent)."""
    entry = model.data.get("observation_space")
    text = entry.get("spaces") if isinstance(entry, dict) else None
    if not isinstance(text, str):
        return None
    found = {key: tuple(int(n) for n in shape.replace(" ", "").split(",") if n) for key, shape in _BOX.findall(text)}
    return found or None


def describe_shapes(shapes: Mapping[str, tuple[int, ...]]) -> str:
    return "{" + ", ".join(f"{key}: {tuple(shape)}" for key, shape in shapes.items()) + "}"
