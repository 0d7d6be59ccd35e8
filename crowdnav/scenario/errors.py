"""The one exception a scenario author sees: every problem with file, field path, line and expectation.

Issues and their formatting are shared with the training and experiment configs
(:mod:`crowdnav.config_errors`).
"""

from __future__ import annotations

from crowdnav.config_errors import ConfigIssue, format_issues, show
from crowdnav.errors import CrowdNavError

__all__ = ["ScenarioError", "ScenarioIssue", "show"]

ScenarioIssue = ConfigIssue
"""One problem found in a scenario document (the shared :class:`~crowdnav.config_errors.ConfigIssue`)."""


class ScenarioError(CrowdNavError, ValueError):
    """A scenario file (or an override) is invalid; ``str()`` is the user-facing report."""

    def __init__(self, source: str, issues: list[ScenarioIssue]):
        self.source = source
        self.issues = list(issues)
        super().__init__(self.report())

    def report(self) -> str:
        return format_issues(self.source, self.issues)
