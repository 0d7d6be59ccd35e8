"""A scenario's world: the scenario loaded once and its geometry compiled once.

:func:`load_world` is the one place a scenario source (library name, YAML file, mapping or
:class:`Scenario`) becomes what the simulator and the environments run on: the loader
validates the file (:mod:`crowdnav.scenario.loader`, no geometry), then the static obstacles
(:mod:`crowdnav.worlds.obstacles`) and the placement candidates (:mod:`crowdnav.worlds.placement`) are
built, which checks the geometry. A geometry problem is a ScenarioError naming the file and
line like any other.

"World" names three things in crowdnav, kept apart by their type: the scenario file's ``world:``
section (its bounds, :class:`crowdnav.scenario.fields.World`), the compiled scenario here
(:class:`CompiledWorld`, what a sensor is built with: a public name) and one of the K
simulations a batch steps together (an ``int`` index in :mod:`crowdnav.batch` and the vector env).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from crowdnav.scenario.errors import ScenarioIssue
from crowdnav.scenario.loader import LoadedScenario, Overrides, read_scenario
from crowdnav.scenario.schema import Scenario
from crowdnav.worlds.obstacles import GeometryError, StaticObstacles, build_obstacles
from crowdnav.worlds.placement import Placement, build_placement

WorldSource = Scenario | str | Path | Mapping[str, Any]
"""A library name (``"room_furniture"``), a YAML path, a parsed mapping or a :class:`Scenario`."""


@dataclass
class CompiledWorld:
    """A scenario with its geometry compiled: what the simulator needs at reset and step time."""

    scenario: Scenario
    obstacles: StaticObstacles
    placement: Placement
    source: LoadedScenario | None = None
    """Where the scenario came from, so later checks (modality names) report file and line."""


def compile_world(scenario: Scenario) -> CompiledWorld:
    """Build static obstacles and placement candidates; raise GeometryError on bad geometry."""
    obstacles = build_obstacles(scenario)
    placement = build_placement(scenario, obstacles)
    return CompiledWorld(scenario=scenario, obstacles=obstacles, placement=placement)


def load_world(source: WorldSource, overrides: Overrides | None = None) -> CompiledWorld:
    """Load ``source`` with ``overrides`` and compile its world (once); every problem is a ScenarioError.

    A :class:`Scenario` without overrides is compiled as it is (it was validated when built).
    """
    loaded = read_scenario(source, overrides)
    try:
        world = compile_world(loaded.scenario)
    except GeometryError as error:
        raise loaded.error([ScenarioIssue(error.path, error.message)]) from None
    world.source = loaded
    return world
