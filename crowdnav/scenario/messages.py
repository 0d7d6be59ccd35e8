"""Pydantic validation errors of a scenario, in the words of the scenario format.

The rewriting itself is shared by every configuration file kind (:mod:`crowdnav.config_errors`);
this module applies it to the :class:`~crowdnav.scenario.schema.Scenario` model.
"""

from __future__ import annotations

from typing import Any

from pydantic import ValidationError

from crowdnav.config_errors import validation_issues
from crowdnav.scenario.errors import ScenarioIssue
from crowdnav.scenario.schema import Scenario


def schema_issues(error: ValidationError, document: dict[str, Any]) -> list[ScenarioIssue]:
    """One issue per document path; alternatives for the same path are joined with '; or'."""
    return validation_issues(error, document, Scenario)

