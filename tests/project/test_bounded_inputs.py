"""Every input path has the limits of a file: ``--set`` values, override paths and values, env
options, training-config overrides, special files and odd encodings are refused in one line and
in well under a second; numbers are read the YAML 1.2 way.
"""

from __future__ import annotations

import os
import re
import time

import pytest
from crowdnav.agents.training.config import ConfigError, load_config
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from crowdnav import ScenarioError
from crowdnav.cli import main
from crowdnav.cli.common import CliError, parse_overrides
from crowdnav.envs.core import load_env_world
from crowdnav.envs.single import CrowdNavEnv
from crowdnav.envs.vector.env import CrowdNavVectorEnv
from crowdnav.worlds.placement import PlacementError
from crowdnav.yaml_input import MAX_DEPTH, YamlLimitError, check_value, parse_value, read_text_file

ALIAS_BOMB = "{" + ", ".join(
    [f"a: &a [{', '.join(['lol'] * 9)}]"]
    + [f"{name}: &{name} [{', '.join([f'*{prev}'] * 9)}]" for prev, name in zip("abcdefgh", "bcdefghi", strict=True)]
) + "}"


def _one_line_error(capsys, *argv: str) -> str:
    started = time.perf_counter()
    code = main(list(argv))
    elapsed = time.perf_counter() - started
    err = capsys.readouterr().err
    assert code == 1 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert elapsed < 5  # generous for a loaded machine: the point is seconds, not the 61 s an expanded bomb took
    return err


@pytest.mark.parametrize("value, expected", [
    (ALIAS_BOMB, "the value holds more than 100,000 values once its aliases are expanded"),
    ("[" * 5000, "not valid YAML"),
    ("[" * 100 + "]" * 100, "the value is nested 65 levels deep; expected at most 64"),
    ("!!int 31e-6", "the value holds a value its explicit tag (such as !!int) cannot read"),  # found by the fuzzing below
    ("!!int ", "the value holds a value its explicit tag (such as !!int) cannot read"),  # an empty tagged value (PyYAML IndexError)
    ("!!float ", "the value holds a value its explicit tag (such as !!int) cannot read"),
])
def test_set_value_bombs_and_deep_nesting_are_refused_in_one_line(capsys, value, expected):
    assert len(ALIAS_BOMB) < 500  # a few hundred bytes that expand to 387 million values
    err = _one_line_error(capsys, "scenario", "validate", "open_space", "--set", f"description={value}")
    assert expected in err and err.startswith("crowdnav: error: --set 'description'"), err


def test_a_five_thousand_part_override_path_is_one_line_naming_the_limit(capsys):
    err = _one_line_error(capsys, "scenario", "validate", "open_space", "--set", "a." * 5000 + "b=1")
    assert f"expected at most 1,000 characters and {MAX_DEPTH} parts" in err


@pytest.mark.parametrize("text, value", [
    ("1e-6", 1e-6), ("2.5E3", 2500.0), (".5", 0.5), ("-3", -3), ("+4", 4), ("0", 0), (".inf", float("inf")),
    ("010", "010"), ("2:30", "2:30"), ("0x1F", "0x1F"), ("1_000", "1_000"), ("2024-01-01", "2024-01-01"),
])
def test_numbers_are_read_the_yaml_1_2_way(text, value):
    parsed = parse_value(text)
    assert parsed == value and type(parsed) is type(value)


def test_set_accepts_an_exponent_and_refuses_yaml_1_1_integers_in_one_line(capsys):
    assert parse_overrides(["time_step=1e-1"]) == {"time_step": 0.1}
    assert main(["scenario", "validate", "open_space", "--set", "time_step=1e-1"]) == 0
    capsys.readouterr()
    for written in ("010", "2:30"):
        err = _one_line_error(capsys, "scenario", "validate", "open_space", "--set", f"humans.count={written}")
        assert "humans.count: expected a whole number of humans" in err and f"got '{written}'" in err


def test_yaml_1_1_integers_in_a_scenario_file_are_refused_not_reinterpreted(tmp_path):
    path = tmp_path / "octal.yaml"
    path.write_text("world: {min: [0, 0], max: [10, 10]}\nrobot:\n  max_speed: 1.0\nhumans: {count: 010}\n")
    with pytest.raises(ScenarioError, match=r"octal.yaml:4: humans.count: .*got '010'"):
        load_env_world(str(path), {})


