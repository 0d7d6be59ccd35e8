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
from typing import Any, TypeVar

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


def cdiv_real(ar: np.ndarray, ai: np.ndarray, b: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """CPython's ``(ar + ai j) / b`` for a real ``b`` (made ``complex(b, 0.0)``: ``_Py_c_quot``'s branch for ``|b.real| >= |b.imag|``)."""
    return (ar + ai * 0.0) / b, (ai - ar * 0.0) / b


_ATAN2 = np.frompyfunc(math.atan2, 2, 1)


def phase(re: np.ndarray, im: np.ndarray) -> np.ndarray:
    """``cmath.phase(complex(re, im))`` for each entry: libm's ``atan2`` called per entry (numpy's vectorized ``arctan2``
    differs from it in the last bit)."""
    out: np.ndarray = _ATAN2(im, re).astype(float)
    return out


def robot_velocity(robot: Any, dt: float, actions: np.ndarray, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`crowdnav.sim.robots.robot_kinematics` of one robot spec in every row (``actions`` (K, 2), ``heading`` (K,)),
    its action clipped first: (velocity re, im, new heading), in CPython's scalar arithmetic."""
    a0 = np.minimum(1.0, np.maximum(-1.0, actions[:, 0]))
    a1 = np.minimum(1.0, np.maximum(-1.0, actions[:, 1]))
    if robot.kinematics == "holonomic":
        norm = np.hypot(a0, a1)
        over = norm > 1.0
        # command /= norm: CPython divides by complex(norm, 0): (re + im * 0) / norm, (im - re * 0) / norm
        divisor = np.where(over, norm, 1.0)  # only the rows over 1 are divided (a zero action has norm 0)
        cr = np.where(over, (a0 + a1 * 0.0) / divisor, a0)
        ci = np.where(over, (a1 - a0 * 0.0) / divisor, a1)
        cr, ci = cmul(cr, ci, robot.max_speed, 0.0)
        h = 0.0 + heading  # 1j * heading: its imaginary part is 0 * 0 + 1 * h
        re, im = cmul(cr, ci, np.cos(h), np.sin(h))
        return re, im, heading
    speed, turn = a0 * robot.max_speed, a1 * robot.max_angular_speed
    new_heading = heading + turn * dt
    turning = np.abs(turn) > 1e-9
    with np.errstate(divide="ignore", invalid="ignore"):
        # (speed / turn) * -1j * (exp(1j new) - exp(1j old)); -1j is complex(-0.0, -1.0)
        kr, ki = cmul(speed / turn, 0.0, -0.0, -1.0)
        h_new, h_old = 0.0 + new_heading, 0.0 + heading
        arc_re, arc_im = cmul(kr, ki, np.cos(h_new) - np.cos(h_old), np.sin(h_new) - np.sin(h_old))
    line_re, line_im = cmul(speed * dt, 0.0, np.cos(0.0 + heading), np.sin(0.0 + heading))
    dr, di = np.where(turning, arc_re, line_re), np.where(turning, arc_im, line_im)
    # displacement / dt: CPython divides by complex(dt, 0)
    return (dr + di * 0.0) / dt, (di - dr * 0.0) / dt, remainder(new_heading, TWO_PI)
