"""The recorded crowd (``humans.model: replay``): people appear, walk and leave as recorded, in both simulators.

The recording is written by the test (no data ships): four people in 60 s at 2.5 Hz in the
open_space world, at most three at once.
"""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav.crowd.recording import read_recording
from crowdnav.crowd.replay import PARKING
from crowdnav.scenario import ScenarioError
from crowdnav.sim.simulator import Simulator
from crowdnav.worlds.compiled import load_world
from tests.core.test_vector_env import check_batch_equals_singles

PEOPLE = {  # id: (first s, last s, start point, end point)
    1: (0.0, 40.0, -4 - 2j, 4 - 2j),
    2: (10.0, 40.0, 4 + 2j, -4 + 2j),
    3: (30.0, 50.0, 0 - 4j, 0 + 4j),
    4: (44.0, 60.0, -4 + 4j, 4 - 4j),
}


def _write(path) -> None:
    rows = []
    for person, (t0, t1, a, b) in PEOPLE.items():
        for t in np.arange(t0, t1 + 1e-9, 0.4):
            where = a + (b - a) * (t - t0) / (t1 - t0)
            rows.append((round(t / 0.4) * 10, person, where.real, where.imag))
    rows.sort()
    path.write_text("".join(f"{f}\t{p}\t{x:.4f}\t{y:.4f}\n" for f, p, x, y in rows))


@pytest.fixture
def recording(tmp_path):
    path = tmp_path / "walk.txt"
    _write(path)
    return path


def _replay(path, **extra):
    return {"humans.model": "replay", "humans.count": 3, "humans.replay": {"file": str(path), **extra}}


def test_placed_humans_are_the_recorded_people_present_at_each_step_and_the_rest_are_parked(recording):
    sim = Simulator("open_space", _replay(recording, offset=[0.5, 0.0]))
    model = sim.crowd.models["replay"]
    grid = read_recording(recording).resample(sim.dt)
    seen = set()
    for seed in (0, 1):
        sim.reset(seed=seed)
        _, expected, present = grid.window(model.start, sim.scenario.max_steps + 1)
        for step in range(60):
            here = sim.human_positions
            shown = np.abs(here - PARKING) > 1e6  # parked places wait near PARKING
            assert np.array_equal(np.sort(here[shown]), np.sort(expected[step][present[step]] + 0.5))
            assert sim.human_stopped.all()  # no command, goal rule or stall check touches them
            seen.add(int(shown.sum()))
            sim.step(np.zeros(2))
    assert {1, 2}.issubset(seen)  # people came and went within the windows


def test_recorded_velocities_are_the_steps_between_positions(recording):
    sim = Simulator("open_space", _replay(recording))
    sim.reset(seed=3)
    before = sim.human_positions.copy()
    velocities = sim.human_velocities.copy()
    sim.step(np.zeros(2))
    both = (np.abs(before - PARKING) > 1e6) & (np.abs(sim.human_positions - PARKING) > 1e6)
    assert both.any()
    assert np.allclose(before[both] + velocities[both] * sim.dt, sim.human_positions[both])


def test_the_seed_chooses_the_window(recording):
    sim = Simulator("open_space", _replay(recording))
    starts = []
    for seed in range(8):
        sim.reset(seed=seed)
        starts.append(sim.crowd.models["replay"].start)
    again = Simulator("open_space", _replay(recording))
    for seed, start in enumerate(starts):
        again.reset(seed=seed)
        assert again.crowd.models["replay"].start == start
    assert len(set(starts)) > 4


def test_batched_replay_worlds_equal_single_simulators_bit_for_bit(recording):
    check_batch_equals_singles(load_world("open_space", {**_replay(recording), "max_steps": 40}), worlds=3, first_seed=5, steps=90,
                               rng_seed=6, scale=1.0)