def test_override_values_from_python_are_bounded_like_files():
    shared = [0.0] * 10
    for _ in range(6):
        shared = [shared] * 10  # a million values by reference, expanded by validation or copying
    deep: dict = {}
    node = deep
    for _ in range(5000):
        node["a"] = {}
        node = node["a"]
    cyclic: list = []
    cyclic.append(cyclic)
    for value, expected in ((shared, "more than 100,000 values"), (deep, "nested more than 64 levels"), (cyclic, "contains itself")):
        with pytest.raises(ScenarioError, match=expected) as caught:
            load_env_world("open_space", {"description": value})
        assert len(str(caught.value).splitlines()) == 1
        with pytest.raises(ValueError, match=expected):
            CrowdNavEnv("open_space", sensors={"lidar": value})
        with pytest.raises(ConfigError, match=expected):
            load_config(None, {"overrides": value})


def test_a_mapping_source_is_bounded_before_it_is_copied():
    deep: dict = {}
    node = deep
    for _ in range(5000):
        node["a"] = {}
        node = node["a"]
    with pytest.raises(ScenarioError, match="<mapping>: the scenario mapping is nested more than 64 levels"):
        load_env_world({"description": deep}, {})


def test_shared_values_within_the_limits_are_accepted():
    row = [1.0, 2.0]
    check_value({"a": [row] * 100, "b": row})  # a value used twice is fine


def test_num_envs_and_sizes_are_refused_up_front():
    started = time.perf_counter()
    with pytest.raises(ValueError, match="num_envs must be an integer from 1 to 4,096, got 1000000000000"):
        CrowdNavVectorEnv("open_space", 10**12)
    with pytest.raises(ValueError, match="agents; expected at most 2,000,000"):
        CrowdNavVectorEnv("open_space", 4096, overrides={"world.max": [100, 100], "humans.count": 1000,
                                                         "humans.spawn": [{"type": "rectangle", "min": [1, 1], "max": [99, 99]}]})
    assert time.perf_counter() - started < 30
    for override, expected in (({"num_envs": 10**12}, "num_envs: expected an integer <= 4096"),
                               ({"net_arch": [20000, 20000]}, "net_arch.0: expected an integer <= 4096"),
                               ({"net_arch": [8] * 17}, "net_arch: expected at most 16 items"),
                               ({"buffer_size": 10**12}, "buffer_size: expected an integer <= 10000000")):
        with pytest.raises(ConfigError, match=expected):
            load_config(None, override)


@pytest.fixture
def odd_files(tmp_path):
    fifo = tmp_path / "pipe.yaml"
    os.mkfifo(fifo)
    (tmp_path / "utf16.yaml").write_bytes("name: x\n".encode("utf-16"))
    (tmp_path / "utf16le.yaml").write_bytes("name: x\n".encode("utf-16-le"))
    (tmp_path / "latin1.yaml").write_bytes("name: x\ndescription: caf\xe9\n".encode("latin-1"))
    return {
        str(fifo): "is a FIFO (named pipe), not a regular file",
        "/dev/zero": "is a device, not a regular file",
        str(tmp_path): "is a directory",
        str(tmp_path / "utf16.yaml"): "is UTF-16 text; expected UTF-8",
        str(tmp_path / "utf16le.yaml"): "holds NUL bytes: not UTF-8 text",
        str(tmp_path / "latin1.yaml"): "is not UTF-8 text (byte 0xe9 at offset 24)",
    }


def test_special_files_and_odd_encodings_get_one_line_saying_what_they_are(odd_files):
    for path, expected in odd_files.items():
        with pytest.raises(YamlLimitError, match=re.escape(expected)):
            read_text_file(path)
        for load, error in ((lambda p: load_env_world(p, {}), ScenarioError), (load_config, ConfigError)):
            with pytest.raises(error) as caught:
                load(path)
            message = str(caught.value)
            assert path in message and (expected in message or "directory" in message) and len(message.splitlines()) == 1


def test_a_utf8_byte_order_mark_is_accepted(tmp_path):
    path = tmp_path / "bom.yaml"
    path.write_bytes(b"\xef\xbb\xbfscenario: open_space\n")
    assert load_config(path).scenario == "open_space"


# ------------------------------------------------------------------ fuzzing --set values

