"""The top-level command prints any CrowdNavError a command lets through as one line; one schema command serves both spellings."""

from __future__ import annotations

import pytest

from crowdnav.cli import main
from crowdnav.cli import schema as schema_cli
from crowdnav.scenario import ScenarioError
from crowdnav.scenario.errors import ScenarioIssue
from crowdnav.sim.orca_solver import OrcaUnavailableError


@pytest.mark.parametrize("error", [
    OrcaUnavailableError("orca needs the optional package pyrvo: pip install -e \".[orca]\" in crowdnav's clone"),
    ScenarioError("my.yaml", [ScenarioIssue("humans.count", "expected a count"), ScenarioIssue("robot.radius", "expected a number > 0")]),
])
def test_a_crowdnav_error_a_command_lets_through_is_one_line_on_stderr_and_exit_status_1(monkeypatch, capsys, error):
    def fail(kind):
        raise error

    monkeypatch.setattr(schema_cli, "json_schema", fail)
    assert main(["schema", "scenario"]) == 1
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1 and captured.err.startswith("crowdnav: error: ")
    assert all(line.strip() in captured.err for line in str(error).splitlines())  # every issue kept, on the one line


def test_crowdnav_scenario_schema_is_the_same_command_as_crowdnav_schema_scenario(capsys, tmp_path):
    assert main(["schema", "scenario"]) == 0
    first = capsys.readouterr().out
    assert main(["scenario", "schema"]) == 0
    assert capsys.readouterr().out == first and '"title": "crowdnav scenario"' in first
    assert main(["scenario", "schema", "--output", str(tmp_path / "s.json")]) == 0
    assert (tmp_path / "s.json").read_text(encoding="utf-8") == first
