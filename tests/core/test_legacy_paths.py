"""The module paths of crowdnav's flat root before sim/ and worlds/ still import, as the modules they became."""

from __future__ import annotations

import importlib
import pickle
import subprocess
import sys
from pathlib import Path

import pytest

import crowdnav
from crowdnav.legacy_paths import MOVED
from crowdnav.sim.simulator import Simulator

PACKAGE = Path(crowdnav.__file__).parent


@pytest.mark.parametrize("old", sorted(MOVED))
def test_every_old_module_path_is_the_new_module(old):
    new = importlib.import_module(MOVED[old])
    assert importlib.import_module(old) is new and sys.modules[old] is new and new.__name__ == MOVED[old]


@pytest.mark.parametrize("old", sorted(MOVED))
def test_every_old_path_is_gone_from_the_tree_and_its_new_module_is_there(old):
    """The table names moves: no file is left at an old path (it would hide the move), each new one exists."""
    assert not (PACKAGE / f"{old.removeprefix('crowdnav.')}.py").exists()
    assert (PACKAGE.parent / f"{MOVED[old].replace('.', '/')}.py").is_file()


def test_the_public_names_are_the_same_objects_under_both_paths():
    from crowdnav.social_force import goal_force
    from crowdnav.world import load_world

    from crowdnav import simulator as old_simulator  # the from-list form, through the package
    from crowdnav.sim.forces import goal_force as kernel
    from crowdnav.worlds.compiled import load_world as compiled_load_world

    assert old_simulator.Simulator is crowdnav.Simulator is Simulator
    assert goal_force is kernel and load_world is compiled_load_world


def test_an_old_path_that_never_existed_is_still_not_found():
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("crowdnav.no_such_module")


@pytest.mark.parametrize(("old", "name"), [("crowdnav.simulator", "Simulator"), ("crowdnav.events", "Collision"),
                                           ("crowdnav.world", "CompiledWorld"), ("crowdnav.obstacles", "StaticObstacles"),
                                           ("crowdnav.placement", "Placement")])
def test_a_pickle_naming_a_class_by_its_old_module_loads_the_class(old, name):
    """The bytes a pickle written before the move holds for a class: its module path (the old one) and its name."""
    assert pickle.loads(f"c{old}\n{name}\n.".encode()) is getattr(importlib.import_module(MOVED[old]), name)


def test_old_paths_import_first_thing_in_a_fresh_interpreter(tmp_path):
    """Nothing imported before: the old path itself imports crowdnav, which installs the finder."""
    code = ("import crowdnav.simulator, crowdnav.orca, crowdnav.placement_team\n"
            "from crowdnav.sim import simulator\n"
            "assert crowdnav.simulator is simulator\n"
            "print(crowdnav.simulator.__name__, crowdnav.orca.__name__, crowdnav.placement_team.__name__)\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.split() == ["crowdnav.sim.simulator", "crowdnav.sim.orca_solver", "crowdnav.worlds.placement_team"]