SCENARIO_PATHS = ["humans.count", "humans.radius", "time_step", "robot.max_speed", "robot.start", "world.max", "description",
                  "humans.spawn.0", "walls", "sensors.lidar.beams", "humans.preferred_speed", "robot.start.radius", "max_steps"]
FRAGMENTS = ["1e-6", "010", "2:30", "0x10", ".inf", "-.nan", "&a [1, 2]", "*a", "[", "]", "{", "}", "!!python/object:os.system",
             "!!int 3", "!!int ",
             "!!float ", "~", "yes", "- 1", ": ", "'", '"', "#", "|", "\\x00", "\n", "\t", ",", "[1, 2]", "{type: circle}", "3", "0.5"]


@st.composite
def set_items(draw):
    path = draw(st.one_of(st.sampled_from(SCENARIO_PATHS), st.text(max_size=12),
                          st.lists(st.sampled_from(["a", "0", "humans", "count", ""]), max_size=80).map(".".join)))
    value = "".join(draw(st.lists(st.one_of(st.sampled_from(FRAGMENTS), st.text(max_size=4)), max_size=8)))
    return f"{path}={value}"


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(items=st.lists(set_items(), min_size=1, max_size=3))
def test_fuzzed_set_values_fail_in_one_line_or_give_a_world_that_resets(items):
    try:
        world, _ = load_env_world("open_space", parse_overrides(items))
    except CliError as error:
        assert len(str(error).splitlines()) == 1 and str(error).startswith("--set "), str(error)
        return
    except ScenarioError as error:  # one line per problem, each naming the file
        lines = str(error).splitlines()
        assert len(lines) == len(error.issues) and all(line.startswith(error.source + ":") for line in lines), str(error)
        return
    from crowdnav.sim.simulator import Simulator

    simulator = Simulator(world)
    for seed in range(3):
        try:
            simulator.reset(seed)
        except PlacementError as error:  # validate said OK, so reset must place
            pytest.fail(f"{items}: validated, then reset failed: {error}")


# ------------------------------------------------------------------ geometry cost

def _zigzag_floor(n: int) -> dict:
    xs = [1 + 98 * i / (n - 3) for i in range(n - 2)]
    points = [[x, 1.0 if i % 2 == 0 else 2.0] for i, x in enumerate(xs)] + [[99.0, 9.0], [1.0, 9.0]]
    return {"world.min": [0, 0], "world.max": [100, 10], "world.points": points,
            "robot.start": {"type": "rectangle", "min": [5, 5], "max": [6, 6]}, "robot.goal": {"type": "rectangle", "min": [90, 5], "max": [91, 6]},
            "humans.count": 0}


def _crossing_walls(n: int) -> dict:
    import numpy as np

    rng = np.random.default_rng(0)
    walls = [{"points": np.clip(rng.uniform(2, 98, 2) + rng.uniform(-15, 15, (6, 2)), 1, 99).tolist(), "thickness": 0.1} for _ in range(n)]
    return {"world.min": [0, 0], "world.max": [100, 100], "walls": walls, "humans.count": 0,
            "robot.start": {"type": "points", "points": [[0.5, 0.5]]}, "robot.goal": {"type": "points", "points": [[99.5, 99.5]]}}


@pytest.mark.parametrize("overrides, expected", [
    (_zigzag_floor(10_000), "world.points: the geometry has 10,000 vertices"),  # took 413 s and 7.6 GB
    (_crossing_walls(2_000), "walls: the geometry has 12,000 vertices"),  # took 338 s and 3.1 GB
    (_zigzag_floor(2_000), "world.points: more than 10,000 pairs of edges lie within"),
    (_crossing_walls(300), "more than 10,000 pairs of edges lie within"),
])
def test_costly_geometry_is_refused_up_front_naming_the_field(overrides, expected):
    started = time.perf_counter()
    with pytest.raises(ScenarioError, match=expected) as caught:
        load_env_world("open_space", overrides)
    assert len(str(caught.value).splitlines()) == 1 and time.perf_counter() - started < 5


def test_one_detailed_outline_padding_every_obstacle_is_refused():
    overrides = _zigzag_floor(900)
    overrides["furniture"] = [{"type": "rectangle", "center": [5.0 + i, y], "size": [0.1, 0.1]} for i in range(90) for y in (6, 8)]
    with pytest.raises(ScenarioError, match=r"world.points: 18\d obstacles padded to this one's 9\d\d edges make a table of 1\d\d,\d\d\d"):
        load_env_world("open_space", overrides)
