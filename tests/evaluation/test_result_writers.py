"""Results folders that cannot be mixed: one `crowdnav evaluate` writer per result folder (a lock; a second one is refused
in one line naming the folder and the first one's PID), a result written whole (a hidden sibling folder renamed into
place), and whatever kills a writer, the folder holds the old complete result or the new one, never a mix."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from crowdnav.evaluation.evaluate import evaluate_policy
from crowdnav.evaluation.leaderboard import write_leaderboard
from crowdnav.evaluation.storage import META_FILE, TEST_FILE, ResultsError, finished_runs
from crowdnav.evaluation.trajectories import finished_results

from crowdnav.cli import main
from tests.paths import REPO

SCENARIO, EPISODES, NAME = "corridor", 3, "shared"
ARGS = ["--scenario", SCENARIO, "--episodes", str(EPISODES), "--name", NAME, "--no-progress"]

SLOW = textwrap.dedent('''
    import time
    from pathlib import Path

    import numpy as np

    def act(observation):  # says it started, then waits for the test to let it finish
        Path("started").touch()
        deadline = time.monotonic() + 120
        while not Path("release").exists() and time.monotonic() < deadline:
            time.sleep(0.01)
        distance, sin, cos = observation["goal"]
        return np.array([cos, sin], dtype=np.float32)
''')


def _folder(out: Path) -> Path:
    return out / "evaluate" / f"{NAME}--{SCENARIO}" / f"seeds_0-{EPISODES - 1}"


def _crowdnav(out: Path, policy: str, *extra: str, cwd: Path, patch: str = "") -> subprocess.Popen:
    """``crowdnav evaluate POLICY`` into ``out`` in a child process, after running ``patch`` (Python) in it."""
    code = f"{patch}\nimport sys\nfrom crowdnav.cli import main\nsys.exit(main(sys.argv[1:]))"
    return subprocess.Popen([sys.executable, "-c", code, "evaluate", policy, *ARGS, "--out", str(out), *extra], cwd=cwd,
                            env={**os.environ, "PYTHONPATH": str(REPO)}, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {path.name: path.read_bytes() for path in sorted(folder.iterdir())}


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> dict[str, bytes]:
    """Each policy's test_episodes.csv under the shared name, evaluated alone: what a whole result of it holds."""
    out = tmp_path_factory.mktemp("reference")
    return {policy: (evaluate_policy(policy, SCENARIO, out / policy.replace(":", "_"), episodes=EPISODES, name=NAME) / TEST_FILE).read_bytes()
            for policy in ("baseline:straight", "baseline:social_force")}


def _assert_whole(folder: Path, reference: dict[str, bytes]) -> str:
    """The folder holds one policy's complete result: its rows are those that policy scores alone. Returns the policy."""
    meta = json.loads((folder / META_FILE).read_text())
    assert meta["status"] == "complete" and (folder / TEST_FILE).read_bytes() == reference[meta["policy"]]
    return str(meta["policy"])


def test_a_second_writer_is_refused_in_one_line_naming_the_folder_and_the_first_writers_pid(tmp_path, capsys):
    (tmp_path / "slow_pol.py").write_text(SLOW)
    out = tmp_path / "results"
    first = _crowdnav(out, "slow_pol:act", "--modalities", "goal", cwd=tmp_path)
    deadline = time.monotonic() + 120
    while not (tmp_path / "started").exists():
        assert first.poll() is None, first.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.01)
    try:
        for extra in ([], ["--force"]):  # --force replaces a finished result, never one being written
            assert main(["evaluate", "baseline:straight", *ARGS, "--out", str(out), *extra]) == 1
            error = capsys.readouterr().err.strip()
            assert error == (f"crowdnav: error: {_folder(out)} is being written by another process (PID {first.pid}); "
                             "one writer at a time: wait for it to finish, or write to another --out")
    finally:
        (tmp_path / "release").touch()
        _, stderr = first.communicate(timeout=300)
    assert first.returncode == 0, stderr
    assert json.loads((_folder(out) / META_FILE).read_text())["policy"] == "slow_pol:act"
    assert sorted(path.name for path in _folder(out).parent.iterdir()) == [_folder(out).name]  # no lock or staging left


