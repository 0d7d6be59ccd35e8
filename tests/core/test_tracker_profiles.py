"""``sensors.tracker``: named profiles, selected per scenario, by override (``--set``) or env option; bad names and values
are one-line errors naming the field (file and line for a file)."""

from __future__ import annotations

import pytest

from crowdnav.cli.common import parse_overrides
from crowdnav.envs import CrowdNavEnv
from crowdnav.scenario import ScenarioError, load_scenario
from crowdnav.scenario.tracker import PERFECT, TRACKER_PROFILES, VALUE_FIELDS, TrackerSettings
from tests.core.test_scenario_errors import VALID, issue_at, write


def test_the_default_is_perfect_with_no_tracker_values():
    settings = load_scenario("room_furniture").sensors.tracker
    assert settings.profile == PERFECT and settings.values is None
    assert settings.model_dump() == {"profile": PERFECT}


@pytest.mark.parametrize("name", [name for name, values in TRACKER_PROFILES.items() if values is not None])
def test_a_profile_name_alone_selects_all_of_its_values(name):
    for overrides in ({"sensors.tracker": name}, {"sensors.tracker.profile": name}):
        settings = load_scenario("room_furniture", overrides).sensors.tracker
        assert settings.values == TRACKER_PROFILES[name]
        assert settings.model_dump() == {"profile": name}  # dumped as written: a reload resolves the same way


def test_a_field_beside_the_profile_overrides_that_value_only():
    overrides = parse_overrides(["sensors.tracker.profile=camera_front", "sensors.tracker.window=3", "sensors.tracker.fov_deg=90"])
    values = load_scenario("room_furniture", overrides).sensors.tracker.values
    assert values is not None and (values.window, values.fov_deg) == (3, 90.0)
    assert values.detection_probability == TRACKER_PROFILES["camera_front"].detection_probability  # type: ignore[union-attr]


def test_the_profile_is_selected_in_a_scenario_file_and_by_env_option(tmp_path):
    file = write(tmp_path, VALID + "sensors:\n  tracker: lidar_tracker\n")
    assert load_scenario(file).sensors.tracker.profile == "lidar_tracker"
    env = CrowdNavEnv("room_furniture", modalities=["humans"], sensors={"tracker": {"profile": "camera_front", "max_range": 4.0}})
    assert env.core.tracker is not None and env.core.tracker.values.max_range == 4.0
    assert CrowdNavEnv("room_furniture", modalities=["humans"]).core.tracker is None  # perfect: no tracker at all


@pytest.mark.parametrize(("overrides", "path", "fragments"), [
    ({"sensors.tracker": "lidar"}, "sensors.tracker", ["unknown tracker profile 'lidar'", "lidar_tracker", "camera_front"]),
    ({"sensors.tracker.profile": "camera"}, "sensors.tracker.profile", ["unknown tracker profile 'camera'", "did you mean 'camera_front'"]),
    ({"sensors.tracker.position_noise": 0.1}, "sensors.tracker.position_noise", ["'perfect' profile", "lidar_tracker"]),
    ({"sensors.tracker.profile": "lidar_tracker", "sensors.tracker.detection_probability": 1.5},
     "sensors.tracker.detection_probability", ["<= 1", "1.5"]),
    ({"sensors.tracker.profile": "lidar_tracker", "sensors.tracker.window": 1}, "sensors.tracker.window", [">= 2"]),
    ({"sensors.tracker.profile": "lidar_tracker", "sensors.tracker.fov_deg": 400}, "sensors.tracker.fov_deg", ["<= 360"]),
    ({"sensors.tracker.profile": "lidar_tracker", "sensors.tracker.occlusion": "yes"}, "sensors.tracker.occlusion", ["'yes'"]),
    ({"sensors.tracker.profile": "lidar_tracker", "sensors.tracker.noise": 0.1}, "sensors.tracker.noise", ["unknown key 'noise'"]),
])
def test_bad_names_and_values_are_one_line_errors_naming_the_field(overrides, path, fragments):
    with pytest.raises(ScenarioError) as caught:
        load_scenario("room_furniture", overrides)
    issue = issue_at(caught.value, path)
    assert "\n" not in issue.message
    for fragment in fragments:
        assert fragment in issue.message


def test_a_bad_profile_in_a_file_names_the_file_the_line_and_the_field(tmp_path):
    file = write(tmp_path, VALID + "sensors:\n  tracker: {profile: lidar_tracker, drop_probability: 1.0}\n")
    with pytest.raises(ScenarioError) as caught:
        load_scenario(file)
    issue = issue_at(caught.value, "sensors.tracker.drop_probability")
    assert issue.line == 13 and "< 1" in issue.message
    assert f"{file}:13: sensors.tracker.drop_probability: " in str(caught.value)


def test_several_robots_keep_the_perfect_tracker_in_one_line():
    with pytest.raises(ScenarioError) as caught:
        load_scenario("robots_crossing_hall", {"sensors.tracker": "lidar_tracker"})
    assert "one robot" in issue_at(caught.value, "sensors.tracker").message


def test_every_profile_value_is_a_documented_field():
    assert set(VALUE_FIELDS) == set(TrackerSettings.model_fields) - {"profile"}
    for name in VALUE_FIELDS:
        assert TrackerSettings.model_fields[name].description
