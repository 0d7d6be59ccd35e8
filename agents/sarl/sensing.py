"""What a trained SARL agent reads must be what it was trained to read: the tracker's rows, the room's slots, the geodesic grid.

The attention pools are indifferent to how many humans or static shapes they read (a run trained on raw
observations plays any number), but an observation normalisation (the run's, and the agent's inverse of it) holds
one scale per row and per grid point, and the geodesic
grid's spacing is a constant of its lookahead (:attr:`~crowdnav.agents.sarl.lookahead.Physics.geodesic_spacing`). So a
world whose sensors differ (``--set sensors.humans.count=...`` at evaluation) is refused in one line naming the
setting and both values (:class:`SensorMismatchError`), not played with rows misread or a broadcast error.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from crowdnav.agents.sarl.lookahead import GEODESIC_KEY, STATIC_KEY

from crowdnav.errors import CrowdNavError

SETTINGS = {"humans": ("sensors.humans.count", "tracked humans"), STATIC_KEY: ("sensors.obstacles.count", "static shapes"),
            GEODESIC_KEY: ("sensors.geodesic.size", "grid points a side")}
"""Observation key -> (the sensor setting that sizes it, what its rows count)."""


class SensorMismatchError(CrowdNavError, ValueError):
    """A world whose sensors differ from those a SARL agent was trained with; one line naming the setting and both values."""


def trained_rows(agent: Any) -> dict[str, int]:
    """Observation key -> the rows the agent's normalisation holds scales for (a key it reads raw takes any number)."""
    return {key: int(scale.shape[0]) for key, (_, scale) in agent.scales.items() if key in SETTINGS and scale.ndim >= 2}


def check_shapes(agent: Any, shapes: Mapping[str, tuple[int, ...]], batched: bool) -> None:
    """SensorMismatchError where an observation key (``shapes``: per key, with a leading batch axis if ``batched``) has
    other rows than the agent was trained on."""
    for key, trained in trained_rows(agent).items():
        if key in shapes and len(shapes[key]) > int(batched) and shapes[key][int(batched)] != trained:
            setting, what = SETTINGS[key]
            raise SensorMismatchError(f"{setting}: this SARL agent was trained with {trained} {what}, the world gives "
                                      f"{shapes[key][int(batched)]}; evaluate it with {setting}={trained}")


def check_world(agent: Any, observation_space: Any, scenario: Any) -> None:
    """SensorMismatchError where the world (its observation space and scenario) senses otherwise than the agent was trained to."""
    check_shapes(agent, {key: tuple(space.shape) for key, space in observation_space.spaces.items()}, batched=False)
    if agent.geodesic:
        spacing = float(scenario.sensors.geodesic.spacing)
        if not np.isclose(spacing, agent.physics.geodesic_spacing, rtol=0.0, atol=1e-12):
            raise SensorMismatchError(f"sensors.geodesic.spacing: this SARL agent was trained with {agent.physics.geodesic_spacing} m, "
                                      f"the world gives {spacing} m; evaluate it with sensors.geodesic.spacing={agent.physics.geodesic_spacing}")
