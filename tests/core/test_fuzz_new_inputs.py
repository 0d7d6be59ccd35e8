"""Fuzzed and hostile input on the input paths that landed together (issue 36, Reliability 5):
the env options ``shield`` / ``residual`` and the ``plan`` modality, the planners (oracle,
predictive), the recording reader of ``humans.model: replay``, and walking groups / stalls in
scenario YAML.

What every test asserts: bad input is a one-line ValueError (a CrowdNavError where crowdnav
defines one) that names the field or file; a huge value is refused before anything large is
allocated (each probe runs under a 1 GiB address-space cap in a subprocess where that matters).
Hypothesis runs derandomized with a few examples, so each test stays well under 20 s.
"""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from crowdnav.envs import CrowdNavEnv
from crowdnav.envs.vector.env import CrowdNavVectorEnv
from crowdnav.errors import CrowdNavError
from crowdnav.planning.oracle import OraclePlanner, PlannerUnavailable
from crowdnav.planning.predictive import MAX_WINDOW_CELLS, PlannerSettings, PredictivePlanner
from crowdnav.planning.shield import shield_settings
from crowdnav.planning.static_map import MAX_MAP_CELLS, MapTooLarge

FUZZ = settings(max_examples=40, derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow])
BIG_WORLD = {"world.min": [-5000, -5000], "world.max": [5000, 5000]}


def one_line(error: BaseException) -> str:
    text = str(error)
    assert text and "\n" not in text and "Traceback" not in text, text
    return text


def run_capped(code: str, limit_mb: int = 1024, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    """``code`` in a fresh interpreter whose address space is capped: a giant allocation fails there, not here."""
    cap = f"import resource; resource.setrlimit(resource.RLIMIT_AS, ({limit_mb << 20}, {limit_mb << 20}))\n"
    return subprocess.run([sys.executable, "-c", cap + textwrap.dedent(code)], capture_output=True, text=True, timeout=timeout)


# ----------------------------------------------------------------- PlannerSettings and the shield option

SETTING_VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-10**12, 10**12), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=5), st.lists(st.integers(), max_size=2),
)


@FUZZ
@given(st.dictionaries(st.sampled_from(["horizon", "cells_per_step", "prediction", "human_margin", "static_margin",
                                        "map_spacing", "horizn", ""]), SETTING_VALUES, max_size=4))
def test_shield_option_mappings_give_settings_or_a_one_line_value_error(option):
    try:
        found = shield_settings(option)
    except ValueError as error:
        one_line(error)
        return
    assert isinstance(found, PlannerSettings)
    for name in ("horizon", "human_margin", "static_margin", "map_spacing"):
        value = getattr(found, name)
        assert not isinstance(value, bool) and math.isfinite(value) and value >= 0
    assert not isinstance(found.cells_per_step, bool) and 1 <= found.cells_per_step <= 8


@pytest.mark.parametrize("option", ["yes", 1, 0, 1.0, [True], ("horizon", 2.0), {"horizon": 2.0}.items()])
def test_shield_option_of_the_wrong_type_is_refused_naming_what_it_takes(option):
    with pytest.raises(ValueError, match="shield must be true, false or a mapping") as caught:
        shield_settings(option)
    one_line(caught.value)


@pytest.mark.parametrize("field", ["horizon", "human_margin", "static_margin", "map_spacing", "cells_per_step"])
def test_planner_settings_refuse_booleans_where_numbers_go(field):
    with pytest.raises(ValueError, match=field) as caught:  # True == 1 in Python: a 1 s horizon nobody asked for
        PlannerSettings(**{field: True})
    one_line(caught.value)


@pytest.mark.parametrize(("settings_", "dt"), [
    ({"horizon": 1e9}, 0.2), ({"horizon": 100.0, "cells_per_step": 8}, 0.2), ({"horizon": 1e300}, 0.2),
    ({"horizon": 3.0, "cells_per_step": 8}, 0.01),
])
def test_a_lattice_over_the_window_limit_is_refused_before_anything_is_allocated(settings_, dt):
    with pytest.raises(ValueError, match=f"over the limit of {MAX_WINDOW_CELLS:,} cells") as caught:
        PlannerSettings(**settings_).window(dt)
    one_line(caught.value)


