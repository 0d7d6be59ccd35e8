"""The robot frame and the polar / cartesian encoding of one vector.

Robot frame: x along ``robot_heading``, y to the robot's left. A world vector ``w`` (complex)
becomes ``w * to_robot_frame(sim)``. Bearings are measured from the robot's x axis,
counter-clockwise positive.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Literal

import numpy as np
from gymnasium import spaces

if TYPE_CHECKING:
    from crowdnav.simulator import Simulator

Frame = Literal["polar", "cartesian"]


def to_robot_frame(sim: Simulator) -> complex:
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
