"""The humans' social-force model, as vectorized functions over complex 2-D vectors.

Forces are dimensionless "desired-direction" vectors; the desired velocity is the total
force times the human's preferred speed. With ``d`` distances in metres:

* goal force:      ``w_goal * (g - p) / max(|g - p|, d_sat)``: unit length far from the goal,
  proportional to the distance within ``d_sat`` (so humans slow down as they arrive);
* neighbour force: ``sum_j A_j * exp((r_i + r_j - d_ij) / B_j) * (p_i - p_j) / d_ij``
  (humans, and the robot only when ``see_robot`` is on);
* obstacle force:  ``sum_k A_o * exp((r_i - d_ik) / B_o) * (p_i - q_ik) / d_ik`` with ``q_ik``
  the nearest point of static obstacle ``k``;
* velocity command: ``v + (v_pref * F - v) * min(1, dt / tau)``, capped at the max speed;
* group terms (members of groups with ``walk_together``): :func:`group_force`, the gaze,
  attraction and repulsion of Moussaïd, Perozo, Garnier, Helbing and Theraulaz (2010), "The
  walking behaviour of pedestrian social groups and its impact on crowd dynamics", PLoS ONE
  5(4): e10047.

The same functions drive the simulator's built-in crowd and :class:`SocialForcePolicy`
(which reads them from observations), so there is one implementation of the model.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from crowdnav.scenario.crowd import GroupForce

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
    # the last axis: one world (N, M) or a batch (K, N, M); np.add.reduce is ndarray.sum without its Python wrapper
    force: np.ndarray = np.add.reduce(offset * magnitude, axis=-1)
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


def group_centroids(positions: np.ndarray, key: np.ndarray, bins: int) -> tuple[np.ndarray, np.ndarray]:
    """Each group's member count and centre of mass: ``key`` (m,) the group bin of each of ``positions`` (m,) complex.

    Sums run in the order of the members (:func:`numpy.bincount`), so the members of one group
    give the same bits whether one world or a batch of worlds is flattened.
    Returns ``(counts, centres)``, (bins,) each (centre 0 for an empty bin).
    """
    counts = np.bincount(key, minlength=bins)
    size = np.maximum(counts, 1)
    centres = np.bincount(key, weights=positions.real, minlength=bins) / size
    centres = centres + 1j * (np.bincount(key, weights=positions.imag, minlength=bins) / size)
    return counts, centres


def member_keys(member: np.ndarray, group: np.ndarray, groups: int) -> tuple[np.ndarray, np.ndarray, int]:
    """The flat indices of ``member`` (any leading world axes, last axis the n humans) and each one's group bin.

    A bin is ``world * groups + group`` (worlds numbered over the leading axes), so no two worlds share one.
    Returns ``(index, key, bins)``: index into the flattened humans, key (same length), number of bins.
    """
    worlds = int(np.prod(member.shape[:-1], dtype=np.int64))
    n = member.shape[-1]
    index = np.flatnonzero(member)
    key = (index // n) * groups + group.reshape(-1)[index] if n else index
    return index, key, worlds * groups


def group_force(
    positions: np.ndarray,
    velocities: np.ndarray,
    preferred_speed: np.ndarray,
    member: np.ndarray,
    group: np.ndarray,
    groups: int,
    params: GroupForce,
    relaxation_time: float,
) -> np.ndarray:
    """(..., n) complex: the group terms of Moussaïd et al. (2010) on every human, as dimensionless force (0 for non-members).

    ``positions``, ``velocities`` (..., n) complex, ``preferred_speed`` (..., n): the humans (any
    leading world axes); ``member`` (..., n) bool: who walks in a group that walks together
    (stopped humans left out); ``group`` (..., n) int: each human's group (< ``groups``);
    ``params``: a :class:`crowdnav.scenario.schema.GroupForce`. For member i of a group of N
    walking members with centre of mass c (m/s^2, as in the paper):

    * gaze:       ``-beta_1 * alpha_i * v_i``, alpha_i = max(0, angle(v_i, c - p_i) - phi) (rad):
      a member who must turn its head further than the vision field's half-angle phi to see the
      group's centre slows down (v_i: its velocity);
    * attraction: ``beta_2 * (c - p_i) / |c - p_i|`` where ``|c - p_i| > (N - 1) * spread``;
    * repulsion:  ``beta_3 * sum_k (p_i - p_k) / |p_i - p_k|`` over fellow members k closer than d_0.

    The paper adds them to dv/dt; crowdnav's velocity command relaxes toward ``v_pref * F`` over
    tau, so an acceleration a enters F as ``tau * a / v_pref`` (the paper's balance of the terms
    against the goal force is kept).
    """
    p = params
    out = np.zeros(positions.shape, dtype=complex)
    index, key, bins = member_keys(member, group, groups)
    if len(index) == 0:
        return out
    z = positions.reshape(-1)[index]
    v = velocities.reshape(-1)[index]
    counts, centres = group_centroids(z, key, bins)
    size = counts[key]
    to_centre = centres[key] - z
    distance = np.abs(to_centre)
    far = distance > (size - 1) * p.attraction_spread
    attraction = np.where(far, to_centre / np.where(far, distance, 1.0), 0.0) * p.attraction_strength
    turn = np.maximum(np.abs(np.angle(to_centre * np.conj(v))) - np.radians(p.vision_angle), 0.0)
    total = attraction - p.gaze_strength * turn * v
    # fellow-member pairs: the members of one bin are contiguous (index order), from its first one, size of them
    first = np.searchsorted(key, key, side="left")
    pair_i = np.repeat(np.arange(len(index)), size)
    pair_j = np.repeat(first - np.cumsum(size) + size, size) + np.arange(len(pair_i))
    other = pair_i != pair_j
    pair_i, pair_j = pair_i[other], pair_j[other]
    apart = z[pair_i] - z[pair_j]
    gap = np.abs(apart)
    close = (gap < p.repulsion_distance) & (gap > 0.0)
    push = np.where(close, apart / np.where(close, gap, 1.0), 0.0) * p.repulsion_strength
    total = total + (np.bincount(pair_i, weights=push.real, minlength=len(index))
                     + 1j * np.bincount(pair_i, weights=push.imag, minlength=len(index)))
    out.reshape(-1)[index] = total * (relaxation_time / preferred_speed.reshape(-1)[index])
    return out
