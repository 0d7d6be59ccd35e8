"""Named crowd presets: the humans' speeds and social-force parameters a scenario's ``humans`` section starts from.

A scenario picks one with ``humans.preset`` (``paper`` when absent); any ``humans.preferred_speed``
or ``humans.social_force`` field it also gives overrides the preset's value, as reward terms
override a reward preset (:mod:`crowdnav.scenario.reward_presets`). docs/simulator.md#crowd-presets
gives the values, their sources and how each maps onto crowdnav's formulas.

* ``paper``: the OpenSocInt paper's humans, the schema's defaults (every library scenario and track).
* ``calibrated``: people as measured. Preferred speeds normal with mean 1.34 m/s and standard
  deviation 0.26 m/s (Weidmann 1993, as used by Helbing & Molnár 1995, Phys. Rev. E 51: 4282),
  clipped to mean +- 2 sd; the speed cap 1.3 times the preferred speed (Helbing & Molnár 1995);
  relaxation time 0.54 s (Moussaïd, Helbing, Garnier, Johansson, Combe & Theraulaz 2009, Proc. R.
  Soc. B 276: 2755); human repulsion from the circular specification fitted to video tracks
  (Johansson, Helbing & Shukla 2007, Adv. Complex Syst. 10: 271): ``A = 0.42 m/s^2``, ``B = 1.65 m``;
  walls from Helbing & Molnár 1995 (``U0 = 10 m^2/s^2``, ``R = 0.2 m``). Checked for issue 52 against
  secondary write-ups that quote the papers (the papers' own text was not reachable): every value agrees;
  docs/simulator.md#crowd-presets says which source gives which and what stays unconfirmed.

Mapping (approximate where said). crowdnav's repulsions are dimensionless parts of the desired
direction: the acceleration they give is ``v* F / tau``. A published acceleration ``a`` (m/s^2)
therefore maps to ``a * tau / v*``, taken at the mean preferred speed 1.34 m/s (approximate: a
slower walker is pushed less, a faster one more). The fitted anisotropy (``lambda = 0.12``: people
behind weigh 0.12) has no counterpart: crowdnav's repulsion is isotropic, at the weight of a
person straight ahead (1), so people behind push more than in the fit. Helbing & Molnár's wall
force ``(U0 / R) exp(-d / R)``, ``d`` from the centre, is ``A_o exp((r - d) / B_o)`` with
``A_o = (U0 / R) exp(-r / R)`` at radius ``r = 0.3 m``. The goal force's saturation distance and
tolerance have no published counterpart and keep crowdnav's values.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from crowdnav.suggest import unknown_name_message

DEFAULT_CROWD_PRESET = "paper"
"""The preset of a scenario whose ``humans.preset`` is absent: the schema's own defaults."""

SPEED_MEAN, SPEED_SD = 1.34, 0.26
"""Free walking speed (m/s): Weidmann (1993), the preferred speeds of Helbing & Molnár (1995)."""
RELAXATION_TIME = 0.54
"""Seconds (Moussaïd et al. 2009: 0.54 +- 0.05 s, estimated from their participants' starts, with desired speeds 1.29 m/s)."""
_HUMAN_A, _HUMAN_B = 0.42, 1.65
"""Circular specification fitted by Johansson, Helbing & Shukla (2007): m/s^2 and m (+- 0.26 and 1.01; lambda 0.12 unused)."""
_WALL_U0, _WALL_R, _BODY_RADIUS = 10.0, 0.2, 0.3
"""Helbing & Molnár (1995)'s wall potential (m^2/s^2, m), and the body radius its force is written at (m)."""


def _dimensionless(acceleration: float) -> float:
    """A published repulsion (m/s^2) as crowdnav's dimensionless strength: ``a * tau / v*`` at the mean speed, 3 decimals."""
    return round(acceleration * RELAXATION_TIME / SPEED_MEAN, 3)


@dataclass(frozen=True)
class CrowdPreset:
    """A named set of crowd values: what the fields a scenario does not give take."""

    name: str
    doc: str
    """One line: what the preset is for."""
    preferred_speed: tuple[float, float] | None
    """``humans.preferred_speed`` (None: the schema's default)."""
    speed_normal: tuple[float, float] | None
    """(mean, sd) m/s: walkers taking the preset's range draw from this normal, clipped to it (None: uniform in the range)."""
    social_force: Mapping[str, float]
    """``humans.social_force`` field -> value (read-only; the others keep the schema's defaults)."""


_HUMAN_STRENGTH = _dimensionless(_HUMAN_A)
CROWD_PRESETS: Mapping[str, CrowdPreset] = MappingProxyType({preset.name: preset for preset in (
    CrowdPreset("paper", "The OpenSocInt paper's humans: the schema's defaults (every library scenario and track).", None, None,
                MappingProxyType({})),
    CrowdPreset(
        "calibrated", "People as measured: normal preferred speeds (1.34 +- 0.26 m/s) and social-force parameters fitted to pedestrians.",
        (round(SPEED_MEAN - 2 * SPEED_SD, 2), round(SPEED_MEAN + 2 * SPEED_SD, 2)), (SPEED_MEAN, SPEED_SD),
        MappingProxyType({
            "relaxation_time": RELAXATION_TIME,
            "max_speed_factor": 1.3,
            "human_strength": _HUMAN_STRENGTH,
            "human_range": _HUMAN_B,
            "robot_strength": _HUMAN_STRENGTH,  # the robot as one more person, when humans see it
            "robot_range": _HUMAN_B,
            "obstacle_strength": _dimensionless(_WALL_U0 / _WALL_R * math.exp(-_BODY_RADIUS / _WALL_R)),
            "obstacle_range": _WALL_R,
        }),
    ),
)})
"""Every crowd preset by name; :data:`DEFAULT_CROWD_PRESET` first."""


def unknown_crowd_preset_message(name: object) -> str:
    """E.g. ``unknown crowd preset 'calibratd'; did you mean 'calibrated'? expected one of: paper, calibrated``."""
    return unknown_name_message("crowd preset", name, tuple(CROWD_PRESETS))
