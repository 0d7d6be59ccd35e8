"""Module paths crowdnav's core had before its packages by concept, still importable (as the modules they became).

Users, notebooks and older docs import ``crowdnav.simulator``, ``crowdnav.world``, ``crowdnav.policies``,
``crowdnav.envs.world_state`` and the like; a file that pickled one of their classes names it by that path.
:data:`MOVED` maps each old path to its module now (the flat root before :mod:`crowdnav.sim` and
:mod:`crowdnav.worlds`; the scripted policies before :mod:`crowdnav.planning.scripted`; the flat ``crowdnav/envs/``
before :mod:`crowdnav.envs.engines` and :mod:`crowdnav.envs.vector`); :func:`install` (run once by ``crowdnav``)
appends a finder to :data:`sys.meta_path` that answers an old path with the new module itself: one
module object under both names (``crowdnav.simulator.Simulator is crowdnav.sim.simulator.Simulator``),
so a class unpickled by its old path is the class. Nothing is imported until an old path is, as a module
(``import crowdnav.policies``) or as an attribute of its package (``crowdnav.policies`` after ``import crowdnav``:
:func:`old_attribute`). Code imports the new paths (tests/core/test_legacy_paths.py checks the old ones).

Not in the table: ``crowdnav.envs.vector`` was a module and is now a package; it exports that module's public names
(:mod:`crowdnav.envs.vector`), so ``crowdnav.envs.vector.CrowdNavVectorEnv`` is still the class.

:class:`LegacyPaths` serves any such table: :mod:`crowdnav.agents.legacy` installs one for the
flat layout agents/ had.
"""
from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
from collections.abc import Mapping, Sequence
from importlib.machinery import ModuleSpec
from types import ModuleType

MOVED: dict[str, str] = {
    "crowdnav.simulator": "crowdnav.sim.simulator",
    "crowdnav.sim_state": "crowdnav.sim.state",
    "crowdnav.sim_geometry": "crowdnav.sim.geometry",
    "crowdnav.contacts": "crowdnav.sim.contacts",
    "crowdnav.neighbours": "crowdnav.sim.neighbours",
    "crowdnav.crowd_grid": "crowdnav.sim.crowd_grid",
    "crowdnav.events": "crowdnav.sim.events",
    "crowdnav.groups": "crowdnav.sim.groups",
    "crowdnav.robots": "crowdnav.sim.robots",
    "crowdnav.robot_view": "crowdnav.sim.robot_view",
    "crowdnav.episode_draw": "crowdnav.sim.episode_draw",
    "crowdnav.social_force": "crowdnav.sim.forces",
    "crowdnav.orca": "crowdnav.sim.orca_solver",
    "crowdnav.world": "crowdnav.worlds.compiled",
    "crowdnav.obstacles": "crowdnav.worlds.obstacles",
    "crowdnav.placement": "crowdnav.worlds.placement",
    "crowdnav.placement_checks": "crowdnav.worlds.placement_checks",
    "crowdnav.placement_regions": "crowdnav.worlds.placement_regions",
    "crowdnav.placement_team": "crowdnav.worlds.placement_team",
    "crowdnav.policies": "crowdnav.planning.scripted",
    "crowdnav.envs.engine": "crowdnav.envs.engines.protocol",
    "crowdnav.envs.vector_stacked": "crowdnav.envs.engines.stacked",
    "crowdnav.envs.vector_stacked_team": "crowdnav.envs.engines.stacked_team",
    "crowdnav.envs.vector_stacked_robots": "crowdnav.envs.engines.stacked_robots",
    "crowdnav.envs.vector_team": "crowdnav.envs.engines.per_world",
    "crowdnav.envs.robots_engine": "crowdnav.envs.engines.robots",
    "crowdnav.envs.robots_state": "crowdnav.envs.engines.robots_state",
    "crowdnav.envs.world_state": "crowdnav.envs.engines.world_state",
    "crowdnav.envs.world_state_codec": "crowdnav.envs.engines.world_state_codec",
    "crowdnav.envs.vector_actions": "crowdnav.envs.vector.actions",
    "crowdnav.envs.vector_infos": "crowdnav.envs.vector.infos",
}
"""Old module path -> the module it is now."""


class LegacyPaths(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds the old paths of its table (only those) and loads each as its new module."""

    def __init__(self, moved: Mapping[str, str]) -> None:
        self.moved = moved

    def find_spec(self, fullname: str, path: Sequence[str] | None = None, target: ModuleType | None = None) -> ModuleSpec | None:
        return importlib.util.spec_from_loader(fullname, self) if fullname in self.moved else None

    def create_module(self, spec: ModuleSpec) -> ModuleType:
        return importlib.import_module(self.moved[spec.name])  # its attributes (__name__, __spec__) stay the new module's

    def exec_module(self, module: ModuleType) -> None:
        """Nothing: the new module ran when it was imported."""


def install(moved: Mapping[str, str] = MOVED) -> None:
    """Put a finder for ``moved`` on :data:`sys.meta_path` once, after the others (it never hides a module that exists)."""
    if not any(isinstance(finder, LegacyPaths) and finder.moved is moved for finder in sys.meta_path):
        sys.meta_path.append(LegacyPaths(moved))


def old_attribute(package: str, name: str, moved: Mapping[str, str] = MOVED) -> ModuleType:
    """``package.name`` where that is an old path of ``moved`` (imported now), for the package's PEP 562 ``__getattr__``.

    Before a move, importing the package often imported such a module too (``crowdnav.envs.single`` imported
    ``crowdnav.policies``), so ``import crowdnav`` then ``crowdnav.policies.StraightToGoal`` worked; so it still does.
    """
    if f"{package}.{name}" not in moved:
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    return importlib.import_module(f"{package}.{name}")
