"""``crowdnav scenario validate`` = the environment for recorded crowds: it refuses what an environment refuses (a missing
recording, too few places) with the environment's own message, and what ``from-recording`` writes validates and builds an
environment from any folder. The recordings are written by the tests (no data ships)."""

from __future__ import annotations

import pytest
import yaml

from crowdnav.cli import main
from crowdnav.envs import CrowdNavEnv
from crowdnav.scenario import ScenarioError
from tests.cli.test_recording_cli import write_recording


def _recorded(tmp_path, walkers=None):
    """A recording and the scenario ``from-recording`` writes beside it (``recorded.yaml``, naming ``walk.txt``)."""
    recording = tmp_path / "walk.txt"
    write_recording(recording, "frames", *([walkers] if walkers else []))
    out = tmp_path / "recorded.yaml"
    assert main(["scenario", "from-recording", str(recording), "--out", str(out)]) == 0
    return recording, out


def _environment_refusal(scenario) -> str:
    with pytest.raises(ScenarioError) as error:
        CrowdNavEnv(str(scenario))
    return str(error.value)


@pytest.mark.parametrize("old,new,field", [
    ("file: walk.txt", "file: gone.txt", "humans.replay.file: "),  # the recording is missing
    ("count: 4", "count: 3", "humans.count: "),  # fewer places than the people present at once need
])
def test_validate_refuses_a_replay_scenario_as_the_environment_does_with_its_message(tmp_path, capsys, old, new, field):
    _, scenario = _recorded(tmp_path)
    text = scenario.read_text()
    assert text.count(old) == 1
    scenario.write_text(text.replace(old, new))
    refusal = _environment_refusal(scenario)
    capsys.readouterr()
    assert main(["scenario", "validate", str(scenario)]) == 1
    err = capsys.readouterr().err
    assert err == refusal + "\n"  # one line, the environment's words
    line = text[: text.index(old)].count("\n") + 1
    assert err.startswith(f"{scenario}:{line}: {field}")  # file, line and field; the expectation follows


def test_validate_refuses_an_overridden_count_below_the_people_present_at_once(tmp_path, capsys):
    _, scenario = _recorded(tmp_path)
    capsys.readouterr()
    assert main(["scenario", "validate", str(scenario), "--set", "humans.count=2"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "humans.count: model replay: the recording walk.txt needs 4 places" in err
    assert "expected count >= 4 (from override)" in err


def test_from_recording_output_validates_and_builds_an_environment_from_any_folder(tmp_path, capsys, monkeypatch):
    data, scenarios, elsewhere = tmp_path / "data", tmp_path / "scenarios", tmp_path / "elsewhere"
    for folder in (data, scenarios, elsewhere):
        folder.mkdir()
    beside, _ = _recorded(scenarios)  # inside the scenario's folder: named relative to it
    write_recording(data / "walk.txt", "frames")
    away = scenarios / "away.yaml"  # outside it: named by its absolute path
    assert main(["scenario", "from-recording", str(data / "walk.txt"), "--out", str(away)]) == 0
    assert yaml.safe_load((scenarios / "recorded.yaml").read_text())["humans"]["replay"]["file"] == "walk.txt"
    assert yaml.safe_load(away.read_text())["humans"]["replay"]["file"] == str((data / "walk.txt").resolve())
    monkeypatch.chdir(elsewhere)
    for scenario in ("../scenarios/recorded.yaml", "../scenarios/away.yaml"):
        assert main(["scenario", "validate", scenario]) == 0
        env = CrowdNavEnv(scenario)
        env.reset(seed=0)
        env.close()
    assert beside.exists()


def test_from_recording_of_people_walking_up_to_2_m_s_validates_and_builds_an_environment(tmp_path, capsys):
    fast = {1: (0.0, 6.0, -6 - 1j, 6 - 1j), 2: (2.0, 9.0, 6 + 1j, -6 + 1j), 3: (4.0, 12.0, -6 + 0j, 6 + 0.5j),
            4: (5.0, 12.0, 6 - 2j, -6 - 1.5j)}  # 1.6-2.0 m/s: hotel's fast people, written at the default 0.2 s step
    _, scenario = _recorded(tmp_path, fast)
    assert yaml.safe_load(scenario.read_text())["humans"]["preferred_speed"][1] > 1.5
    # loads since issue 52 item 2 (human sub-steps: recorded speeds at the default step); refused before it
    assert main(["scenario", "validate", str(scenario)]) == 0
    CrowdNavEnv(str(scenario)).close()
