"""The humans' social-force model, as vectorized functions over complex 2-D vectors.

Forces are dimensionless "desired-direction" vectors; the desired velocity is the total
force times the human's preferred speed. With ``d`` distances in metres:

* goal force:      ``w_goal * (g - p) / max(|g - p|, d_sat)``: unit length far from the goal,
  proportional to the distance within ``d_sat`` (so humans slow down as they arrive);
* neighbour force: ``sum_j A_j * exp((r_i + r_j - d_ij) / B_j) * (p_i - p_j) / d_ij``
  (humans, and the robot only when ``see_robot`` is on);
* obstacle force:  ``sum_k A_o * exp((r_i - d_ik) / B_o) * (p_i - q_ik) / d_ik`` with ``q_ik``
  the nearest point of static obstacle ``k``;
* velocity command: ``v + (v_pref * F - v) * min(1, dt / tau)``, capped at the max speed.

The same functions drive the simulator's built-in crowd and :class:`SocialForcePolicy`
(which reads them from observations), so there is one implementation of the model.
"""

from __future__ import annotations

import numpy as np

MAX_EXPONENT = 700.0


def goal_force(to_goal: np.ndarray, weight: float, saturation_distance: float) -> np.ndarray:
    """(N,) complex: pull towards the goal, ``to_goal`` = goal minus position."""
    force: np.ndarray = to_goal * (weight / np.maximum(np.abs(to_goal), saturation_distance))
    return force


def repulsion(offset: np.ndarray, distance: np.ndarray, gain: np.ndarray, neg_inv_range: np.ndarray | float) -> np.ndarray:
    """(N,) complex: sum over columns of exponential repulsion.

    ``offset`` (N, M) complex points from each agent to what repels it (another agent's centre
    or an obstacle's nearest point) and ``distance`` (N, M) is its length (centre distance for
    agents, surface distance for obstacles). ``gain`` = ``-A * exp(contact / B)`` with the sign
    folded in (so no extra negation per step); masked pairs have gain 0.
    ``neg_inv_range`` = ``-1 / B``.
    """
    # exp in float32: numpy has no AVX2 kernel for float64 exp and this is the step's largest
    # array op at high density; 1e-7 relative error on a force is far below the model's fidelity.
    magnitude = gain * np.exp(np.multiply(distance, neg_inv_range, dtype=np.float32))
    magnitude /= distance
    force: np.ndarray = (offset * magnitude).sum(axis=-1)  # the last axis: one world (N, M) or a batch (K, N, M)
    return force


def repulsion_gain(strength: np.ndarray | float, contact: np.ndarray | float, decay_range: np.ndarray | float) -> np.ndarray:
    """``-A * exp(contact / B)``: the precomputable part of :func:`repulsion`.

    The exponent is capped at 700 (exp(700) ~ 1e304, below float64's overflow) so a gain is
    never inf: inf times the vanishing ``exp(-d / B)`` of a far pair would be NaN.
    """
    exponent = np.minimum(np.asarray(contact, dtype=float) / decay_range, MAX_EXPONENT)
    return -np.asarray(strength, dtype=float) * np.exp(exponent)


def velocity_command(
    force: np.ndarray,
    velocity: np.ndarray,
    preferred_speed: np.ndarray,
    max_speed: np.ndarray,
    relax: float,
) -> np.ndarray:
    """(N,) complex velocity (m/s): relax towards ``preferred_speed * force``, cap at ``max_speed``.

    ``relax`` = ``min(1, dt / relaxation_time)``.
    """
    command = velocity + (force * preferred_speed - velocity) * relax
    # max_speed / max(speed, max_speed) is 1 below the cap and never divides by zero.
    capped: np.ndarray = command * (max_speed / np.maximum(np.abs(command), max_speed))
    return capped