def test_a_relative_recording_is_read_beside_the_scenario_file_and_may_not_leave_its_folder(tmp_path, recording):
    scenario = (tmp_path / "scenario.yaml")
    source = (load_world("open_space").source.label)
    text = open(source, encoding="utf-8").read().replace("  count: 5\n", "  count: 3\n  model: replay\n  replay: {file: walk.txt}\n")
    scenario.write_text(text)
    sim = Simulator(str(scenario))
    sim.reset(seed=0)
    inner = tmp_path / "inner"
    inner.mkdir()
    (inner / "scenario.yaml").write_text(text.replace("walk.txt", "../walk.txt"))
    with pytest.raises(ScenarioError, match=r"humans.replay.file: .*must stay inside") as error:
        Simulator(str(inner / "scenario.yaml"))
    assert "\n" not in str(error.value)


def test_what_replay_needs_is_refused_in_one_line(recording):
    with pytest.raises(ScenarioError, match="model replay needs a recording: add humans.replay"):
        load_world("open_space", {"humans.model": "replay"})
    with pytest.raises(ScenarioError, match="humans.count: the replaying group's count is its number of places"):
        load_world("open_space", {**_replay(recording), "humans.count": [2, 3]})
    with pytest.raises(ScenarioError, match=r"humans.count: model replay: the recording .* needs 3 places .*expected count >= 3"):
        Simulator("open_space", {**_replay(recording), "humans.count": 2})


def native_equals_sync(overrides: dict, check_finite: bool = False) -> int:
    """Steps the native vector env and gymnasium's sync one side by side on ``overrides``; returns the episode ends seen."""
    import gymnasium as gym

    import crowdnav  # noqa: F401  (registers the ids)

    options = {"num_envs": 3, "modalities": ["goal", "humans", "lidar"], "overrides": {**overrides, "max_steps": 30}}
    native = gym.make_vec("crowdnav/OpenSpace-v0", vectorization_mode="vector_entry_point", **options)
    sync = gym.make_vec("crowdnav/OpenSpace-v0", vectorization_mode="sync", **options)
    first, second = native.reset(seed=3), sync.reset(seed=3)
    assert all(np.array_equal(first[0][key], second[0][key]) for key in first[0])
    rng, ends = np.random.default_rng(3), 0
    for _ in range(70):
        actions = rng.uniform(-1, 1, (3, 2)).astype(np.float32)
        mine, theirs = native.step(actions), sync.step(actions)
        assert all(mine[0][key].tobytes() == theirs[0][key].tobytes() for key in mine[0])
        if check_finite:
            assert all(np.isfinite(mine[0][key]).all() for key in mine[0])  # parked places are out of every sensor's range
        assert mine[1].tobytes() == theirs[1].tobytes() and (mine[2] == theirs[2]).all() and (mine[3] == theirs[3]).all()
        ends += int((mine[2] | mine[3]).sum())
    return ends


def test_the_native_vector_env_with_a_recorded_crowd_equals_the_sync_one(recording):
    ends = native_equals_sync(_replay(recording), check_finite=True)
    assert ends > 0  # resets happened inside the comparison


def test_empty_places_are_nobody_to_the_global_state_and_the_planners_estimate(recording):
    from crowdnav.envs.multi_agent import STATE_COLUMNS, global_state
    from crowdnav.planning.predictive import CrowdEstimate

    sim = Simulator("open_space", _replay(recording))
    sim.reset(seed=0)
    for _ in range(60):  # until a place is empty and another held
        shown = np.abs(sim.human_positions - PARKING) > 1e6
        if shown.any() and not shown.all():
            break
        sim.step(np.zeros(2))
    assert shown.any() and not shown.all()
    table = global_state(sim, sim.max_humans).reshape(-1, len(STATE_COLUMNS))[1:]
    assert (table[~shown] == 0).all() and (table[shown, 7] == 1).all()  # an empty place's row: zero, inactive
    assert np.array_equal(CrowdEstimate.from_sim(sim.robot_view(0)).present[0], shown)