def test_the_window_limit_leaves_room_for_the_documented_settings():
    assert PlannerSettings().window(0.2) == (10, 20)
    PlannerSettings(horizon=10.0).window(0.2)  # a long horizon at the default resolution
    PlannerSettings(horizon=2.0, cells_per_step=8).window(0.2)  # the finest lattice at the default horizon


@pytest.mark.parametrize("shield", [{"horizon": 1e9}, {"horizon": 100, "cells_per_step": 8}, {"map_spacing": 1e-6},
                                    {"map_spacing": 5e-324}])
def test_env_refuses_a_giant_shield_at_construction_in_one_line_under_a_memory_cap(shield):
    done = run_capped(f"""
        from crowdnav.envs import CrowdNavEnv
        from crowdnav.envs.vector.env import CrowdNavVectorEnv
        for make in (lambda: CrowdNavEnv("open_space", shield={shield!r}), lambda: CrowdNavVectorEnv("open_space", 2, shield={shield!r})):
            try:
                make()
            except ValueError as error:
                print(type(error).__name__, "|", error)
            else:
                print("ACCEPTED")
    """)
    lines = done.stdout.splitlines()
    assert done.returncode == 0 and len(lines) == 2, done.stdout + done.stderr
    assert all("over the" in line and "limit" in line and "Memory" not in line for line in lines), lines


@pytest.mark.parametrize("kind", ["shield", "plan"])
def test_a_world_too_large_for_the_planners_maps_is_refused_at_construction(kind):
    options = {"shield": True} if kind == "shield" else {"modalities": ["plan", "goal"]}
    with pytest.raises(ValueError, match=f"limit of {MAX_MAP_CELLS:,}") as caught:
        CrowdNavEnv("open_space", overrides=BIG_WORLD, **options)
    assert "10000 m x 10000 m" in one_line(caught.value)


def test_predictive_baseline_refuses_a_world_too_large_for_its_maps_in_one_line():
    env = CrowdNavEnv("open_space", overrides=BIG_WORLD)
    env.reset(seed=0)
    with pytest.raises(MapTooLarge) as caught:
        PredictivePlanner()(env.simulator)
    assert isinstance(caught.value, CrowdNavError)
    one_line(caught.value)


@pytest.mark.parametrize(("oracle", "overrides"), [
    (OraclePlanner(cells_per_step=64), {}),  # a 3 mm lattice over a 10 m room for 150 steps
    (OraclePlanner(), {"max_steps": 100_000}),
    (OraclePlanner(), {"world.min": [-200, -200], "world.max": [200, 200]}),
])
def test_oracle_refuses_a_lattice_over_its_cell_limit_before_playing_the_crowd_forward(oracle, overrides):
    env = CrowdNavEnv("open_space", overrides={"humans.see_robot": False, **overrides})
    env.reset(seed=0)
    with pytest.raises(PlannerUnavailable, match="limit of") as caught:
        oracle(env.simulator)
    one_line(caught.value)


@pytest.mark.parametrize("residual", ["yes", 1, None, 0.0, [True]])
def test_residual_option_must_be_a_boolean(residual):
    for make in (lambda: CrowdNavEnv("open_space", modalities=["plan", "goal"], residual=residual),
                 lambda: CrowdNavVectorEnv("open_space", 2, modalities=["plan", "goal"], residual=residual)):
        with pytest.raises(ValueError, match="residual must be true or false") as caught:
            make()
        one_line(caught.value)


def test_residual_without_the_plan_modality_names_the_missing_key():
    with pytest.raises(ValueError, match="must include plan") as caught:
        CrowdNavEnv("open_space", modalities=["goal"], residual=True)
    one_line(caught.value)


@pytest.mark.parametrize("scenario_overrides", [{"robot.kinematics": "unicycle", "robot.max_angular_speed": 1.0}])
def test_shield_and_plan_refuse_a_unicycle_robot_in_one_line(scenario_overrides):
    for options in ({"shield": True}, {"modalities": ["plan", "goal"]}):
        with pytest.raises(ValueError, match="holonomic") as caught:
            CrowdNavEnv("open_space", overrides=scenario_overrides, **options)
        one_line(caught.value)


