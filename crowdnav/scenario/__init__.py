"""Scenario files: schema, loading with precise errors, and the shipped library."""

from crowdnav.scenario.errors import ScenarioError, ScenarioIssue
from crowdnav.scenario.loader import load_scenario
from crowdnav.scenario.schema import Scenario

__all__ = ["Scenario", "ScenarioError", "ScenarioIssue", "load_scenario"]
