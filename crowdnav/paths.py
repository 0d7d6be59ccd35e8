"""Names that become file or folder names, and output paths that stay inside their folder.

One folder-safe pattern for every user-given name that ends up in a path (scenario names in
video file names, experiment and configuration names in results folders), and one check that a
path built under an output folder resolves inside it, after ``..`` and symlinks.
"""

from __future__ import annotations

import re
from pathlib import Path

from crowdnav.errors import CrowdNavError

SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,127}$")
SAFE_NAME_EXPECTATION = "a name of 1-128 letters, digits, '_', '.' or '-' starting with a letter or digit (it becomes part of file names)"


class OutputPathError(CrowdNavError, ValueError):
    """A path built under an output folder would land outside it."""


def is_safe_name(name: object) -> bool:
    """Whether ``name`` can be used as a file or folder name on its own (no separators, no ``..``)."""
    return isinstance(name, str) and SAFE_NAME.match(name) is not None


def safe_stem(stem: str) -> str:
    """A folder-safe name derived from a file's stem (``my room.yaml`` -> ``my_room``)."""
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", stem).lstrip("._-")[:128]
    return name or "scenario"


def inside(folder: str | Path, name: str) -> Path:
    """``folder / name``, refused unless it resolves inside ``folder`` (``..``, absolute names, symlinks)."""
    root = Path(folder).resolve()
    path = (root / name).resolve()
    if path == root or not path.is_relative_to(root):
        raise OutputPathError(f"{name!r} would be written to {path}, outside the output folder {root}")
    return path