@FUZZ
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=2, max_size=2))
def test_a_shielded_residual_env_refuses_non_finite_actions_and_keeps_stepping(action):
    env = _shielded_residual_env()
    try:
        _, reward, _, _, info = env.step(np.array(action, dtype=np.float32))
    except ValueError as error:
        assert not all(math.isfinite(a) for a in action)
        one_line(error)
        return
    assert math.isfinite(reward) and isinstance(info["shielded"], bool)
    assert np.isfinite(env.simulator.robot_position.real) and np.isfinite(env.simulator.robot_position.imag)


_ENV: list[CrowdNavEnv] = []


def _shielded_residual_env() -> CrowdNavEnv:
    """One env for every example (building one costs the maps); reset when its episode ends."""
    if not _ENV:
        _ENV.append(CrowdNavEnv("open_space", modalities=["plan", "goal"], shield=True, residual=True))
        _ENV[0].reset(seed=0)
    env = _ENV[0]
    if env.simulator.state.step_count >= env.scenario.max_steps - 1 or env.core._running is False:
        env.reset(seed=1)
    return env


# ----------------------------------------------------------------- recordings (humans.model: replay): the reader

from crowdnav.crowd.recording import MAX_BYTES, RecordingError, read_recording  # noqa: E402

GOOD_ROW = "0\t1\t0.5\t1.5"


@pytest.mark.parametrize(("name", "text", "expected"), [
    ("frames.txt", "0 1 0 0\n1000000000000000 1 1 1\n", None),  # frames far apart: once a 7 PiB bincount
    ("frames.txt", "0 1 1e300 0\n10 1 1e300 0\n", "beyond"),  # a position the simulator would square into inf
    ("frames.txt", "0 1 0 -1e7\n", "beyond"),
    ("eth.ndjson", '{"track": {"f": 0, "p": 1, "x": ' + "9" * 400 + ', "y": 0}}\n', "beyond"),  # an int with no float
    ("eth.ndjson", '{"scene": {"id": 0, "fps": ' + "9" * 400 + '}}\n{"track": {"f": 0, "p": 1, "x": 0, "y": 0}}\n', "fps"),
    ("eth.ndjson", '{"scene": {"id": 0, "fps": NaN}}\n', "fps"),
    ("eth.ndjson", '{"scene": {"id": 0, "fps": -2.5}}\n', "fps"),
    ("eth.ndjson", '{"track": {"f": 0, "p": 1, "x": NaN, "y": 0}}\n', "finite"),
    ("eth.ndjson", '{"track": {"f": 0.5, "p": 1, "x": 0, "y": 0}}\n', "whole numbers"),
    ("eth.ndjson", '{"track": {"f": 0, "p": true, "x": 0, "y": 0}}\n', "whole numbers"),
    ("eth.ndjson", '{"track": {"f": 0, "p": 1, "x": "0", "y": 0}}\n', "finite numbers"),
    ("eth.ndjson", "[" * 100_000 + "\n", "not a JSON object"),
    ("eth.ndjson", '{"track": {"f": 0, "p": 1, "x": 0, "y": 0}, "scene": {}}\n', "expected"),
    ("eth.ndjson", '{"person": {}}\n', "unknown line kind"),
    ("eth.ndjson", "", "no annotation"),
    ("frames.txt", "\n# only a comment\n\n", "no annotation"),
    ("frames.txt", "0 1 0\n", "3 columns"),
    ("frames.txt", "0 1 x 0\n", "not a number"),
    ("frames.txt", "0 1 inf 0\n", "not finite"),
    ("frames.txt", "0.5 1 0 0\n", "whole numbers"),
    ("frames.txt", "1e300 1 0 0\n", "whole numbers"),
    ("frames.txt", "0 1 0 0\n0 1 1 1\n", "two positions"),
    ("frames.txt", GOOD_ROW + "\n0 1 2 3 4\n", "5 columns"),
    ("obsmat.txt", "0 1 0 0 0 0 0\n", "7 columns"),
])
def test_malformed_or_extreme_recordings_read_or_fail_in_one_line_naming_file_and_line(tmp_path, name, text, expected):
    path = tmp_path / name
    path.write_text(text)
    done = run_capped(f"""
        from crowdnav.crowd.recording import RecordingError, read_recording
        try:
            read_recording({str(path)!r})
        except RecordingError as error:
            print("REFUSED", error)
        else:
            print("READ")
    """, limit_mb=1024)
    out = done.stdout.strip()
    assert done.returncode == 0 and len(out.splitlines()) == 1, done.stdout + done.stderr
    if expected is None:
        assert out == "READ"
    else:
        assert out.startswith("REFUSED") and expected in out and name in out, out


