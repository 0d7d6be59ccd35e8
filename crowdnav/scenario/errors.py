"""The one exception a scenario author sees: every problem with file, field path, line and expectation."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


def show(value: Any) -> str:
    """A value as the YAML author wrote it (lists, not tuples), shortened for messages."""
    text = repr(list(value) if isinstance(value, tuple) else value)
    return text if len(text) <= 80 else text[:77] + "..."


@dataclass(frozen=True)
class ScenarioIssue:
    """One problem found in a scenario document."""

    path: str
    """Dotted location inside the document, e.g. ``humans.count`` ('' for the whole document)."""
    message: str
    """What is wrong and what was expected."""
    line: int | None = None
    """1-based line in the YAML file, when it can be found."""


class ScenarioError(ValueError):
    """A scenario file (or an override) is invalid; ``str()`` is the user-facing report."""

    def __init__(self, source: str, issues: list[ScenarioIssue]):
        self.source = source
        self.issues = list(issues)
        super().__init__(self.report())

    def report(self) -> str:
        lines = []
        for issue in self.issues:
            where = self.source if issue.line is None else f"{self.source}:{issue.line}"
            field = f" {issue.path}:" if issue.path else ""
            lines.append(f"{where}:{field} {issue.message}")
        return "\n".join(lines)
