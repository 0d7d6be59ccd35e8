"""The ``crowdnav`` command line: scenario list, validate and schema."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import pytest

from crowdnav.cli import build_parser, main
from crowdnav.cli.common import CliError, format_table, parse_overrides, reward_options, reward_weight
from crowdnav.scenario.library import library_descriptions, library_dir, library_names
from crowdnav.scenario.reward_presets import REWARD_PRESETS, REWARD_TERMS
from crowdnav.scenario.schema import Scenario


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_scenario_list_shows_every_library_scenario_with_its_description(capsys):
    code, out, err = run(capsys, "scenario", "list")
    assert code == 0 and err == ""
    lines = out.splitlines()
    assert lines[0].split() == ["NAME", "DESCRIPTION"]
    listed = {line.split()[0]: line.split(None, 1)[1] for line in lines[1:]}
    assert listed == library_descriptions()
    assert set(listed) == set(library_names())


def test_scenario_schema_is_json_schema_of_the_scenario_model(capsys):
    code, out, _ = run(capsys, "scenario", "schema")
    assert code == 0
    schema = json.loads(out)
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert schema["title"] == "crowdnav scenario"
    assert set(schema["properties"]) == set(Scenario.model_fields)
    top_level = {"description", "world", "walls", "furniture", "robot", "humans", "time_step", "max_steps", "sensors", "reward"}
    assert top_level <= set(schema["properties"])
    assert schema["additionalProperties"] is False
    assert schema["required"] == ["description"]
    assert schema["oneOf"] == [{"required": ["robot"]}, {"required": ["robots"]}]  # one robot or several, exactly one way


def test_scenario_schema_output_option_writes_the_same_schema(tmp_path, capsys):
    target = tmp_path / "scenario.schema.json"
    code, out, err = run(capsys, "scenario", "schema", "--output", str(target))
    assert code == 0 and out == "" and str(target) in err
    _, printed, _ = run(capsys, "scenario", "schema")
    assert json.loads(target.read_text(encoding="utf-8")) == json.loads(printed)


def test_scenario_schema_unwritable_output_is_a_one_line_error(tmp_path, capsys):
    code, out, err = run(capsys, "scenario", "schema", "--output", str(tmp_path / "missing" / "schema.json"))
    assert code == 1 and out == ""
    assert err.startswith("crowdnav: error: cannot write") and err.count("\n") == 1


def test_scenario_validate_ok_for_library_names_and_files(capsys):
    file = library_dir() / "corridor.yaml"
    code, out, err = run(capsys, "scenario", "validate", "room_furniture", str(file))
    assert code == 0 and err == ""
    assert out.splitlines() == [f"OK {library_dir() / 'room_furniture.yaml'}", f"OK {file}"]


def test_scenario_validate_whole_library(capsys):
    code, out, _ = run(capsys, "scenario", "validate", *library_names())
    assert code == 0
    assert len(out.splitlines()) == len(library_names())


def test_scenario_validate_applies_set_overrides(capsys):
    code, out, err = run(capsys, "scenario", "validate", "open_space", "--set", "humans.count=[2, 500]")
    assert code == 1 and out == ""
    assert "humans.count:" in err and "asked for up to 500" in err and "(from override)" in err
    code, _, _ = run(capsys, "scenario", "validate", "open_space", "--set", "humans.count=3", "--set", "robot.max_speed=0.5")
    assert code == 0


def test_parse_overrides_reads_values_as_yaml():
    assert parse_overrides(["humans.count=20", "humans.preferred_speed=[0.5, 1]", "world.boundary_walls=false", "name=x=y"]) == {
        "humans.count": 20,
        "humans.preferred_speed": [0.5, 1],
        "world.boundary_walls": False,
        "name": "x=y",
    }
    with pytest.raises(CliError, match="PATH=VALUE"):
        parse_overrides(["humans.count"])
    with pytest.raises(CliError, match="not valid YAML"):
        parse_overrides(["humans.count=[1,"])


def test_bad_set_option_is_a_one_line_error(capsys):
    code, out, err = run(capsys, "scenario", "validate", "open_space", "--set", "nonsense")
    assert code == 1 and out == ""
    assert err == "crowdnav: error: --set expects PATH=VALUE, e.g. humans.count=20; got 'nonsense'\n"


@pytest.mark.parametrize("argv", [[], ["scenario"], ["scenario", "frobnicate"], ["scenario", "validate"]])
def test_usage_errors_exit_2_with_usage(capsys, argv):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert "usage: crowdnav" in err


def test_render_reward_flags_become_reward_weights():
    args = build_parser().parse_args(["render", "open_space", "--reward", "paper", "--reward-weight", "social=-50",
                                      "--reward-weight", "step=-1"])
    assert reward_options(args) == {"preset": "paper", "social": -50.0, "step": -1.0}
    assert reward_options(build_parser().parse_args(["render", "open_space"])) == {}


def test_reward_weight_values_are_checked_and_terms_listed():
    assert reward_weight(" goal_reached = 25 ") == ("goal_reached", 25.0)
    with pytest.raises(argparse.ArgumentTypeError, match="expected one of: step, goal_progress, social, goal_reached, collision"):
        reward_weight("colision=-1")
    with pytest.raises(argparse.ArgumentTypeError, match="finite number"):
        reward_weight("step=nan")


@pytest.mark.parametrize(("argv", "message", "listing", "names"), [
    (["--reward", "gentle"], "argument --reward: invalid choice: 'gentle'", "(choose from ", REWARD_PRESETS),
    (["--reward-weight", "speed=1"], "argument --reward-weight: unknown reward term 'speed'", "expected one of: ", REWARD_TERMS),
])
def test_render_unknown_reward_names_exit_2_listing_the_valid_ones(capsys, argv, message, listing, names):
    code, out, err = run(capsys, "render", "open_space", *argv)
    assert code == 2 and out == ""
    assert message in err and "Traceback" not in err
    valid = err.split(listing)[1].splitlines()[0]
    assert all(name in valid for name in names)


def test_help_exits_0(capsys):
    code, out, _ = run(capsys, "scenario", "--help")
    assert code == 0
    assert all(command in out for command in ("list", "validate", "schema"))


def test_command_groups_register_through_the_parser():
    parser = build_parser()
    args = parser.parse_args(["scenario", "validate", "x"])
    assert callable(args.handler) and args.scenarios == ["x"]


def test_format_table_aligns_columns():
    assert format_table(("A", "B"), [("long name", "x"), ("s", "y z")]).splitlines() == [
        "A          B",
        "long name  x",
        "s          y z",
    ]


def test_python_dash_m_crowdnav_runs_the_cli():
    result = subprocess.run(
        [sys.executable, "-m", "crowdnav", "scenario", "validate", "empty_room"], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("OK ") and result.stdout.strip().endswith("empty_room.yaml")


@pytest.mark.parametrize(("command", "missing", "extra"), [("train", "torch", "train"), ("benchmark", "torch", "bench"), ("benchmark", "ray", "ray")])
def test_command_of_a_missing_extra_names_the_extra_to_install(monkeypatch, capsys, command, missing, extra):
    """On the core install a command whose layer needs an extra exits 1 with the pip line, no traceback."""

    def handler(args):
        raise ModuleNotFoundError(f"No module named {missing!r}", name=missing)

    parser = build_parser()
    monkeypatch.setattr("crowdnav.cli.build_parser", lambda: parser)
    for action in parser._subparsers._group_actions[0].choices.values():
        action.set_defaults(handler=handler)
    assert main([command]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"crowdnav: error: `crowdnav {command}` needs {missing}")
    assert err.endswith(f'pip install -e ".[{extra}]" in crowdnav\'s clone')


def test_unrelated_missing_module_is_not_hidden(monkeypatch):
    def handler(args):
        raise ModuleNotFoundError("No module named 'nonexistent'", name="nonexistent")

    parser = build_parser()
    monkeypatch.setattr("crowdnav.cli.build_parser", lambda: parser)
    parser._subparsers._group_actions[0].choices["train"].set_defaults(handler=handler)
    with pytest.raises(ModuleNotFoundError):
        main(["train"])


def test_a_command_whose_extra_is_missing_stops_before_its_handler_starts(monkeypatch, capsys):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "pandas" else real(name, *a))
    started = []
    parser = build_parser()
    monkeypatch.setattr("crowdnav.cli.build_parser", lambda: parser)
    parser._subparsers._group_actions[0].choices["benchmark"].set_defaults(handler=lambda args: started.append(1) or 0)
    assert main(["benchmark"]) == 1 and not started
    assert capsys.readouterr().err.strip().endswith('needs pandas, which the core install leaves out: pip install -e ".[bench]" in crowdnav\'s clone')


def test_train_help_shows_the_config_defaults_and_set_merges_scenario_overrides(capsys, tmp_path):
    assert main(["train", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "RL algorithm (default: sac)" in text and "(default: lidar,goal)" in text and "--set PATH=VALUE" in text
    config = tmp_path / "c.yaml"
    config.write_text("overrides: {max_steps: 80}\n")
    assert main(["train", "--config", str(config), "--set", "humans.count=3", "--print-config"]) == 0
    printed = capsys.readouterr().out
    assert "humans.count: 3" in printed and "max_steps: 80" in printed


def test_benchmark_help_lists_every_shipped_experiment(capsys):
    from crowdnav.evaluation.experiment import shipped_experiments

    assert main(["benchmark", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert all(name in text for name in shipped_experiments()) and len(shipped_experiments()) >= 9


def test_scenario_describe_summarises_every_library_scenario_and_refuses_a_bad_one_in_one_line(capsys):
    from crowdnav.scenario.library import library_names

    for name in library_names():
        assert main(["scenario", "describe", name]) == 0
        out = capsys.readouterr().out
        assert out.startswith(f"{name}: ") and "world: " in out and "robot: " in out and "humans: up to " in out
    assert main(["scenario", "describe", "station_hall", "--set", "humans.groups.0.count=3"]) == 0
    assert "group commuters: 3 walk" in capsys.readouterr().out
    assert main(["scenario", "describe", "no_such_room"]) == 1
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_an_output_location_the_file_system_refuses_is_one_line_for_every_writing_command(tmp_path, capsys, monkeypatch):
    import errno
    import pathlib

    blocker = tmp_path / "a_file"
    blocker.write_text("")
    for argv in (["train", "--scenario", "open_space", "--modalities", "goal", "--episodes", "1", "--out", str(blocker / "run"),
                  "--no-progress"],
                 ["evaluate", "baseline:straight", "--scenario", "open_space", "--episodes", "1", "--out", str(blocker), "--no-progress"]):
        assert main(argv) == 1
        err = capsys.readouterr().err.strip()
        assert err.startswith("crowdnav: error: cannot write ") and "Not a directory" in err and err.count("\n") == 0

    def read_only(self, *args, **kwargs):  # what a read-only mount answers (root ignores permission bits, so simulate it)
        raise OSError(errno.EROFS, "Read-only file system", str(self))

    monkeypatch.setattr(pathlib.Path, "mkdir", read_only)
    assert main(["evaluate", "baseline:straight", "--scenario", "open_space", "--episodes", "1", "--out", str(tmp_path / "ro"),
                 "--no-progress"]) == 1
    assert "Read-only file system" in capsys.readouterr().err
