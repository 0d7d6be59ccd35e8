"""Tracks (evaluation/tracks/*.yaml): what each fixes, and a change of their episodes caught by the fingerprint."""

from __future__ import annotations

import importlib.util
import re

import pytest
from crowdnav.evaluation.track import FINGERPRINT_SEEDS, Track, TrackError, check_version, fingerprint, load_track, shipped_tracks

HAS_PYRVO = importlib.util.find_spec("pyrvo") is not None


def test_the_issue_tracks_are_shipped_and_figure4_fixes_the_paper_setting():
    assert {"figure4", "room", "circle_crossing", "crowded_open_space", "station_hall", "robots_crossing_hall"} <= set(shipped_tracks())
    figure4 = load_track("figure4")
    assert (figure4.scenario, dict(figure4.overrides)) == ("room_furniture", {"humans.count": 5, "humans.preferred_speed": [0.5, 1.2]})
    assert figure4.seeds == list(range(100)) and figure4.observations is None and figure4.version >= 1
    circle = load_track("circle_crossing")
    assert circle.test_episodes == 500 and circle.overrides == {"humans.model": "orca", "humans.preferred_speed": [1.0, 1.0]}
    assert load_track("room").overrides == {}
    assert figure4.env_options()["overrides"]["max_steps"] == figure4.time_limit_steps == 150


@pytest.mark.parametrize("name", [name if name != "circle_crossing" or HAS_PYRVO else
                                  pytest.param(name, marks=pytest.mark.skip(reason="ORCA humans need pyrvo (the orca extra)"))
                                  for name in shipped_tracks()])
def test_the_track_episodes_match_the_stored_fingerprint(name):
    """A change of the simulator or of the track that moves its episodes fails here: bump the version, store the new fingerprint."""
    track = load_track(name)
    now = fingerprint(track)
    assert now == track.fingerprint, (
        f"track {track.label}: its episodes changed (fingerprint {now}, stored {track.fingerprint}). Bump `version` to "
        f"{track.version + 1} and set fingerprint: \"{now}\" in {track.source} (crowdnav track check), then regenerate its "
        f"reference results (crowdnav track reference {name})")


def _variant(tmp_path, **changes) -> Track:
    text = load_track("figure4").source
    body = open(text, encoding="utf-8").read()
    for key, value in changes.items():
        body = re.sub(rf"^{key}: .*$", f"{key}: {value}", body, flags=re.M)
    path = tmp_path / "variant.yaml"
    path.write_text(body, encoding="utf-8")
    return load_track(str(path), check_fingerprint=False)  # its stored fingerprint is figure4's: loaded to compute its own


def test_a_change_of_the_episodes_changes_the_fingerprint(tmp_path):
    base = load_track("figure4")
    faster = _variant(tmp_path, overrides="{humans.count: 5, humans.preferred_speed: [0.6, 1.2]}")
    assert fingerprint(faster) != base.fingerprint
    later = _variant(tmp_path, test_seed_base=1)
    assert fingerprint(later) != base.fingerprint and FINGERPRINT_SEEDS >= 5


def test_a_bad_track_file_is_one_line_naming_the_file_and_the_field(tmp_path):
    with pytest.raises(TrackError, match=r"variant.yaml:\d+: observations: any, or a list of observation keys") as error:
        _variant(tmp_path, observations="[goal, sonar]")
    assert "\n" not in str(error.value)
    with pytest.raises(TrackError, match=r"variant.yaml:\d+: scenario: a library scenario name; did you mean 'room_furniture'"):
        _variant(tmp_path, scenario="room_furnitur")
    with pytest.raises(TrackError, match=r"version"):
        _variant(tmp_path, version=0)
    with pytest.raises(TrackError, match="unknown track 'figure5'; expected one of: .*did you mean 'figure4'"):
        load_track("figure5")


def test_observation_keys_the_track_does_not_allow_are_refused():
    hall = load_track("robots_crossing_hall")
    hall.check_observations(["goal", "lidar"])
    with pytest.raises(TrackError, match="track robots_crossing_hall allows the observation keys .*; humans is not allowed"):
        hall.env_options(["goal", "humans"])


def test_results_of_another_version_are_refused():
    track = load_track("figure4")
    check_version(track, track.identity(), "here")
    with pytest.raises(TrackError, match=r"measured on track figure4 v\d+, and the track is v\d+ now"):
        check_version(track, {**track.identity(), "version": track.version + 1}, "here")
    with pytest.raises(TrackError, match="was not measured on track figure4"):
        check_version(track, {"name": "room", "version": 1}, "here")