def test_two_evaluations_started_together_into_one_folder_leave_one_whole_result(tmp_path, reference):
    out = tmp_path / "results"
    for extra in ([], ["--force"]):  # with --force both may finish, one after the other: still one whole result
        runs = {policy: _crowdnav(out, policy, *extra, cwd=tmp_path) for policy in ("baseline:straight", "baseline:social_force")}
        done = {policy: (run.wait(timeout=300), *run.communicate()) for policy, run in runs.items()}
        codes = sorted(code for code, _, _ in done.values())
        assert codes in ([0, 1], [0, 0] if extra else [0, 1]), done
        for code, stdout, stderr in done.values():
            if code == 1:  # the loser: one line, the lock's or the finished result's
                assert stderr.count("\n") == 1 and ("is being written by another process (PID " in stderr or "already holds" in stderr)
            else:
                assert f"wrote {_folder(out)}" in stdout
        _assert_whole(_folder(out), reference)
    table, _ = write_leaderboard([out], tmp_path / "board")
    assert len(table) == 1


def test_a_kill_between_the_two_files_leaves_the_old_result_whole_and_unranked_leftovers(tmp_path, reference):
    out = tmp_path / "results"
    kill_at_meta = ("import os\nimport crowdnav.evaluation.storage as storage\nwrite = storage.atomic_write_json\n"
                    "storage.atomic_write_json = lambda path, doc: os._exit(9) if path.name == 'meta.json' else write(path, doc)\n")
    fresh = _crowdnav(out, "baseline:straight", cwd=tmp_path, patch=kill_at_meta)  # a first result, killed mid-way
    assert fresh.wait(timeout=300) == 9 and not _folder(out).exists()
    assert finished_results(out) == [] and finished_runs([out]) == []  # its half-written staging folder is no result
    assert main(["evaluate", "baseline:straight", *ARGS, "--out", str(out)]) == 0
    old = _snapshot(_folder(out))
    replacing = _crowdnav(out, "baseline:social_force", "--force", cwd=tmp_path, patch=kill_at_meta)
    assert replacing.wait(timeout=300) == 9
    assert any(path.name.startswith(f".{_folder(out).name}.") and path.name.endswith(".new")
               for path in _folder(out).parent.iterdir())  # its rows, hidden
    assert _snapshot(_folder(out)) == old and _assert_whole(_folder(out), reference) == "baseline:straight"
    table, _ = write_leaderboard([out], tmp_path / "board")
    assert len(table) == 1 and list(finished_results(out)) == [_folder(out)]
    assert main(["evaluate", "baseline:social_force", *ARGS, "--out", str(out), "--force"]) == 0
    assert _assert_whole(_folder(out), reference) == "baseline:social_force"
    assert sorted(path.name for path in _folder(out).parent.iterdir()) == [_folder(out).name]  # the leftover cleared


def test_a_kill_between_the_renames_of_a_replacement_gets_the_old_result_back(tmp_path, reference, capsys):
    out = tmp_path / "results"
    assert main(["evaluate", "baseline:straight", *ARGS, "--out", str(out)]) == 0
    old = _snapshot(_folder(out))
    # a system without an atomic exchange of two folders: the old one is renamed aside first; the kill comes right after
    kill_aside = ("import os\nimport crowdnav.files as files\nfiles._exchange = lambda a, b: False\n"
                  "rename = os.rename\n"
                  "def killing(source, target):\n    rename(source, target)\n    if str(target).endswith('.old'): os._exit(9)\n"
                  "os.rename = killing\n")
    replacing = _crowdnav(out, "baseline:social_force", "--force", cwd=tmp_path, patch=kill_aside)
    assert replacing.wait(timeout=300) == 9
    assert not _folder(out).exists() and finished_results(out) == []  # no result then, never a mixed one
    with pytest.raises(ResultsError, match="no finished run here"):
        write_leaderboard([out], tmp_path / "board")
    assert main(["evaluate", "baseline:social_force", *ARGS, "--out", str(out)]) == 1  # the next writer puts it back
    assert "already holds this policy's results" in capsys.readouterr().err
    assert _snapshot(_folder(out)) == old and _assert_whole(_folder(out), reference) == "baseline:straight"
    assert sorted(path.name for path in _folder(out).parent.iterdir()) == [_folder(out).name]