def test_a_recording_that_is_not_utf8_a_folder_missing_or_too_big_is_refused(tmp_path):
    (tmp_path / "latin.txt").write_bytes(b"0 1 0 0\n0 2 \xe9 0\n")
    (tmp_path / "folder.txt").mkdir()
    with open(tmp_path / "huge.txt", "wb") as stream:  # sparse: no disk used
        stream.truncate(MAX_BYTES + 1)
    for name, words in [("latin.txt", "latin.txt:2: not UTF-8"), ("folder.txt", "not a regular file"),
                        ("missing.txt", "cannot read"), ("huge.txt", "more than")]:
        with pytest.raises(RecordingError, match=words) as caught:
            read_recording(tmp_path / name)
        one_line(caught.value)


def test_a_relative_recording_path_may_not_escape_the_naming_folder(tmp_path):
    inside = tmp_path / "scenarios"
    inside.mkdir()
    (tmp_path / "secret.txt").write_text(GOOD_ROW + "\n")
    (inside / "link.txt").symlink_to(tmp_path / "secret.txt")
    for escape in ("../secret.txt", "link.txt", "./../scenarios/../secret.txt"):
        with pytest.raises(RecordingError, match="must stay inside") as caught:
            read_recording(escape, folder=inside)
        one_line(caught.value)


ROW_TEXT = st.lists(st.one_of(
    st.tuples(st.integers(-5, 10**6), st.integers(-3, 3), st.floats(-1e7, 1e7), st.floats(-1e7, 1e7)).map(
        lambda r: "\t".join(map(repr, r))),
    st.text(alphabet="0123456789 .,-e\tnaif#\n{}[]\"", max_size=30),
), max_size=12)


@FUZZ
@given(ROW_TEXT, st.sampled_from(["auto", "frames", "obsmat", "trajnet"]))
def test_fuzzed_recordings_read_and_resample_or_fail_in_one_line(tmp_path_factory, rows, fmt):
    path = tmp_path_factory.mktemp("rec") / "walk.txt"
    path.write_text("\n".join(rows) + "\n")
    try:
        recording = read_recording(path, fmt)
    except RecordingError as error:
        assert "walk.txt" in one_line(error)
        return
    assert np.isfinite(recording.times).all() and np.isfinite(recording.positions).all()
    grid = recording.resample(0.25) if recording.duration < 1e5 else None
    if grid is not None:
        assert all(np.isfinite(track.positions).all() for track in grid.tracks)


# ----------------------------------------------------------------- walking groups and stalls in scenario YAML

from crowdnav.scenario import ScenarioError  # noqa: E402
from crowdnav.sim.simulator import Simulator  # noqa: E402

ODD = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=True, allow_infinity=True),
                st.just(1e300), st.just(-1e-300), st.text(max_size=4), st.lists(st.floats(-2, 2), max_size=3))


@settings(max_examples=30, derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.dictionaries(st.sampled_from(["humans.stall.time", "humans.stall.progress", "humans.stall.speed",
                                        "humans.group_force.gaze_strength", "humans.group_force.attraction_strength",
                                        "humans.group_force.attraction_spread", "humans.group_force.repulsion_strength",
                                        "humans.walk_together"]), ODD, min_size=1, max_size=3))
def test_stall_and_group_force_settings_load_and_step_finitely_or_fail_in_one_line_naming_the_field(overrides):
    try:
        sim = Simulator("station_hall", overrides)
    except ScenarioError as error:
        message = one_line(error) if "\n" not in str(error) else str(error).splitlines()[0]
        assert any(key.split(".")[-1] in str(error) for key in overrides), message
        return
    sim.reset(seed=0)
    for _ in range(5):
        sim.step(np.zeros(2))
    assert np.isfinite(sim.human_positions).all()
