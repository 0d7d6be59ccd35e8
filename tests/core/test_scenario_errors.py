"""Invalid scenario files: each mistake is reported with file, dotted path, line and what was expected."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from crowdnav.cli import main
from crowdnav.scenario import ScenarioError, load_scenario
from crowdnav.worlds.compiled import load_world

VALID = """\
description: A small test room.
world: {min: [-4, -4], max: [4, 4]}
robot:
  kinematics: holonomic
  start: {type: rectangle, min: [-3.5, -3.5], max: [-2.5, -2.5]}
  goal: {type: rectangle, min: [2.5, 2.5], max: [3.5, 3.5]}
humans:
  count: 4
  radius: 0.3
  spawn: [{type: rectangle, min: [-3.5, -3.5], max: [3.5, 3.5]}]
  goal: [{type: rectangle, min: [-3.5, -3.5], max: [3.5, 3.5]}]
"""


def edit(old: str, new: str) -> str:
    """The valid document with one exact line fragment replaced (so line numbers stay known)."""
    assert VALID.count(old) == 1, old
    return VALID.replace(old, new)


# (case id, YAML text, dotted path, line or None, fragments the message must contain)
CASES = [
    (
        "unknown top-level key lists the allowed keys",
        VALID + "humnas: 3\n",
        "humnas", 12, ["unknown key 'humnas'", "expected one of:", "humans", "max_steps", "world"],
    ),
    (
        "unknown nested key lists the section's keys",
        edit("  kinematics: holonomic\n", "  kinematics: holonomic\n  max_sped: 1.0\n"),
        "robot.max_sped", 5, ["unknown key 'max_sped'; did you mean 'max_speed'?", "goal_radius"],
    ),
    (
        "wrong type",
        VALID + "time_step: fast\n",
        "time_step", 12, ["expected a number", "'fast'"],
    ),
    (
        "negative radius",
        edit("  radius: 0.3\n", "  radius: -0.3\n"),
        "humans.radius", 9, ["expected a number > 0", "-0.3"],
    ),
    (
        "region outside the world",
        edit("max: [3.5, 3.5]}\nhumans", "max: [4.5, 3.5]}\nhumans"),
        "robot.goal", 6, ["outside the world", "x in [-4, 4]"],
    ),
    (
        "self-intersecting furniture polygon",
        VALID + "furniture:\n  - {type: polygon, name: bow tie, points: [[0, 0], [1, 1], [1, 0], [0, 1]]}\n",
        "furniture.0.points", 13, ["Self-intersection", "expected a simple polygon"],
    ),
    (
        "crowd that does not fit its spawn region",
        edit("  count: 4\n", "  count: 200\n"),
        "humans.count", 8, ["hold at most", "asked for up to 200"],
    ),
    (
        "unicycle without a maximum angular speed",
        edit("kinematics: holonomic", "kinematics: unicycle"),
        "robot.max_angular_speed", 3, ["maximum angular speed", "unicycle"],
    ),
    (
        "count range with min > max",
        edit("  count: 4\n", "  count: [8, 3]\n"),
        "humans.count", 8, ["0 <= min <= max", "[8, 3]"],
    ),
    (
        "count that is neither a number nor a range, without union noise",
        edit("  count: 4\n", "  count: many\n"),
        "humans.count", 8, ["expected a whole number of humans, or [min, max]", "'many'"],
    ),
    (
        "unknown region type",
        edit("start: {type: rectangle,", "start: {type: hexagon,"),
        "robot.start", 5, ["unknown type 'hexagon'", "'rectangle', 'polygon', 'points', 'circle'"],
    ),
    (
        "region without a type",
        edit("start: {type: rectangle, min", "start: {min"),
        "robot.start", 5, ["expected a 'type' key", "'rectangle'"],
    ),
    (
        "impossible min_start_goal_distance",
        edit("  kinematics: holonomic\n", "  kinematics: holonomic\n  min_start_goal_distance: 20\n"),
        "robot.min_start_goal_distance", 5, ["20 m", "largest distance available"],
    ),
    (
        "robot too fast for the time step",
        edit("  kinematics: holonomic\n", "  kinematics: holonomic\n  max_speed: 4.0\n"),
        "robot.max_speed", 5, ["0.8 m per step", "less than its diameter 0.6 m"],
    ),
    (
        "point with three coordinates",
        edit("min: [-3.5, -3.5], max: [-2.5, -2.5]}", "min: [-3.5, -3.5, 0], max: [-2.5, -2.5]}"),
        "robot.start.min", 5, ["expected a point [x, y]", "[-3.5, -3.5, 0]"],
    ),
    (
        "missing required field names the field's meaning",
        edit("  goal: {type: rectangle, min: [2.5, 2.5], max: [3.5, 3.5]}\n", ""),
        "robot.goal", 3, ["required field is missing", "goal position"],
    ),
    (
        "unknown reward preset lists the presets",
        VALID + "reward: {preset: papr, social: -50}\n",
        "reward.preset", 12, ["unknown reward preset 'papr'; did you mean 'paper'?", "expected one of: default, paper"],
    ),
    (
        "unknown reward term lists the terms and the preset key",
        VALID + "reward:\n  preset: paper\n  socal: -50\n",
        "reward.socal", 14,
        ["unknown key 'socal'; did you mean 'social'?", "collision, goal_progress, goal_reached, preset, social, step"],
    ),
    (
        "duplicate key",
        edit("  radius: 0.3\n", "  radius: 0.3\n  radius: 0.4\n"),
        "humans.radius", 10, ["duplicate key 'radius'", "first given at line 9"],
    ),
]


def write(tmp_path: Path, text: str, name: str = "scenario.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def issue_at(error: ScenarioError, path: str):
    matches = [issue for issue in error.issues if issue.path == path]
    assert matches, f"no issue at {path!r} in:\n{error}"
    return matches[0]


def test_the_base_document_is_valid(tmp_path):
    load_scenario(write(tmp_path, VALID))


@pytest.mark.parametrize(("case", "text", "path", "line", "expected"), CASES, ids=[case[0] for case in CASES])
def test_invalid_file_reports_file_path_line_and_expectation(tmp_path, case, text, path, line, expected):
    file = write(tmp_path, text)
    with pytest.raises(ScenarioError) as caught:
        load_world(file)  # the loader's checks, then the geometry's
    issue = issue_at(caught.value, path)
    assert issue.line == line
    report_line = next(row for row in str(caught.value).splitlines() if f" {path}: " in row)
    assert report_line.startswith(f"{file}:{line}: {path}: ")
    for fragment in expected:
        assert fragment in issue.message


def test_the_loader_leaves_geometry_to_the_world_which_reports_it_with_the_line(tmp_path):
    file = write(tmp_path, edit("  goal: {type: rectangle, min: [2.5, 2.5], max: [3.5, 3.5]}\n",
                                "  goal: {type: rectangle, min: [2.5, 2.5], max: [4.5, 3.5]}\n"))
    assert list(load_scenario(file).robot.goal.max) == [4.5, 3.5]  # pure: YAML, schema and consistency only
    with pytest.raises(ScenarioError) as caught:
        load_world(file)
    assert issue_at(caught.value, "robot.goal").line == 6


def test_there_are_at_least_twelve_distinct_invalid_file_cases():
    assert len({case[0] for case in CASES}) >= 12
    assert len({case[1] for case in CASES}) == len(CASES)


def test_malformed_yaml_reports_the_line(tmp_path):
    file = write(tmp_path, "description: broken\nrobot:\n  start: {type: rectangle, min: [0, 0]\n  goal: {}\n")
    with pytest.raises(ScenarioError) as caught:
        load_scenario(file)
    (issue,) = caught.value.issues
    assert "malformed YAML" in issue.message
    assert issue.line in (3, 4)
    assert str(caught.value).startswith(f"{file}:{issue.line}: ")


def test_empty_file_says_it_is_empty(tmp_path):
    file = write(tmp_path, "# only a comment\n")
    with pytest.raises(ScenarioError) as caught:
        load_scenario(file)
    assert str(caught.value) == f"{file}:1: expected a mapping of scenario fields at the top level, got an empty file"


def test_top_level_list_is_rejected(tmp_path):
    with pytest.raises(ScenarioError, match="top level, got list"):
        load_scenario(write(tmp_path, "- description: x\n"))


def test_missing_file_names_the_file(tmp_path):
    missing = tmp_path / "nowhere.yaml"
    with pytest.raises(ScenarioError) as caught:
        load_scenario(missing)
    assert str(caught.value) == f"{missing}: file not found"


def test_unknown_library_name_suggests_the_closest_and_lists_the_library():
    with pytest.raises(ScenarioError) as caught:
        load_scenario("corridr")
    report = str(caught.value)
    assert report.startswith("corridr: no such file or library scenario")
    assert "did you mean 'corridor'?" in report and "room_furniture" in report


def test_directory_is_rejected_with_a_clear_message(tmp_path):
    with pytest.raises(ScenarioError, match="is a directory; expected a scenario YAML file"):
        load_scenario(str(tmp_path) + "/")


def test_all_schema_problems_are_reported_together(tmp_path):
    text = edit("  radius: 0.3\n", "  radius: -1\n") + "time_step: 0\nmax_steps: ten\n"
    with pytest.raises(ScenarioError) as caught:
        load_scenario(write(tmp_path, text))
    assert {"humans.radius", "time_step", "max_steps"} <= {issue.path for issue in caught.value.issues}


@pytest.mark.parametrize(
    ("overrides", "path", "expected"),
    [
        ({"walls.2.thickness": 0.2}, "walls.2.thickness", "override path does not exist at 'walls'"),
        ({"humans.count.low": 1}, "humans.count.low", "goes through 'humans.count'"),
        ({"humans.furniture": []}, "humans.furniture", "unknown key 'furniture'"),
        ({"humans.count": "lots"}, "humans.count", "expected a whole number of humans"),
        ({"robot.max_speed": -1}, "robot.max_speed", "expected a number > 0"),
        ({"robot.start.min": [0, 0, 0]}, "robot.start.min", "expected a point [x, y]"),
        ({"reward.preset": "fast"}, "reward.preset", "unknown reward preset 'fast'; expected one of: default, paper"),
        ({"reward.speed": 1}, "reward.speed", "unknown key 'speed'"),
    ],
)
def test_bad_override_names_the_override(tmp_path, overrides, path, expected):
    file = write(tmp_path, VALID)
    with pytest.raises(ScenarioError) as caught:
        load_scenario(file, overrides=overrides)
    issue = issue_at(caught.value, path)
    assert expected in issue.message
    assert issue.line is None  # the value is not in the file
    assert str(caught.value).startswith(f"{file}: {path}: ")


def test_override_inside_a_region_keeps_the_region_line(tmp_path):
    with pytest.raises(ScenarioError) as caught:
        load_world(write(tmp_path, VALID), overrides={"robot.goal.max": [4.5, 3.5]})
    issue = issue_at(caught.value, "robot.goal")
    assert issue.line == 6 and "(with override robot.goal.max)" in issue.message


def test_mapping_source_is_labelled_as_such():
    with pytest.raises(ScenarioError) as caught:
        load_scenario({"description": "x"})
    assert str(caught.value).startswith("<mapping>: robot: required field is missing")


def test_cli_validate_reports_every_bad_file_and_exits_1(tmp_path, capsys):
    good = write(tmp_path, VALID, "good.yaml")
    bad = [write(tmp_path, text, f"bad{i}.yaml") for i, (_, text, *_rest) in enumerate(CASES[:4])]
    argv = ["scenario", "validate", str(good), *map(str, bad), str(tmp_path / "missing.yaml"), str(tmp_path)]
    assert main(argv) == 1
    out, err = capsys.readouterr()
    assert out == f"OK {good}\n"
    for file in bad:
        assert f"{file}:" in err
    assert f"{tmp_path / 'missing.yaml'}: file not found" in err
    assert f"{tmp_path}: is a directory" in err
    assert "6 of 7 scenarios are invalid" in err


def test_cli_validate_never_shows_a_traceback(tmp_path):
    bad = [write(tmp_path, text, f"bad{i}.yaml") for i, (_, text, *_rest) in enumerate(CASES)]
    empty = write(tmp_path, "", "empty.yaml")
    files = [*map(str, bad), str(empty), "no_such_scenario", str(tmp_path)]
    command = [sys.executable, "-m", "crowdnav", "scenario", "validate", *files]
    result = subprocess.run(command, capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert "Traceback" not in result.stderr + result.stdout
    assert result.stdout == ""
    assert result.stderr.count(str(tmp_path)) >= len(CASES) + 2
    assert "unknown key 'humnas'" in result.stderr and "got an empty file" in result.stderr
