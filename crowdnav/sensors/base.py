"""The modality interface, its registry, and the factory the environments call.

A modality turns the simulator's state into one observation array in the robot's frame. It is
built once per environment from the compiled (static) world and its settings, so everything
that never moves is precomputed in ``__init__``; ``observe`` then reads the simulator's state
and the geometry the simulator caches after every reset/step.

Adding a modality is one class with a ``key``, ``make_space`` and ``observe``, decorated with
:func:`register_modality` (see docs/sensors.md).
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

import numpy as np
from gymnasium import spaces
from pydantic import BaseModel

if TYPE_CHECKING:  # imported for type hints only: the sensors never build a simulator
    from crowdnav.scenario.schema import Sensors
    from crowdnav.simulator import Simulator
    from crowdnav.world import CompiledWorld


class Modality(abc.ABC):
    """One observation key of the robot: a fixed gymnasium Box and a way to fill it."""

    key: ClassVar[str]
    """Observation key, e.g. ``lidar``; unique in :data:`MODALITIES`."""
    settings_type: ClassVar[type[BaseModel] | None] = None
    """Pydantic model of the settings (``None``: the modality takes no settings)."""

    def __init__(self, world: CompiledWorld, settings: Any = None):
        if self.settings_type is not None:
            if settings is None:
                settings = self.settings_type()
            elif not isinstance(settings, self.settings_type):
                raise TypeError(
                    f"modality {self.key!r} expects settings of type {self.settings_type.__name__}, "
                    f"got {type(settings).__name__}"
                )
        self.world = world
        self.settings = settings
        self._space: spaces.Box | None = None

    def space(self) -> spaces.Box:
        """The observation space (built once: the same object on every call)."""
        if self._space is None:
            self._space = self.make_space()
        return self._space

    @abc.abstractmethod
    def make_space(self) -> spaces.Box:
        """Build the observation space; called once by :meth:`space`."""

    @abc.abstractmethod
    def observe(self, sim: Simulator) -> np.ndarray:
        """A new array in :meth:`space` describing the simulator's current state."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}(key={self.key!r}, settings={self.settings!r})"


MODALITIES: dict[str, type[Modality]] = {}
"""Registry: observation key -> modality class, filled by :func:`register_modality`."""

M = TypeVar("M", bound=type[Modality])


def register_modality(cls: M) -> M:
    """Class decorator: make ``cls`` available under ``cls.key`` in :data:`MODALITIES`."""
    if not (isinstance(cls, type) and issubclass(cls, Modality)):
        raise TypeError(f"register_modality expects a Modality subclass, got {cls!r}")
    key = getattr(cls, "key", None)
    if not isinstance(key, str) or not key.isidentifier():
        raise ValueError(f"{cls.__name__}.key must be an identifier-like string, got {key!r}")
    existing = MODALITIES.get(key)
    if existing is not None and _full_name(existing) != _full_name(cls):
        raise ValueError(f"modality key {key!r} is already registered by {_full_name(existing)}")
    MODALITIES[key] = cls  # same full name: a module reload replaces its own class
    return cls


def _full_name(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def build_modalities(names: Sequence[str], world: CompiledWorld, sensors: Sensors) -> dict[str, Modality]:
    """Instantiate the named modalities, in the order given.

    Each gets ``getattr(sensors, key, None)`` as settings. Raises ValueError on an empty list,
    duplicates, or unknown keys (naming them and listing the available ones).
    """
    if isinstance(names, str):
        raise TypeError(f"expected a sequence of modality keys, got the string {names!r}")
    names = list(names)
    available = ", ".join(sorted(MODALITIES))
    if not names:
        raise ValueError(f"expected at least one modality; available: {available}")
    unknown = [name for name in names if name not in MODALITIES]
    if unknown:
        raise ValueError(f"unknown modality key(s): {', '.join(map(repr, unknown))}; available: {available}")
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise ValueError(f"duplicate modality key(s): {', '.join(map(repr, duplicates))}")
    return {name: MODALITIES[name](world, getattr(sensors, name, None)) for name in names}
