"""The native vector env's action pipeline: the actions checked, the plan added (residual), the shield.

:class:`crowdnav.envs.vector.env.CrowdNavVectorEnv` runs every step's actions through here, and so does
its ``restore_worlds`` when it replays the actions since an episode's reset (a training resume): the
worlds then execute exactly the actions they executed when the episodes were played.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from crowdnav.envs.core import real_array
from crowdnav.envs.engines.protocol import WorldEngine
from crowdnav.planning.shield import Shield

SMALL_BATCH = 8
"""Up to this many worlds, :func:`checked_actions` checks the actions as Python floats."""


def checked_actions(actions: Any, num_envs: int) -> np.ndarray:
    """``actions`` as a (num_envs, 2) float array; a one-line ValueError for another shape or a non-finite row."""
    values = real_array(actions, "the robot actions")
    if values.shape != (num_envs, 2):
        raise ValueError(f"the robot actions must have shape ({num_envs}, 2), got shape {values.shape}")
    # a few worlds (one: the common case) are checked as Python floats, cheaper than two numpy calls
    if not (all(map(math.isfinite, values.ravel().tolist())) if num_envs <= SMALL_BATCH else np.isfinite(values).all()):
        i = int(np.flatnonzero(~np.isfinite(values).all(1))[0])
        raise ValueError(f"the robot action of world {i} must be finite (no NaN or inf), got {values[i].tolist()}")
    return values


def executed(
    actions: np.ndarray, plan: np.ndarray | None, shield: Shield | None, engine: WorldEngine
) -> tuple[np.ndarray, np.ndarray | None]:
    """The actions the robots execute: ``plan`` (the residual env's observed plans) plus the policy's action, through the
    shield (the engine's call, as the single env's world by world bit for bit; and which worlds' actions it replaced;
    None without a shield)."""
    if plan is not None:  # each policy action corrects the plan its world observed
        actions = actions + plan
    if shield is None:
        return actions, None
    return engine.shielded(shield, actions)


def checked_replay(actions: Any, lengths: Any, num_envs: int) -> tuple[np.ndarray, np.ndarray]:
    """``restore_worlds``' (actions, lengths) as arrays: lengths (num_envs,) non-negative integers, actions
    (num_envs, >= the longest length, 2) real; a one-line ValueError otherwise."""
    b = num_envs
    lengths = np.asarray(lengths)
    actions = real_array(actions, "the restored worlds' actions")
    if lengths.shape != (b,) or lengths.dtype.kind not in "iu" or (lengths < 0).any() \
            or actions.ndim != 3 or actions.shape[0] != b or actions.shape[2] != 2 or lengths.max(initial=0) > actions.shape[1]:
        raise ValueError(f"restore_worlds: lengths must be ({b},) non-negative integers and actions ({b}, >= max length, 2), "
                         f"got lengths {lengths.dtype}{lengths.shape} and actions {actions.shape}")
    return actions, lengths
