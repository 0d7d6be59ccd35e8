"""Checks of a SARL checkpoint's files before they are used: ``state.json``'s fields, the npz members' headers, finite weights.

A checkpoint folder (``algorithm/``: state.json, weights.npz, memory.npz, demonstrations.npz) may come from
elsewhere or be damaged. Its options are checked as a config's are (:mod:`crowdnav.agents.sarl.options`, sizes
included) before any network is built; every npz member's shape and dtype are read from its ``.npy`` header
(:func:`array_headers`, nothing else read) and compared with what the options and ``state.json`` declare before a
single array is loaded, so a member declaring gigabytes is refused, not allocated; loaded weights must be finite.
Each refusal is one line naming the file (:class:`SarlFileError`).
"""

from __future__ import annotations

import json
import math
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import fields
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import torch
from crowdnav.agents.sarl.lookahead import OPTIONAL_KEYS, REQUIRED_KEYS, Physics
from crowdnav.agents.sarl.options import MAX_ROWS, check_options
from crowdnav.agents.training.config import ConfigError

from crowdnav.errors import CrowdNavError

MAX_STATE_BYTES = 16 << 20
"""Most bytes of a ``state.json`` (crowdnav's are a few KB; the geodesic grid's scales a few hundred)."""
MAX_MEMBERS = 4096
"""Most members of one npz (the biggest allowed ensemble's weights and Adam state hold a few hundred)."""

Header = tuple[tuple[int, ...], np.dtype]
KINDS = {"f": "float", "iu": "integer", "fiu": "a number"}


class SarlFileError(CrowdNavError, ValueError):
    """A SARL checkpoint file that is not what crowdnav writes (damaged, tampered, or of other settings); one line."""


def refuse(path: Path, message: str) -> NoReturn:
    raise SarlFileError(f"{path}: {message}")


def _shown(value: Any) -> str:
    return repr(value)[:40]


# ------------------------------------------------------------------ state.json


def read_state(path: Path, name: str, defaults: Mapping[str, Any]) -> dict[str, Any]:
    """``state.json`` parsed, with every field the loader reads checked (options: as a config's, against ``defaults``)."""
    try:
        if path.stat().st_size > MAX_STATE_BYTES:
            refuse(path, f"{path.stat().st_size:,} bytes, more than the {MAX_STATE_BYTES:,} a SARL state.json may hold")
        document = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as error:
        refuse(path, f"cannot be read as JSON ({str(error)[:120]})")
    if not isinstance(document, dict):
        refuse(path, "expected a JSON object")
    options = document.get("options")
    if not isinstance(options, dict) or set(options) - set(defaults):
        refuse(path, f"options: expected a mapping of the agent's options, got {_shown(options)}")
    try:
        check_options({**defaults, **options}, name, "options")
    except ConfigError as error:
        refuse(path, str(error))
    for field, low, high, default in (("humans", 0, MAX_ROWS, None), ("statics", 0, MAX_ROWS, 0), ("episodes", 0, None, None)):
        value = document.get(field, default)
        if not _integer(value, low, high):
            refuse(path, f"{field}: expected an integer from {low}{'' if high is None else f' to {high:,}'}, got {_shown(value)}")
    if not isinstance(document.get("geodesic", False), bool):
        refuse(path, f"geodesic: expected true or false, got {_shown(document.get('geodesic'))}")
    decay = document.get("decay_episodes")
    if decay is not None and not _integer(decay, 1, None):
        refuse(path, f"decay_episodes: expected null or a positive integer, got {_shown(decay)}")
    for name, most in (("gamma", 1.0), ("learning_rate", 1e6)):
        if not _number(document.get(name), 0.0, most):
            refuse(path, f"{name}: expected a number from 0.0 to {most}, got {_shown(document.get(name))}")
    _check_physics(path, document.get("physics"))
    _check_scales(path, document.get("scales"))
    groups = document.get("adam_groups")
    if not isinstance(groups, list) or not all(isinstance(group, dict) for group in groups):
        refuse(path, f"adam_groups: expected a list of Adam's parameter groups, got {_shown(groups)}")
    if not isinstance(document.get("rng"), dict):
        refuse(path, f"rng: expected a generator's state, got {_shown(document.get('rng'))}")
    return document


def _integer(value: Any, low: int, high: int | None) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and low <= value and (high is None or value <= high)


def _number(value: Any, low: float, high: float) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and low <= value <= high


def _check_physics(path: Path, physics: Any) -> None:
    names = {field.name for field in fields(Physics)}
    if not isinstance(physics, dict) or set(physics) - names or not {"radius", "max_speed", "time_step", "weights"} <= set(physics):
        refuse(path, f"physics: expected the fields {', '.join(sorted(names))}, got {_shown(physics)}")
    for key, value in physics.items():
        positive = key in ("radius", "max_speed", "time_step", "geodesic_spacing", "reward_scale")
        if key != "weights" and not (_number(value, 0.0, 1e6) and (value > 0 or not positive)):
            refuse(path, f"physics.{key}: expected a {'positive ' if positive else ''}number up to 1e6, got {_shown(value)}")
    weights = physics["weights"]
    terms = ("step", "goal_progress", "social", "goal_reached", "collision")
    if not isinstance(weights, dict) or set(weights) != set(terms) or not all(_number(weights[term], -1e6, 1e6) for term in terms):
        refuse(path, f"physics.weights: expected finite numbers for {', '.join(terms)}, got {_shown(weights)}")


