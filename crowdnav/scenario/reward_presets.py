"""Named reward presets: the complete sets of weights a scenario's ``reward`` section starts from.

A scenario picks a preset with ``reward: {preset: NAME}`` (``default`` when the section or the
key is absent); any term it also gives overrides that preset's weight, see
:class:`crowdnav.scenario.schema.RewardWeights`. docs/agents.md#reward describes the terms,
the presets and every way to select them.

**Sign convention.** Every weight is the factor by which its term's quantity is multiplied
before it is *added* to the reward (:mod:`crowdnav.envs.reward`): a penalty has a negative
weight. Per step ``t``, with ``d_t`` the robot-goal centre distance (m) and ``F_social`` the
humans' social force on the robot:

* ``step``          = ``w_step``                          (< 0: a cost per step);
* ``goal_progress`` = ``w_goal_progress * (d_{t-1} - d_t)`` (> 0: pays progress, charges retreat);
* ``social``        = ``w_social * |F_social|``           (< 0: a cost of being close to people);
* ``goal_reached``  = ``w_goal_reached`` on the success step, ``collision`` = ``w_collision`` on the
  collision step.

How the ``paper`` preset maps onto the OpenSocInt paper (Section "Reward functions"): the paper
writes ``r_int = r_step + r_goal-d + r_social`` and ``r_end = w_goal-r * [goal] + w_coll *
[collision]`` with ``w_goal-r = 500``, ``w_coll = -500``, ``w_step = -5``, ``w_goal-d = 10``,
``w_social = -100``. ``goal_reached`` and ``collision`` are ``r_end``'s two parts, weights as
printed. ``r_social`` is the social repulsion force times ``w_social``: ``social`` with -100.
``r_goal-d`` is the goal-direction term times ``w_goal-d``; crowdnav pays it as the per-step
decrease of the goal distance, as the paper's draft formula ``w_goal-d * [d(t-1) - d(t)]``
(a comment in its LaTeX source) does: ``goal_progress`` with 10. The paper also writes
``r_step = -w_step``, which with ``w_step = -5`` would be a *bonus* of 5 per step, contradicting
its own "penalises taking unnecessary steps"; crowdnav reads it as a penalty of 5 per step:
``step`` with -5.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from crowdnav.suggest import unknown_name_message

REWARD_TERMS = ("step", "goal_progress", "social", "goal_reached", "collision")
"""Names of the reward terms, in summation order (also the keys of ``info["reward_terms"]``)."""

# The `default` preset, one weight per line; calibrated in docs/agents.md#reward. Scale: full
# speed at the goal earns ~1 per step (5 per metre x 0.2 m), the order of SAC's entropy bonus.
DEFAULT_STEP = -0.1
DEFAULT_GOAL_PROGRESS = 5.0
DEFAULT_SOCIAL = -1.0
DEFAULT_GOAL_REACHED = 25.0
DEFAULT_COLLISION = -25.0

DEFAULT_PRESET = "default"
"""The preset of a scenario whose ``reward`` section is absent or names none."""


@dataclass(frozen=True)
class RewardPreset:
    """A named, complete set of reward weights."""

    name: str
    doc: str
    """One line: what the preset is for."""
    weights: Mapping[str, float]
    """Term -> weight for every name in :data:`REWARD_TERMS`, in that order (read-only)."""


def _preset(name: str, doc: str, **weights: float) -> RewardPreset:
    if tuple(weights) != REWARD_TERMS:
        raise ValueError(f"preset {name!r} must give {', '.join(REWARD_TERMS)} in that order, got {', '.join(weights)}")
    return RewardPreset(name, doc, MappingProxyType({term: float(weight) for term, weight in weights.items()}))


REWARD_PRESETS: Mapping[str, RewardPreset] = MappingProxyType({preset.name: preset for preset in (
    _preset(
        "default", "crowdnav's default: the paper's five terms at a scale SAC learns from (about 1 per step), with a real social cost.",
        step=DEFAULT_STEP, goal_progress=DEFAULT_GOAL_PROGRESS, social=DEFAULT_SOCIAL,
        goal_reached=DEFAULT_GOAL_REACHED, collision=DEFAULT_COLLISION,
    ),
    _preset(
        "paper", "The OpenSocInt paper's weights: +500 goal, -500 collision, -5 per step, 10 per metre of progress, -100 x |F_social|.",
        step=-5.0, goal_progress=10.0, social=-100.0, goal_reached=500.0, collision=-500.0,
    ),
)})
"""Every preset by name; :data:`DEFAULT_PRESET` first."""


def unknown_preset_message(name: object) -> str:
    """E.g. ``unknown reward preset 'papr'; did you mean 'paper'? expected one of: default, paper``."""
    return _unknown("reward preset", name, tuple(REWARD_PRESETS))


def unknown_term_message(name: object) -> str:
    """E.g. ``unknown reward term 'socal'; did you mean 'social'? expected one of: step, goal_progress, ...``."""
    return _unknown("reward term", name, REWARD_TERMS)


def _unknown(what: str, name: object, valid: tuple[str, ...]) -> str:
    return unknown_name_message(what, name, valid)  # the one wording of unknown names
