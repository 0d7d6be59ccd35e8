"""The people tracker's model (:mod:`crowdnav.sensors.tracker`): field of view and range, noise and detection statistics
over many draws, tracks (confirmation, coasting, drops, gating) and velocities fitted to the noisy positions."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from crowdnav.scenario.tracker import TRACKER_PROFILES, TrackerProfile
from crowdnav.sensors.tracker import PeopleTracker
from crowdnav.sensors.tracker_draws import episode_key
from tests.core.test_tracker_occlusion import PILLAR, RADIUS, scene

IDEAL = TrackerProfile(fov_deg=360.0, max_range=8.0, occlusion=False, min_visible=1 / 3, detection_probability=1.0,
                       position_noise=0.0, position_noise_per_m=0.0, drop_probability=0.0, max_missed=2, confirm_hits=2, window=4)
"""No noise, no misses: what the tests vary one value of."""
DT = 0.2  # the scene's time step


def tracker(worlds: int = 1, furniture: list | None = None, **values) -> PeopleTracker:
    return PeopleTracker(scene(furniture or []), dataclasses.replace(IDEAL, **values), worlds)


def positions(robot: complex, people: list[complex], worlds: int = 1) -> np.ndarray:
    return np.tile(np.array([robot, *people]), (worlds, 1))


def begin(track: PeopleTracker, state: np.ndarray, heading: float = 0.0, seeds: list | None = None) -> None:
    worlds = np.arange(len(state))
    track.start(worlds, seeds if seeds is not None else list(range(len(state))))
    track.update(worlds, state, np.zeros(len(state), complex), np.full(len(state), heading), np.full(state.shape[1], RADIUS))


def step(track: PeopleTracker, state: np.ndarray, heading: float = 0.0) -> None:
    track.update(np.arange(len(state)), state, np.zeros(len(state), complex), np.full(len(state), heading), np.full(state.shape[1], RADIUS))


def reported(track: PeopleTracker, n: int) -> np.ndarray:
    return track.reading(np.arange(track.num_worlds), n).reported


def test_the_field_of_view_is_centred_on_the_heading():
    track = tracker(fov_deg=69.4)
    ahead, edge_in, edge_out, behind = 4 + 0j, 4 * np.exp(1j * math.radians(34)), 4 * np.exp(1j * math.radians(36)), -4 + 0j
    begin(track, positions(0j, [ahead, edge_in, edge_out, behind]))
    np.testing.assert_array_equal(reported(track, 4)[0], [True, True, False, False])
    begin(track, positions(0j, [ahead, edge_in, edge_out, behind]), heading=math.pi)  # turned round
    np.testing.assert_array_equal(reported(track, 4)[0], [False, False, False, True])


def test_people_beyond_the_range_or_behind_a_pillar_are_not_detected():
    track = tracker(max_range=5.0, occlusion=True, furniture=[PILLAR])
    begin(track, positions(0j, [4.5j, 5.5j, 5 + 0j, 4 + 1.5j]))
    np.testing.assert_array_equal(reported(track, 4)[0], [True, False, False, True])


def test_position_noise_is_unbiased_gaussian_with_the_profiles_spread_over_many_draws():
    worlds, sigma, per_m = 4000, 0.1, 0.02
    track = tracker(worlds, position_noise=sigma, position_noise_per_m=per_m)
    near, far = 2 + 0j, -6 + 0j
    begin(track, positions(0j, [near, far], worlds))
    error = track.reading(np.arange(worlds), 2).positions - np.array([near, far])
    for column, distance in ((0, 2.0), (1, 6.0)):
        spread = sigma + per_m * distance
        for axis in (error[:, column].real, error[:, column].imag):
            assert abs(axis.mean()) < 4 * spread / math.sqrt(worlds)
            assert abs(axis.std() / spread - 1) < 0.05
            assert abs(np.mean(np.abs(axis) < spread) - 0.6827) < 0.03  # Gaussian: 68% within one sigma
        assert abs(np.corrcoef(error[:, column].real, error[:, column].imag)[0, 1]) < 0.05


def test_detections_and_false_drops_happen_at_their_probabilities():
    worlds, steps = 2000, 5
    state = positions(0j, [3 + 0j], worlds)
    missing = tracker(worlds, detection_probability=0.85)
    begin(missing, state)
    assert abs(reported(missing, 1).mean() - 0.85) < 0.03
    track = tracker(worlds, drop_probability=0.1, confirm_hits=1)
    begin(track, state)
    lost = 0.0
    for _ in range(steps):
        step(track, state)
        lost += np.mean(track._hits[:, 0] == 1)  # dropped, then detected again at once: a new track
    assert abs(lost / steps - 0.1) < 0.02


def test_a_constant_velocity_is_estimated_exactly_without_noise_once_there_are_two_detections():
    track = tracker()
    velocity = 0.7 - 0.4j
    start = 2 + 1j
    begin(track, positions(0j, [start]))
    reading = track.reading([0], 1)
    assert reading.velocity[0, 0] == 0.0 and reading.positions[0, 0] == start  # one detection: no velocity yet
    for t in range(1, 8):
        step(track, positions(0j, [start + velocity * DT * t]))
        reading = track.reading([0], 1)
        assert abs(reading.velocity[0, 0] - velocity) < 1e-12
        assert abs(reading.positions[0, 0] - (start + velocity * DT * t)) < 1e-12


def test_velocity_noise_is_the_least_squares_slopes_over_the_window():
    worlds, sigma, window = 3000, 0.05, 5
    track = tracker(worlds, position_noise=sigma, window=window)
    state = positions(0j, [3 + 0j], worlds)
    begin(track, state)
    for _ in range(window - 1):
        step(track, state)
    velocity = track.reading(np.arange(worlds), 1).velocity[:, 0]
    expected = sigma * math.sqrt(12 / (window * (window**2 - 1))) / DT  # the slope's spread for equally spaced steps
    for axis in (velocity.real, velocity.imag):
        assert abs(axis.mean()) < 4 * expected / math.sqrt(worlds)
        assert abs(axis.std() / expected - 1) < 0.06


def test_a_hidden_person_coasts_at_its_velocity_then_is_dropped_and_confirmed_again_when_seen():
    track = tracker(occlusion=True, furniture=[PILLAR], max_missed=2, confirm_hits=2)
    assert track.sight is not None
    path = [5 - 3j + 1j * DT * t for t in range(40)]  # walks up behind the pillar at (3, 0), 1 m/s along x = 5
    toward = np.array(path)[:, None]  # each point of the path alone: 40 worlds of one person
    hidden = list(track.sight.visible_fraction(np.zeros(40, complex), toward, np.abs(toward), np.array([RADIUS]),
                                               np.ones((40, 1), bool))[:, 0] < IDEAL.min_visible)
    begin(track, positions(0j, [path[0]]))
    shown, estimate = [True], [path[0]]
    for t in range(1, 40):
        step(track, positions(0j, [path[t]]))
        reading = track.reading([0], 1)
        shown.append(bool(reading.reported[0, 0]))
        estimate.append(reading.positions[0, 0])
    hide, back = hidden.index(True), hidden.index(False, hidden.index(True))
    assert back - hide > 3
    for t in (hide, hide + 1):  # coasting: reported, moved on at the estimated velocity
        assert shown[t] and abs(estimate[t] - path[t]) < 1e-9
    assert not any(shown[hide + 2 : back])  # dropped after max_missed steps
    assert not shown[back] and shown[back + 1]  # a new track, reported from its second detection


def test_a_detection_far_from_its_track_starts_a_new_track():
    track = tracker(confirm_hits=2)
    begin(track, positions(0j, [2 + 0j]))
    step(track, positions(0j, [2.1 + 0j]))
    assert reported(track, 1)[0, 0]
    step(track, positions(0j, [-4 + 0j]))  # a respawned person: 6 m from the prediction
    assert not reported(track, 1)[0, 0] and track._hits[0, 0] == 1


def test_the_same_seed_gives_the_same_tracks_and_the_next_episode_its_own():
    profile = TRACKER_PROFILES["lidar_tracker"]
    state = positions(0j, [2 + 1j, -3 + 0.5j, 1 - 4j, 4 + 4j], 3)

    def play(seeds):
        track = PeopleTracker(scene([PILLAR]), profile, 3)
        readings = []
        for seed in seeds:
            begin(track, state, seeds=[seed] * 3)
            for _ in range(5):
                step(track, state)
            readings.append(track.reading(np.arange(3), 4))
        return readings

    first, again = play([7, None]), play([7, None])
    for a, b in zip(first, again, strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)
    assert not np.array_equal(first[0].positions, first[1].positions, equal_nan=True)  # episode 1 of seed 7 draws anew


def test_episode_keys_follow_the_documented_rule():
    track = tracker(2)
    track.start([0, 1], [5, 9])
    assert list(track._key) == [episode_key(5, 0), episode_key(9, 0)]
    track.start([0], [None])
    assert track._key[0] == episode_key(5, 1) and track._key[1] == episode_key(9, 0)
    track.start([1], [None])
    track.start([1], [None])
    assert track._key[1] == episode_key(9, 2)
    assert len({episode_key(5, 0), episode_key(5, 1), episode_key(6, 0)}) == 3


@pytest.mark.parametrize("name", ["lidar_tracker", "camera_front"])
def test_the_profiles_values_are_as_documented(name):
    values = TRACKER_PROFILES[name]
    assert values is not None and values.occlusion and 0 < values.detection_probability < 1 and values.window >= 2
