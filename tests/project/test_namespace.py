"""crowdnav lives under one import name: a user's own agents/, evaluation/ or scenarios/ folder changes nothing."""

from __future__ import annotations

import subprocess
import sys


def test_crowdnav_run_from_a_folder_holding_agents_evaluation_and_scenarios_folders_is_unaffected(tmp_path):
    for name in ("agents", "evaluation", "scenarios"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "__init__.py").write_text("raise ImportError('the user folder was imported')\n")
        (tmp_path / name / "mine.yaml").write_text("not: a scenario\n")
    code = ("import gymnasium as gym, crowdnav\n"
            "from crowdnav.scenario.library import library_names\n"
            "from crowdnav.evaluation.experiment import shipped_experiments\n"
            "import crowdnav.agents\n"
            "ids = [k for k in gym.registry if k.startswith('crowdnav/') and k != 'crowdnav/Scenario-v0']\n"
            "assert len(ids) == len(library_names()) >= 9 and 'mine' not in library_names(), ids\n"
            "assert 'default' in shipped_experiments()\n"
            "print(len(ids))\n")
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert int(done.stdout) >= 9


def test_no_generic_top_level_names_are_importable_from_outside_the_repository(tmp_path):
    code = "import importlib.util as u; print([n for n in ('agents', 'evaluation', 'scenarios') if u.find_spec(n)])"
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"
