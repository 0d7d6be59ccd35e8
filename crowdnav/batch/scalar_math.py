"""Python's scalar float and complex arithmetic, reproduced bit for bit on numpy arrays.

The single simulator and its sensors do their per-robot math on Python scalars (``complex``,
``math``), which for two or three numbers is faster than numpy. numpy's own complex multiply and
absolute value are vectorized differently and can differ in the last bit, so the batched code
writes every such operation as separately rounded real operations, in CPython's order:

* ``complex * complex``: ``(ar*br - ai*bi) + (ar*bi + ai*br)j`` (CPython's ``_Py_c_prod``; a float
  operand is first made ``complex(f, 0.0)``, as CPython 3.10-3.13 do, signed zeros included; 3.14
  multiplies a float into each part directly (C99 Annex G), which can differ in the sign of a zero);
* ``abs(complex)``: ``hypot(re, im)`` (``np.hypot`` calls the same libm function);
* ``math.remainder(x, 2 pi)``: exact, from ``np.fmod`` (exact) and one exact subtraction;
* ``math.cos`` / ``math.sin`` equal ``np.cos`` / ``np.sin`` here (tested in tests/core/test_vector_env.py).

Arrays are pairs ``(re, im)`` of float64 arrays.
"""

from __future__ import annotations

import math
from typing import TypeVar

import numpy as np

TWO_PI = 2.0 * math.pi

F = TypeVar("F", float, np.ndarray)
"""A Python float (one world) or a float array (one entry per world)."""


def cmul(ar: F, ai: F | float, br: F | float, bi: F | float) -> tuple[F, F]:
    """CPython's complex product ``(ar + ai j) * (br + bi j)`` as ``(re, im)``; arrays if ``ar`` is one."""
    return ar * br - ai * bi, ar * bi + ai * br


def remainder(x: np.ndarray | float, y: float) -> np.ndarray:
    """``math.remainder(x, y)`` for each entry (IEEE remainder: x - n y, n the nearest integer to x / y, ties to even).

    ``fmod`` is exact and leaves ``|f| < y`` with the sign of x; when ``|f| > y / 2`` one more ``y``
    is taken off, exactly (Sterbenz: y / 2 <= |f| <= y). A tie ``|f| == y / 2`` goes to the even
    quotient: the truncated quotient's parity decides (computed exactly for |x| < 2**52 y).
    """
    x = np.asarray(x, dtype=float)
    f: np.ndarray = np.fmod(x, y)
    half = 0.5 * y
    quotient_odd = np.fmod(np.trunc((x - f) / y), 2.0) != 0.0
    over = (np.abs(f) > half) | ((np.abs(f) == half) & quotient_odd)
    return np.where(over, f - np.copysign(y, f), f)
