"""Names that become file names are folder-safe, and output paths cannot leave their folder."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import yaml

from crowdnav import ScenarioError, load_scenario
from crowdnav.cli import main
from crowdnav.paths import OutputPathError, inside, is_safe_name, safe_stem
from crowdnav.scenario.library import library_dir


def _scenario_file(tmp_path: Path, name: str | None, filename: str = "mine.yaml") -> Path:
    document = yaml.safe_load((library_dir() / "open_space.yaml").read_text())
    document["max_steps"] = 3
    if name is None:
        document.pop("name", None)
    else:
        document["name"] = name
    path = tmp_path / filename
    path.write_text(yaml.safe_dump(document))
    return path


@pytest.mark.parametrize("name", ["../victim/pwned", "/tmp/pwned", "..", "a/b", "a\\b", ".hidden", "", "x" * 129])
def test_scenario_names_that_could_leave_a_folder_are_refused_at_validation(tmp_path, name):
    with pytest.raises(ScenarioError, match=r"mine\.yaml:\d+: name: expected a name of 1-128 letters"):
        load_scenario(_scenario_file(tmp_path, name))


@pytest.mark.parametrize("name", ["room_furniture", "Room-2.v1", "a"])
def test_folder_safe_scenario_names_are_accepted(name):
    assert is_safe_name(name)


def test_default_scenario_name_is_the_file_stem_made_folder_safe(tmp_path):
    assert load_scenario(_scenario_file(tmp_path, None, filename="my room (v2).yaml")).name == "my_room__v2_"
    assert safe_stem("...") == "scenario"


@pytest.mark.parametrize("name", ["../x.gif", "/tmp/x.gif", "sub/../../x.gif", ""])
def test_output_paths_resolving_outside_the_folder_are_refused(tmp_path, name):
    with pytest.raises(OutputPathError, match="outside the output folder"):
        inside(tmp_path / "out", name)


def test_output_path_through_a_symlink_leaving_the_folder_is_refused(tmp_path):
    out, victim = tmp_path / "out", tmp_path / "victim"
    out.mkdir()
    victim.mkdir()
    os.symlink(victim, out / "link")
    with pytest.raises(OutputPathError):
        inside(out, "link/video.gif")
    os.symlink(victim / "file.gif", out / "planted.gif")  # a file symlink planted where a video goes
    with pytest.raises(OutputPathError):
        inside(out, "planted.gif")
    assert inside(out, "ok.gif") == (out / "ok.gif").resolve()


def test_render_writes_only_inside_out_even_through_a_planted_symlink(tmp_path, capsys):
    out, victim = tmp_path / "out", tmp_path / "victim"
    out.mkdir()
    victim.mkdir()
    scenario = _scenario_file(tmp_path, "safe")
    os.symlink(victim / "stolen.gif", out / "safe_straight_seed0.gif")
    code = main(["render", str(scenario), "--policy", "straight", "--out", str(out), "--format", "gif", "--no-progress"])
    assert code == 1 and "outside the output folder" in capsys.readouterr().err
    assert not any(victim.iterdir())
