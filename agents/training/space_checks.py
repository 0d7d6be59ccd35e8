"""Gymnasium's spaces narrowed to the kinds crowdnav builds: a Dict of Boxes for observations, a Box for actions.

Gymnasium types an environment's spaces as the base ``Space`` (whose ``shape`` may be None);
these return the concrete space, or raise TypeError naming what came instead, so code that
reads shapes and bounds is checked against what it truly receives. Free of torch.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
from gymnasium import spaces


def dict_space(space: gym.Space[Any]) -> spaces.Dict:
    """``space`` as the Dict every crowdnav observation space is (TypeError for another kind)."""
    if not isinstance(space, spaces.Dict):
        raise TypeError(f"expected a Dict observation space, got {space}")
    return space


def box_space(space: gym.Space[Any], key: str) -> spaces.Box:
    """Observation ``key`` of a Dict space as the Box every crowdnav modality is (TypeError for another kind)."""
    entry = dict_space(space)[key]
    if not isinstance(entry, spaces.Box):
        raise TypeError(f"expected observation {key!r} to be a Box, got {entry}")
    return entry


def action_box(space: gym.Space[Any]) -> spaces.Box:
    """``space`` as the Box every crowdnav action space is (TypeError for another kind)."""
    if not isinstance(space, spaces.Box):
        raise TypeError(f"expected a Box action space, got {space}")
    return space
