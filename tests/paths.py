"""Where the tests find the repository, wherever in tests/ they live."""

from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
"""The repository root (pyproject.toml, docs/, scenarios/)."""
