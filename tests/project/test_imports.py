"""What importing a layer loads: the core and the command line stay free of torch, pygame, pandas and matplotlib.

Each check runs in a fresh interpreter, since this test process has imported everything already.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.paths import REPO

HEAVY = ("torch", "pygame", "pandas", "matplotlib")
ROOT = REPO


def loaded_modules(code: str) -> set[str]:
    """Top-level names of the modules ``code`` imported (``python -X importtime``)."""
    result = subprocess.run([sys.executable, "-X", "importtime", "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert result.returncode == 0, result.stderr[-2000:]
    names = set()
    for line in result.stderr.splitlines():
        if line.startswith("import time:") and line.count("|") == 2:
            names.add(line.rsplit("|", 1)[1].strip().split(".")[0])
    return names


def test_importing_crowdnav_its_envs_and_the_cli_loads_no_torch_pygame_pandas_or_matplotlib():
    code = ("import crowdnav, crowdnav.envs, crowdnav.cli, sys\n"
            f"heavy = [name for name in {HEAVY!r} if name in sys.modules]\n"
            "assert not heavy, heavy\n")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT, timeout=120)


@pytest.mark.parametrize("argv", [["--help"], ["train", "--help"], ["render", "--help"], ["benchmark", "--help"]])
def test_crowdnav_help_loads_no_torch_pygame_pandas_or_matplotlib(argv):
    loaded = loaded_modules(f"from crowdnav.cli import main\nraise SystemExit(main({argv!r}))")
    assert "crowdnav" in loaded
    assert not loaded & set(HEAVY)


def test_building_and_stepping_an_env_without_a_render_mode_loads_no_pygame_or_torch():
    loaded = loaded_modules("from crowdnav import CrowdNavEnv\nenv = CrowdNavEnv('room_furniture')\nenv.reset(seed=0)\nenv.step([1, 0])")
    assert not loaded & set(HEAVY)


def test_the_evaluation_protocol_and_the_seed_rules_load_no_torch():
    loaded = loaded_modules("import crowdnav.evaluation.protocol as p, crowdnav.agents.training.seeding, crowdnav.agents.runs.folder\n"
                            "p.Protocol().check_disjoint()")
    assert not loaded & set(HEAVY)