def _check_scales(path: Path, scales: Any) -> None:
    if not isinstance(scales, dict):
        refuse(path, f"scales: expected a mapping of observation keys, got {_shown(scales)}")
    for key, item in scales.items():
        if key not in (*REQUIRED_KEYS, *OPTIONAL_KEYS) or not isinstance(item, dict) or set(item) != {"offset", "scale"}:
            refuse(path, f"scales.{str(key)[:40]}: expected offset and scale of an observation the agent reads")
        try:
            offset, scale = (np.asarray(item[part], dtype=np.float64) for part in ("offset", "scale"))
        except (TypeError, ValueError):
            refuse(path, f"scales.{key}: expected arrays of numbers")
        if offset.shape != scale.shape or not (np.isfinite(offset).all() and np.isfinite(scale).all()):
            refuse(path, f"scales.{key}: expected finite offset and scale of one shape, got {offset.shape} and {scale.shape}")


# ------------------------------------------------------------------ npz members


def array_headers(path: Path) -> dict[str, Header]:
    """Each npz member's (shape, dtype), read from its ``.npy`` header only; a member's data must hold what it declares."""
    headers: dict[str, Header] = {}
    try:
        with zipfile.ZipFile(path) as archive:
            members = archive.infolist()
            if len(members) > MAX_MEMBERS:
                refuse(path, f"{len(members):,} members, more than the {MAX_MEMBERS:,} a SARL npz may hold")
            for member in members:
                if not member.filename.endswith(".npy"):
                    refuse(path, f"member {member.filename[:60]!r} is not an array (.npy)")
                with archive.open(member) as file:
                    version = np.lib.format.read_magic(file)
                    read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
                    shape, _, dtype = read(file)
                    offset = file.tell()
                if dtype.hasobject:
                    refuse(path, f"{member.filename}: holds Python objects, which crowdnav never writes")
                declared = math.prod(shape) * dtype.itemsize
                if declared > member.file_size - offset:
                    refuse(path, f"{member.filename}: declares {declared:,} bytes of {shape} {dtype}, its data holds "
                                 f"{max(member.file_size - offset, 0):,}")
                headers[member.filename.removesuffix(".npy")] = (tuple(int(n) for n in shape), dtype)
    except (OSError, zipfile.BadZipFile, ValueError, EOFError) as error:
        if isinstance(error, SarlFileError):
            raise
        refuse(path, f"not an npz crowdnav wrote ({str(error).splitlines()[0][:120] if str(error) else type(error).__name__})")
    return headers


def expect(path: Path, headers: Mapping[str, Header], name: str, shape: Sequence[int], kinds: str = "f") -> None:
    """SarlFileError unless member ``name`` is there, of ``shape`` and a dtype of one of ``kinds`` (numpy kind codes)."""
    if name not in headers:
        refuse(path, f"{name}: missing")
    actual, dtype = headers[name]
    if actual != tuple(shape) or dtype.kind not in kinds:
        refuse(path, f"{name}: expected shape {tuple(shape)} ({KINDS.get(kinds, kinds)}), holds {actual} {dtype}")


def only(path: Path, headers: Mapping[str, Header], names: Sequence[str]) -> None:
    """SarlFileError for a member not among ``names`` (nothing crowdnav does not write is read or kept)."""
    extra = sorted(set(headers) - set(names))
    if extra:
        refuse(path, f"member {extra[0][:60]!r} is not one crowdnav writes")


def finite(path: Path, name: str, array: np.ndarray) -> np.ndarray:
    """``array`` if all its values are finite (NaN or infinite weights would act and learn silently wrong)."""
    if array.dtype.kind == "f" and not np.isfinite(array).all():
        refuse(path, f"{name}: holds NaN or infinite values")
    return array


def load_weights(path: Path, network: torch.nn.Module, target: torch.nn.Module) -> dict[int, dict[str, torch.Tensor]]:
    """``weights.npz`` into ``network`` and ``target`` (the agent's, built from its checked options); Adam's state per parameter
    returned. Every member's header is checked against the built networks before any array is read; loaded ones must be finite."""
    headers = array_headers(path)
    expected = {f"{prefix}.{key}": tuple(value.shape) for prefix, module in (("network", network), ("target", target))
                for key, value in module.state_dict().items()}
    shapes = [tuple(parameter.shape) for parameter in network.parameters()]
    moments = {f"adam.{index}.{name}": shape if name != "step" else () for index, shape in enumerate(shapes)
               for name in ("step", "exp_avg", "exp_avg_sq")}
    only(path, headers, [*expected, *moments])
    for name, shape in expected.items():
        expect(path, headers, name, shape)
    for name in headers.keys() & moments.keys():
        expect(path, headers, name, moments[name], "f" if name.endswith("avg") or name.endswith("avg_sq") else "fiu")
    if len({key.split(".")[1] for key in headers.keys() & moments.keys()}) * 3 != len(headers.keys() & moments.keys()):
        refuse(path, "adam: expected step, exp_avg and exp_avg_sq of every parameter Adam has updated")
    adam: dict[int, dict[str, torch.Tensor]] = {}
    with np.load(path, allow_pickle=False) as arrays:
        for prefix, module in (("network.", network), ("target.", target)):
            module.load_state_dict({key[len(prefix):]: torch.from_numpy(finite(path, key, arrays[key]).copy())
                                     for key in expected if key.startswith(prefix)})
        for key in sorted(headers.keys() & moments.keys()):
            _, index, name = key.split(".", 2)
            adam.setdefault(int(index), {})[name] = torch.from_numpy(finite(path, key, arrays[key]).copy())
    return adam
