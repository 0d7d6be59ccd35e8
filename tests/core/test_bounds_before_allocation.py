"""Bounds before allocation (issue 49 item 3), the environment's part: each size an input asks for is counted and refused
in one line before anything of that size is allocated or read.

A recording's span on the time grid and its people's grids, the lines read from it (streamed,
never read whole), a replay episode's state (places x steps), the simulator's pair constants (the
last few crowd sizes kept, episodes unchanged bit for bit) and a walking group too big for its
region. The fresh-process memory checks of the command line are in
tests/cli/test_bounds_before_allocation_cli.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from crowdnav.batch.simulator import BatchSimulator
from crowdnav.crowd import recording
from crowdnav.crowd.recording import MAX_GRID_STEPS, RecordingError, read_recording
from crowdnav.crowd.replay import ReplayError, check_replay_state, places_needed
from crowdnav.scenario import ScenarioError
from crowdnav.scenario.crowd import MAX_REPLAY_CELLS
from crowdnav.sim.simulator import Simulator
from crowdnav.sim.state import CONSTANTS_KEPT, ConstantsCache
from crowdnav.worlds.compiled import load_world

FAR_APART = "0 1 0 0\n10 1 1 0\n20 1 2 0\n30 1 3 0\n2000000010 1 4 0\n"
"""Five rows whose frames span 0 to 2,000,000,010: 80,000,000 s at 0.4 s per 10 frames, 400 million steps of 0.2 s."""


def _one_line(error: pytest.ExceptionInfo[BaseException]) -> str:
    message = str(error.value)
    assert "\n" not in message
    return message


# ------------------------------------------------------------------------------------------------ recordings


def test_frames_two_billion_apart_are_refused_by_their_span_before_any_grid_is_allocated(tmp_path, monkeypatch):
    (tmp_path / "far.txt").write_text(FAR_APART)
    rec = read_recording(tmp_path / "far.txt")
    monkeypatch.setattr(np, "arange", None)  # nothing of the span's size may be built: arange is not even reached
    with pytest.raises(RecordingError) as error:
        rec.resample(0.2)
    message = _one_line(error)
    assert "far.txt" in message and "400,000,003 time steps of 0.2 s" in message and f"{MAX_GRID_STEPS:,}" in message


def test_the_positions_of_all_people_are_counted_before_the_first_persons_grid_is_built(tmp_path, monkeypatch):
    rows = "".join(f"{frame} {person} {frame / 25} {person}\n" for person in (1, 2) for frame in range(0, 101, 10))
    (tmp_path / "two.txt").write_text(rows)  # two people seen for 4 s each: 21 points each at 0.2 s
    rec = read_recording(tmp_path / "two.txt")
    assert sum(len(track.positions) for track in rec.resample(0.2).tracks) == 42
    monkeypatch.setattr(recording, "MAX_GRID_POINTS", 41)
    built: list[int] = []
    real_arange = np.arange
    monkeypatch.setattr(np, "arange", lambda *args, **kw: built.append(1) or real_arange(*args, **kw))
    with pytest.raises(RecordingError, match=r"two.txt: 42 positions at a time step of 0.2 s, more than 41"):
        rec.resample(0.2)
    assert built == []  # refused before the first person's grid


def test_64_mib_of_comment_lines_are_refused_at_the_line_bound_without_reading_the_file_whole(tmp_path, monkeypatch):
    path = tmp_path / "comments.txt"
    path.write_bytes(b"#\n" * 40 + b"0 1 0 0\n")
    monkeypatch.setattr(recording, "MAX_LINES", 30)
    with pytest.raises(RecordingError) as error:
        read_recording(path)
    assert _one_line(error).endswith("comments.txt:31: more than 30 lines; expected a smaller recording")


def test_one_line_longer_than_the_line_bound_is_refused_before_it_is_split(tmp_path, monkeypatch):
    path = tmp_path / "wide.txt"
    path.write_text("0 1 0 0\n" + "1 " * 200 + "\n")
    monkeypatch.setattr(recording, "MAX_LINE_BYTES", 100)
    with pytest.raises(RecordingError) as error:
        read_recording(path)
    assert "wide.txt:2: a line longer than 100 bytes" in _one_line(error)


def test_a_file_over_the_byte_bound_is_refused_from_its_size_before_a_line_is_read(tmp_path, monkeypatch):
    path = tmp_path / "big.txt"
    path.write_text("not a row at all\n" * 10)
    monkeypatch.setattr(recording, "MAX_BYTES", 100)
    with pytest.raises(RecordingError, match=r"big.txt: holds more than 100 bytes"):  # not "1 column": nothing was parsed
        read_recording(path)


def test_streamed_reading_keeps_line_numbers_crlf_lone_cr_and_a_byte_order_mark(tmp_path):
    path = tmp_path / "mixed.txt"
    path.write_bytes(b"\xef\xbb\xbf# header\r\n0 1 0 0\r\n10 1 1 0\r20 1 2 0\n\n30 1 x 0\n")
    with pytest.raises(RecordingError, match=r"mixed.txt:6: a column is not a number"):
        read_recording(path)
    path.write_bytes(b"# header\n0 1 0 0\n\xff\n")
    with pytest.raises(RecordingError, match=r"mixed.txt:3: not UTF-8 text"):
        read_recording(path)


def test_places_needed_counts_comings_and_goings_without_an_array_of_the_whole_span(tmp_path):
    rows = "0 1 0 0\n10 1 1 0\n10 2 0 1\n20 2 1 1\n40 3 0 2\n50 3 1 2\n"  # 1 and 2 overlap; 3 comes after a gap
    (tmp_path / "p.txt").write_text(rows)
    grid = read_recording(tmp_path / "p.txt").resample(0.4)
    dense = np.zeros(grid.steps + 2, dtype=np.int64)  # the former count, over every step of the span
    for track in grid.tracks:
        dense[track.start] += 1
        dense[track.start + len(track.positions) + 1] -= 1
    assert places_needed(grid) == int(np.cumsum(dense).max()) == 2


# ------------------------------------------------------------------------------------------------ replay episodes


def write_big_replay(folder: Path, flow: bool = False) -> Path:
    """A scenario replaying a 2-row recording with 2,000 places over 20,000 steps (``humans.count`` on line 5; 4 with ``flow``)."""
    (folder / "walk.txt").write_text("0 1 0 0\n10 1 1 0\n")
    scenario = folder / "big_replay.yaml"
    scenario.write_text("description: a replay too big for one episode\n"
                        "world: {min: [-5, -5], max: [5, 5]}\n"
                        "robot: {start: {type: rectangle, min: [-4, -4], max: [-3, -3]}, goal: {type: rectangle, min: [3, 3], max: [4, 4]}}\n"
                        + ("humans: {count: 2000, model: replay, replay: {file: walk.txt}}\n" if flow else
                           "humans:\n  count: 2000\n  model: replay\n  replay: {file: walk.txt}\n")
                        + "max_steps: 20000\n")
    return scenario


def test_a_replay_group_of_2000_places_over_20000_steps_is_refused_at_validation_naming_the_count(tmp_path):
    scenario = write_big_replay(tmp_path)
    with pytest.raises(ScenarioError) as error:
        load_world(str(scenario))
    message = _one_line(error)
    assert "big_replay.yaml:5" in message and "humans.count" in message and "40,002,000 (place, step) positions" in message
    assert f"{MAX_REPLAY_CELLS:,}" in message


def test_the_replay_model_checks_its_episode_state_itself_for_a_scenario_built_without_validation():
    check_replay_state(1_000, 1_999)  # 2,000,000 cells: the bound itself
    with pytest.raises(ReplayError) as error:
        check_replay_state(2_000, 20_000)
    assert "2,000 places x 20,001 steps is 40,002,000" in _one_line(error)


# ------------------------------------------------------------------------------------------------ pair constants


def test_the_constants_cache_keeps_the_most_recently_used_sizes_and_frees_the_oldest():
    built: list[tuple[int, bool]] = []
    cache = ConstantsCache(size=2)
    for n in (3, 5, 3, 7, 5):
        cache.get((n, False), lambda n=n: built.append((n, False)) or object())  # type: ignore[func-returns-value]
    assert [n for n, _ in built] == [3, 5, 7, 5] and len(cache) == 2  # 3 used again before 7 came: 5 was freed, then 3


def _episode(sim: Simulator, seed: int, steps: int = 25) -> bytes:
    sim.reset(seed=seed)
    trace = [sim.positions.tobytes()]
    for _ in range(steps):
        sim.step(np.array([0.6, 0.2]))
        trace.append(sim.positions.tobytes() + sim.velocities.tobytes())
    return b"".join(trace)


def test_a_crowd_of_varying_size_keeps_a_bounded_number_of_constants_and_plays_the_same_episodes_bit_for_bit():
    varying = {"humans.count": [1, 60]}
    fresh = [_episode(Simulator("open_space", varying), seed) for seed in (3, 4)]
    sim = Simulator("open_space", varying)
    first = _episode(sim, 3)
    sizes = set()
    for seed in range(100, 160):  # other crowd sizes push the first episode's constants out
        sim.reset(seed=seed)
        sizes.add(sim.n_humans)
        assert len(sim._constants) <= CONSTANTS_KEPT
    assert len(sizes) > 2 * CONSTANTS_KEPT  # a cache per size would have grown past the bound
    assert first == fresh[0] and _episode(sim, 3) == fresh[0] and _episode(sim, 4) == fresh[1]


def test_the_batched_worlds_share_one_bounded_cache_of_constants():
    batch = BatchSimulator(load_world("open_space", {"humans.count": [1, 60]}), 4)
    for round_ in range(10):
        batch.reset(range(4), [4 * round_ + k for k in range(4)])
    caches = {id(slot._constants) for slot in batch.slots}
    assert len(caches) == 1 and len(batch.slots[0]._constants) <= CONSTANTS_KEPT


# ------------------------------------------------------------------------------------------------ walking groups


def test_a_walking_group_too_big_for_its_region_is_refused_with_its_size_not_as_covered_by_obstacles(tmp_path):
    scenario = tmp_path / "big_group.yaml"
    scenario.write_text("description: a walking group bigger than its region\n"
                        "world: {min: [0, 0], max: [10, 10]}\n"
                        "robot: {start: {type: rectangle, min: [1, 1], max: [2, 2]}, goal: {type: rectangle, min: [8, 8], max: [9, 9]}}\n"
                        "humans:\n  groups:\n"
                        "    - {name: walkers, count: 60, walk_together: true, goal_rule: mirror,\n"
                        "       spawn: [{type: rectangle, min: [3, 3], max: [7, 7]}]}\n")
    with pytest.raises(ScenarioError) as error:
        load_world(str(scenario))
    message = _one_line(error)
    assert "humans.groups.0.spawn.0" in message and "walking group of 60 members does not fit its region" in message
    assert "15.89 m across" in message and "covered by obstacles" not in message


def test_a_region_really_covered_by_an_obstacle_still_says_so_for_a_walking_group(tmp_path):
    scenario = tmp_path / "covered.yaml"
    scenario.write_text("description: a spawn region under a table\n"
                        "world: {min: [0, 0], max: [10, 10]}\n"
                        "robot: {start: {type: rectangle, min: [1, 1], max: [2, 2]}, goal: {type: rectangle, min: [8, 8], max: [9, 9]}}\n"
                        "furniture: [{type: rectangle, center: [5, 5], size: [2, 2]}]\n"
                        "humans:\n  groups:\n"
                        "    - {name: walkers, count: 3, walk_together: true, goal_rule: mirror,\n"
                        "       spawn: [{type: rectangle, min: [4.5, 4.5], max: [5.5, 5.5]}]}\n")
    with pytest.raises(ScenarioError, match="region is entirely covered by obstacles"):
        load_world(str(scenario))
