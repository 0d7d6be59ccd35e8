"""No code from a folder crowdnav wrote: a `module:function` POLICY read from a result's meta.json is never imported
unless the command line names it again (`--import`), and a recorded working folder never joins the import path."""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from crowdnav.evaluation.storage import META_FILE, ResultsError
from crowdnav.evaluation.trajectories import replay_evaluation

from crowdnav.cli import main
from tests.paths import REPO

TOWARD_GOAL = textwrap.dedent('''
    import numpy as np

    def toward_goal(observation):
        distance, sin, cos = observation["goal"]
        return np.array([cos, sin], dtype=np.float32)
''')


def _pwn(marker: Path) -> str:
    """A module that, once imported, creates ``marker``: the proof that a results folder ran code."""
    return f"from pathlib import Path\nPath({str(marker)!r}).write_text('ran')\n{TOWARD_GOAL}\nact = toward_goal\n"


@pytest.fixture
def planted(tmp_path, monkeypatch):
    """(results folder, the result planted in it, marker): the issue's exploit, on a genuine `crowdnav evaluate` result.

    The result is scored by a module:function the user really has (``my_pol``, in ``work/``); then its meta.json is
    edited to name ``pwn_policy:act``, a module put into the result folder itself, which is also recorded as ``cwd``.
    """
    monkeypatch.setattr(sys, "path", list(sys.path))  # whatever evaluate adds to the import path, only for this test
    work = tmp_path / "work"
    work.mkdir()
    (work / "my_pol.py").write_text(TOWARD_GOAL)
    monkeypatch.chdir(work)
    try:
        assert main(["evaluate", "my_pol:toward_goal", "--scenario", "corridor", "--modalities", "goal", "--episodes", "2",
                     "--out", str(tmp_path / "R"), "--no-progress"]) == 0
    finally:
        sys.modules.pop("my_pol", None)
    (result,) = (tmp_path / "R" / "evaluate").glob("*/seeds_0-1")
    marker = tmp_path / "PWNED"
    (result / "pwn_policy.py").write_text(_pwn(marker))
    meta = json.loads((result / META_FILE).read_text())
    meta.update(policy="pwn_policy:act", policy_source="pwn_policy:act", cwd=str(result))
    (result / META_FILE).write_text(json.dumps(meta))
    yield tmp_path / "R", result, marker
    sys.modules.pop("pwn_policy", None)


def test_the_issues_exploit_runs_no_code_and_says_in_one_line_what_to_pass(planted, tmp_path):
    results, result, marker = planted
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    done = subprocess.run([sys.executable, "-m", "crowdnav", "trajectories", str(results)], cwd=elsewhere, capture_output=True,
                          text=True, timeout=300, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == 1 and not marker.exists()  # the module never ran
    error = done.stderr.strip()
    assert error.count("\n") == 0 and "Traceback" not in error, error
    assert error.startswith(f"crowdnav: error: {result}: it scored the module:function policy pwn_policy:act")
    assert "crowdnav never imports code a results folder names; to replay it, pass --import pwn_policy:act" in error
    assert not (result / "trajectories").exists()


def test_from_inside_the_results_folder_and_from_python_nothing_is_imported(planted, monkeypatch, capsys):
    results, result, marker = planted
    monkeypatch.chdir(result)  # even with the module in the current folder, only a name on the command line imports it
    assert main(["trajectories", "."]) == 1
    assert "pass --import pwn_policy:act" in capsys.readouterr().err and not marker.exists()
    with pytest.raises(ResultsError, match=r"never imports code a results folder names"):
        replay_evaluation(result)
    assert not marker.exists() and "pwn_policy" not in sys.modules
    assert str(result) not in sys.path and os.fspath(result) not in sys.path  # the recorded cwd never joins the import path


def test_import_names_the_code_to_run_and_only_code_a_result_scored(planted, tmp_path, monkeypatch, capsys):
    results, result, marker = planted
    monkeypatch.chdir(tmp_path / "work")
    assert main(["trajectories", str(results), "--import", "my_pol:toward_goal"]) == 1  # a name no result here scored
    assert "--import my_pol:toward_goal: no result here scored it" in capsys.readouterr().err
    assert main(["trajectories", "baseline:straight", "--scenario", "corridor", "--import", "x:y"]) == 1
    assert "--import is for results folders" in capsys.readouterr().err
    assert not marker.exists()
    # named on the command line, it is imported from where the user runs the command (work/ has none): one line
    assert main(["trajectories", str(results), "--import", "pwn_policy:act"]) == 1
    assert "cannot import 'act' from 'pwn_policy'" in capsys.readouterr().err and not marker.exists()
    # the user's own module of that name, in the current folder: the replay plays it, scored outcomes and all
    (tmp_path / "work" / "pwn_policy.py").write_text(f"{TOWARD_GOAL}\nact = toward_goal\n")
    importlib.invalidate_caches()  # the folder was listed by the failed import just before
    assert main(["trajectories", str(results), "--import", "pwn_policy:act"]) == 0
    assert (result / "trajectories" / "evaluate.csv").is_file() and not marker.exists()
