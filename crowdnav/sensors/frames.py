"""The robot frame and the polar / cartesian encoding of one vector.

Robot frame: x along ``robot_heading``, y to the robot's left. A world vector ``w`` (complex)
becomes ``w * to_robot_frame(sim)``. Bearings are measured from the robot's x axis,
counter-clockwise positive.

The ``*_batch`` helpers do the same for K worlds at once (a :class:`~crowdnav.batch.state.BatchState`),
bit for bit: the single helpers use Python scalar complex math, which the batch reproduces with
separately rounded real operations (:mod:`crowdnav.batch.scalar_math`), not numpy complex ufuncs.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Literal

import numpy as np
from gymnasium import spaces

from crowdnav.batch.scalar_math import cmul

if TYPE_CHECKING:
    from crowdnav.batch.state import BatchState
    from crowdnav.sim.robot_view import RobotWorld

Frame = Literal["polar", "cartesian"]


def to_robot_frame(sim: RobotWorld) -> complex:
    """Unit complex number that rotates world vectors into the robot frame."""
    heading = sim.robot_heading
    return complex(math.cos(heading), -math.sin(heading))


def vector_space(frame: Frame, bound: float) -> spaces.Box:
    """Space of :func:`encode_vector`: polar ``(distance, sin, cos)`` or cartesian ``(x, y)``."""
    if frame == "polar":
        low = np.array([0.0, -1.0, -1.0], dtype=np.float32)
        high = np.array([bound, 1.0, 1.0], dtype=np.float32)
    else:
        high = np.full(2, bound, dtype=np.float32)
        low = -high
    return spaces.Box(low=low, high=high, dtype=np.float32)


def encode_vector(vector: complex, frame: Frame, bound: float) -> np.ndarray:
    """A robot-frame vector as float32, its length clipped to ``bound``.

    Polar: ``(min(|v|, bound), sin, cos)`` of the bearing; a zero vector has bearing 0, i.e.
    ``(0, 0, 1)``. Cartesian: ``(x, y)``, scaled down to length ``bound`` if longer, so the
    direction is kept. Scalar math: for 2-3 numbers it beats numpy's per-call overhead.
    """
    distance = abs(vector)
    if frame == "polar":
        if distance > 0.0:
            sin = min(1.0, max(-1.0, vector.imag / distance))
            cos = min(1.0, max(-1.0, vector.real / distance))
        else:
            sin, cos = 0.0, 1.0
        return np.array((min(distance, bound), sin, cos), dtype=np.float32)
    if distance > bound:
        vector *= bound / distance
    # the clip guards against the rescaled length rounding a hair above the bound
    x = min(bound, max(-bound, vector.real))
    y = min(bound, max(-bound, vector.imag))
    return np.array((x, y), dtype=np.float32)


def to_robot_frame_batch(state: BatchState) -> tuple[np.ndarray, np.ndarray]:
    """(K,) real and imaginary parts of :func:`to_robot_frame` for every world."""
    heading = state.robot_heading
    return np.cos(heading), -np.sin(heading)


@np.errstate(divide="ignore", invalid="ignore")  # bound / 0 is computed for short vectors, then not used
def encode_vectors(re: np.ndarray, im: np.ndarray, frame: Frame, bound: float) -> np.ndarray:
    """(K, 3) polar or (K, 2) cartesian float32: :func:`encode_vector` of each ``re + im j``, bit for bit."""
    distance = np.hypot(re, im)  # abs(complex) is libm hypot; numpy's complex abs is not
    if frame == "polar":
        positive = distance > 0.0
        sin = np.where(positive, np.minimum(1.0, np.maximum(-1.0, im / distance)), 0.0)
        cos = np.where(positive, np.minimum(1.0, np.maximum(-1.0, re / distance)), 1.0)
        return np.stack((np.minimum(distance, bound), sin, cos), axis=1).astype(np.float32)
    # vector *= bound / distance: a Python complex times a float, i.e. times complex(f, 0.0)
    shrunk_re, shrunk_im = cmul(re, im, bound / distance, 0.0)
    longer = distance > bound
    x = np.minimum(bound, np.maximum(-bound, np.where(longer, shrunk_re, re)))
    y = np.minimum(bound, np.maximum(-bound, np.where(longer, shrunk_im, im)))
    return np.stack((x, y), axis=1).astype(np.float32)
