"""The modality interface, its registry, and the factory the environments call.

A modality turns the simulator's state into one observation array in the robot's frame. It is
built once per environment from the compiled (static) world and its settings, so everything
that never moves is precomputed in ``__init__``; ``observe`` then reads the simulator's state
and the geometry the simulator caches after every reset/step.

Adding a modality is one class with a ``key``, ``make_space`` and ``observe``, decorated with
:func:`register_modality` (see docs/sensors.md); ``observe_batch`` (K worlds at once, for the
native vector environment) is optional. Each modality also declares the typical range
of its entries (:meth:`Modality.scale`, by default derived from the Box), which the agents use
to feed their networks O(1) numbers (:meth:`Modality.normalize`).
"""

from __future__ import annotations

import abc
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

import numpy as np
from gymnasium import spaces
from pydantic import BaseModel

if TYPE_CHECKING:  # imported for type hints only: the sensors never build a simulator
    from crowdnav.batch.state import BatchState
    from crowdnav.scenario.schema import Sensors
    from crowdnav.sim.robot_view import RobotWorld
    from crowdnav.worlds.compiled import CompiledWorld


class Modality(abc.ABC):
    """One observation key of the robot: a fixed gymnasium Box and a way to fill it."""

    key: ClassVar[str]
    """Observation key, e.g. ``lidar``; unique in :data:`MODALITIES`."""
    sees_robots: ClassVar[bool] = True
    """With several robots (``robots:``): whether the other robots appear in it (as discs among the humans)."""
    reads_tracker: ClassVar[bool] = False
    """It reads the people as the robot's tracker reports them (``sensors.tracker``): the env gives it the tracked world
    (:mod:`crowdnav.sensors.tracked`) instead of the simulator's true people, the same tracks for every such modality."""
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
        self._normalization: tuple[np.ndarray, np.ndarray] | None = None

    def space(self) -> spaces.Box:
        """The observation space (built once: the same object on every call)."""
        if self._space is None:
            self._space = self.make_space()
        return self._space

    @abc.abstractmethod
    def make_space(self) -> spaces.Box:
        """Build the observation space; called once by :meth:`space`."""

    @abc.abstractmethod
    def observe(self, sim: RobotWorld) -> np.ndarray:
        """A new array in :meth:`space` describing the world around the robot now.

        ``sim``: what the robot's sensors read (:class:`crowdnav.sim.robot_view.RobotWorld`): the
        simulator itself for one robot, a :class:`crowdnav.sim.robot_view.RobotView` for each robot of a ``robots:`` scenario.
        """

    def observe_batch(self, state: BatchState) -> np.ndarray:
        """(K, *space.shape) array of the space's dtype: row k is :meth:`observe` of world k, bit for bit.

        Used by the native vector environment, which steps K worlds as arrays and never builds
        one simulator per world. The built-in modalities implement it; this default raises.
        """
        raise NotImplementedError(
            f"modality {self.key!r} ({type(self).__name__}) has no batched observation: implement "
            "observe_batch(state) (see docs/sensors.md, 'Batched observation (vector env)'), or use "
            'gymnasium.make_vec(..., vectorization_mode="sync"), which calls observe() once per world'
        )

    def scale(self) -> tuple[np.ndarray, np.ndarray]:
        """``(offset, scale)``: float32 arrays of the observation's shape, in the observation's own units.

        They declare the typical range of each entry: ``(observation - offset) / scale`` is O(1),
        mostly within [-1, 1], over the values that actually occur (:meth:`normalize`). The
        default, for a modality that does not override it, comes from the Box: offset 0 and
        scale ``max(|low|, |high|)`` per entry (1 where that is infinite or 0), so zero stays
        zero, signs are kept and the normalised Box lies within [-1, 1]. Override it when the Box
        is a clip bound well above the values that occur (``goal``: distances are clipped at two
        world diagonals but scaled by one). The scale must be positive and finite.
        """
        space = self.space()
        magnitude = np.maximum(np.abs(space.low.astype(np.float64)), np.abs(space.high.astype(np.float64)))
        scale = np.where(np.isfinite(magnitude) & (magnitude > 0.0), magnitude, 1.0)
        return np.zeros(space.shape, dtype=np.float32), scale.astype(np.float32)

    def normalization(self) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`scale`, checked (shape of the observation, finite offset, positive finite scale) and cached."""
        if self._normalization is None:
            offset, scale = self.scale()
            self._normalization = checked_scale(self.key, self.space(), offset, scale)
        return self._normalization

    def normalized_space(self) -> spaces.Box:
        """The Box of :meth:`normalize`'s values: the space's bounds mapped through ``(x - offset) / scale``."""
        return normalized_box(self.space(), *self.normalization())

    def normalize(self, observation: np.ndarray) -> np.ndarray:
        """``(observation - offset) / scale`` as float32 (a batch with leading axes works too)."""
        return normalize_values(observation, *self.normalization())

    def __repr__(self) -> str:
        return f"{type(self).__name__}(key={self.key!r}, settings={self.settings!r})"


def checked_scale(key: str, space: spaces.Box, offset: Any, scale: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(offset, scale)`` as float32 arrays of ``space``'s shape (scalars broadcast); ValueError naming ``key`` otherwise."""
    try:
        offset = np.broadcast_to(np.asarray(offset, dtype=np.float32), space.shape).copy()
        scale = np.broadcast_to(np.asarray(scale, dtype=np.float32), space.shape).copy()
    except ValueError:
        raise ValueError(
            f"modality {key!r}: offset and scale must have the observation's shape {space.shape}, "
            f"got {np.shape(offset)} and {np.shape(scale)}"
        ) from None
    if not np.all(np.isfinite(offset)) or not np.all(np.isfinite(scale) & (scale > 0.0)):
        raise ValueError(f"modality {key!r}: offsets must be finite and scales positive and finite")
    return offset, scale


def normalize_values(values: np.ndarray, offset: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """``(values - offset) / scale`` in float32; ``values`` may carry leading batch axes."""
    scaled: np.ndarray = (np.asarray(values, dtype=np.float32) - offset) / scale
    return scaled


def normalized_box(space: spaces.Box, offset: np.ndarray, scale: np.ndarray) -> spaces.Box:
    """Float32 Box of ``space``'s bounds mapped like :func:`normalize_values` (so it contains every mapped observation)."""
    low, high = normalize_values(space.low, offset, scale), normalize_values(space.high, offset, scale)
    return spaces.Box(low=low, high=high, dtype=np.float32)


class RadiiConstants:
    """Per-primitive constants a sensor derives from the agents' radii, built once per radii vector.

    The radii depend only on the crowd size, so one entry per size a scenario allows; the single
    path (``sim.radii``) and the batched path (``state.radii``) share the entries.
    """

    def __init__(self, build: Callable[[np.ndarray], Any], limit: int = 64):
        self._build, self._limit = build, limit
        self._cache: dict[bytes, Any] = {}

    def __call__(self, radii: np.ndarray) -> Any:
        key = radii.tobytes()
        value = self._cache.get(key)
        if value is None:
            if len(self._cache) >= self._limit:  # bounded: radii edited by hand never pile up
                self._cache.clear()
            value = self._cache[key] = self._build(radii)
        return value


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
        import difflib

        close = difflib.get_close_matches(unknown[0], list(MODALITIES), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ValueError(f"unknown modality key(s): {', '.join(map(repr, unknown))}{hint}; available: {available}")
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise ValueError(f"duplicate modality key(s): {', '.join(map(repr, duplicates))}")
    return {name: MODALITIES[name](world, getattr(sensors, name, None)) for name in names}
