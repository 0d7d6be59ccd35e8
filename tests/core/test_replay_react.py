"""Recorded people who react to the robot (``humans.replay.react_within``), the robot's clear start, clones.

Recordings are written by the tests (no data ships).
"""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav.crowd.recording import read_recording
from crowdnav.crowd.replay import START_CLEARANCE, ReplayModel, empty_places
from crowdnav.sim.simulator import Simulator
from crowdnav.worlds.compiled import load_world
from tests.core.test_replay import _replay, _write, native_equals_sync
from tests.core.test_vector_env import check_batch_equals_singles


@pytest.fixture
def recording(tmp_path):
    path = tmp_path / "walk.txt"
    _write(path)
    return path


def _through(path, point: complex, steps: int) -> None:
    """One person walking straight through ``point`` along x at 1 m/s (frame id x y, 2.5 Hz), ``steps`` * 0.25 s long."""
    seconds = steps * 0.25
    rows = []
    for k, t in enumerate(np.arange(0.0, seconds + 1e-9, 0.4)):
        where = point - 5 + t * 1.0
        rows.append(f"{k * 10} 1 {where.real:.5f} {where.imag:.5f}\n")
    path.write_text("".join(rows))


def _standing_robot_run(path, **extra):
    """Closest centre distance of the person to a robot that never moves, and whether the robot was hit."""
    sim = Simulator("open_space", {**_replay(path, **extra), "humans.count": 1, "max_steps": 40})
    sim.reset(seed=0)
    closest, hit = np.inf, False
    for _ in range(40):
        events = sim.step(np.zeros(2))
        shown = ~empty_places(sim.human_positions)
        closest = min(closest, float(np.abs(sim.human_positions[shown] - sim.robot_position).min(initial=np.inf)))
        hit = hit or events.collision is not None
        if events.collision is not None:
            break
    return closest, hit, sim


def test_a_person_walking_through_a_standing_robot_hits_it_in_pure_replay_and_walks_around_it_when_reacting(tmp_path):
    start = Simulator("open_space", {"max_steps": 40})
    start.reset(seed=0)  # the robot's start does not depend on the crowd: the recording is made to cross it
    path = tmp_path / "through.txt"
    _through(path, complex(start.robot_position), 40)
    _, hit, _ = _standing_robot_run(path)
    assert hit
    closest, hit, sim = _standing_robot_run(path, react_within=2.0)
    contact = sim.scenario.robot.radius + sim.scenario.humans.radius
    assert not hit and closest > contact
    assert sim.crowd.models["replay"].reacting.any()


def test_pure_replay_never_reacts_and_reacting_people_leave_the_recording_only_once_near_a_robot(recording):
    plain = Simulator("open_space", _replay(recording))
    near = Simulator("open_space", _replay(recording, react_within=3.0, react_lookahead=1.6))
    rng = np.random.default_rng(1)
    reacted = 0
    for seed in range(4):
        plain.reset(seed=seed)
        near.reset(seed=seed)
        model = near.crowd.models["replay"]
        assert model.start == plain.crowd.models["replay"].start
        for _ in range(80):
            action = rng.uniform(-1, 1, 2)
            was = model.reacting.copy()
            plain.step(action)
            near.step(action)
            assert not plain.crowd.models["replay"].reacting.any()
            # people who were not reacting before the step are exactly where the recording has them
            calm = ~was
            assert np.array_equal(near.human_positions[calm], plain.human_positions[calm])
            robots = near.robot_position
            newly = model.reacting & ~was
            assert (np.abs(near.human_positions[newly] - robots) <= 3.0).all()
            reacted += int(newly.sum())
    assert reacted > 0


def test_a_clone_steps_its_own_reacting_people(recording):
    overrides = _replay(recording, react_within=4.0)
    sim, again = Simulator("open_space", overrides), Simulator("open_space", overrides)
    sim.reset(seed=2)
    again.reset(seed=2)
    actions = np.random.default_rng(2).uniform(-1, 1, (60, 2))
    for action in actions[:20]:
        sim.step(action)
        again.step(action)
    twin = sim.clone()
    for action in actions[20:]:  # the clone runs ahead with other actions first
        twin.step(-action)
    for action in actions[20:]:
        sim.step(action)
        again.step(action)
        assert np.array_equal(sim.human_positions, again.human_positions)
    assert sim.crowd.models["replay"].reacting.any()


@pytest.fixture
def reactions(monkeypatch):
    """A list that counts, at every placing step of any simulator, how many recorded people react."""
    counted: list[int] = []
    place = ReplayModel.place

    def counting(self, view):
        placed = place(self, view)
        counted.append(int(self.reacting.sum()))
        return placed

    monkeypatch.setattr(ReplayModel, "place", counting)
    return counted


def test_batched_reacting_worlds_equal_single_simulators_bit_for_bit(recording, reactions):
    world = load_world("open_space", {**_replay(recording, react_within=4.0), "max_steps": 40})
    check_batch_equals_singles(world, worlds=3, first_seed=5, steps=90, rng_seed=6, scale=1.0)
    assert sum(reactions) > 20  # people reacted during the comparison


def test_the_native_vector_env_with_reacting_people_equals_the_sync_one(recording, reactions):
    ends = native_equals_sync(_replay(recording, react_within=4.0))
    assert ends > 0 and sum(reactions) > 20


def test_the_window_is_drawn_again_when_a_recorded_person_stands_on_the_robots_start(tmp_path):
    # people standing still at fixed points for the first 30 s, then none: windows starting early put someone on many starts
    rows = []
    spots = [complex(x, y) for x in np.arange(-4.0, 4.1, 1.0) for y in np.arange(-4.0, 4.1, 2.0)]
    for person, spot in enumerate(spots):
        for k in range(76):
            rows.append((k * 10, person, spot.real, spot.imag))
    rows.append((400 * 10, 999, 9.0, 9.0))  # one far away person late, so later windows exist
    rows.sort()
    path = tmp_path / "standing.txt"
    path.write_text("".join(f"{f} {p} {x} {y}\n" for f, p, x, y in rows))
    sim = Simulator("open_space", {**_replay(path), "humans.count": len(spots) + 1, "max_steps": 20})
    model = sim.crowd.models["replay"]
    clearance = sim.scenario.robot.radius + sim.scenario.humans.radius + START_CLEARANCE
    blocked_starts = 0
    for seed in range(12):
        sim.reset(seed=seed)
        shown = ~empty_places(sim.human_positions)
        assert np.abs(sim.human_positions[shown] - sim.robot_position).min(initial=np.inf) >= clearance
        people = model.present_at(0) if model.start else np.zeros(0)
        blocked_starts += int(len(people) > 0 and np.abs(people - sim.robot_position).min() < clearance)
    assert blocked_starts > 0  # the first window would have put someone on a start


def test_reacting_targets_are_the_recorded_positions_ahead(recording):
    sim = Simulator("open_space", _replay(recording, react_within=1.0, react_lookahead=1.0))
    sim.reset(seed=0)
    model = sim.crowd.models["replay"]
    grid = read_recording(recording).resample(sim.dt)
    ahead = round(1.0 / sim.dt)
    for track in grid.tracks:
        span = np.arange(len(track.positions))
        inside = (track.start + span >= model.start) & (track.start + span < model.start + sim.scenario.max_steps + 1)
        if not inside.any():
            continue
        k = int(span[inside][0])
        step = track.start + k - model.start
        place = int(np.flatnonzero(np.isclose(model._positions[step], track.positions[k]))[0])
        assert model._targets[step, place] == track.positions[min(k + ahead, len(track.positions) - 1)]
