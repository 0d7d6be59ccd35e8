"""The module paths crowdnav's core had before its packages by concept (sim/, worlds/, planning/scripted.py, envs/engines/,
envs/vector/) still import, as the modules they became."""

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
    assert not (PACKAGE.parent / f"{old.replace('.', '/')}.py").exists()
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
                                           ("crowdnav.placement", "Placement"), ("crowdnav.policies", "StraightToGoal"),
                                           ("crowdnav.envs.world_state", "VectorWorldState"),
                                           ("crowdnav.envs.vector_stacked", "StackedWorlds")])
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


def test_the_vector_env_module_is_now_its_package_which_exports_its_public_names():
    """``crowdnav.envs.vector`` was a module and is a package: not in the table, its public names are still the objects."""
    import crowdnav.envs.vector as package
    from crowdnav.envs.vector import env

    assert "crowdnav.envs.vector" not in MOVED and package.__name__ == "crowdnav.envs.vector"
    for name in package.__all__:
        assert getattr(package, name) is getattr(env, name) and name in dir(package)
    assert pickle.loads(b"ccrowdnav.envs.vector\nCrowdNavVectorEnv\n.") is env.CrowdNavVectorEnv
    with pytest.raises(AttributeError, match="module 'crowdnav.envs.vector' has no attribute 'no_such_name'"):
        package.no_such_name  # noqa: B018


def test_an_old_path_is_an_attribute_of_its_package_as_before_the_move_and_other_names_are_not():
    """``import crowdnav`` used to import ``crowdnav.policies`` (the single env did), so docs and notebooks read it as an
    attribute; the old flat paths of envs/ likewise."""
    import crowdnav.envs
    from crowdnav.envs.engines import world_state
    from crowdnav.planning import scripted

    assert crowdnav.policies is scripted and crowdnav.envs.world_state is world_state
    from crowdnav.envs import vector_stacked_team  # the from-list form through the package's attribute
    assert vector_stacked_team is importlib.import_module("crowdnav.envs.engines.stacked_team")
    with pytest.raises(AttributeError, match="module 'crowdnav' has no attribute 'no_such_module'"):
        crowdnav.no_such_module  # noqa: B018
    with pytest.raises(AttributeError, match="module 'crowdnav.envs' has no attribute 'no_such_module'"):
        crowdnav.envs.no_such_module  # noqa: B018


def test_old_paths_of_the_envs_and_the_policies_import_first_thing_in_a_fresh_interpreter(tmp_path):
    code = ("import sys, crowdnav\n"
            "assert 'crowdnav.policies' not in sys.modules and crowdnav.policies.StraightToGoal.__module__ == 'crowdnav.planning.scripted'\n"
            "assert crowdnav.envs.world_state is sys.modules['crowdnav.envs.engines.world_state']  # attributes, as before the move\n"
            "import crowdnav.envs.vector_stacked_robots, crowdnav.envs.world_state_codec, crowdnav.policies\n"
            "from crowdnav.envs.engines import stacked_robots\n"
            "assert crowdnav.envs.vector_stacked_robots is stacked_robots\n"
            "print(crowdnav.envs.vector_stacked_robots.__name__, crowdnav.envs.world_state_codec.__name__, crowdnav.policies.__name__)\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.split() == ["crowdnav.envs.engines.stacked_robots", "crowdnav.envs.engines.world_state_codec",
                                     "crowdnav.planning.scripted"]
