"""Type-check crowdnav with mypy (configured in pyproject.toml: strict, agents and evaluation but for two checks).

The repository's agents/, evaluation/ and scenarios/ install as crowdnav.agents, crowdnav.evaluation
and crowdnav.scenarios ([tool.setuptools.package-dir]); mypy reads neither that mapping nor the
editable install's import hook. So this builds the installed layout as a tree of symbolic links
under build/typecheck/, runs mypy on it, and prints the errors with the repository's paths.
Extra arguments go to mypy. Exit status: mypy's.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TREE = ROOT / "build" / "typecheck"
MAPPED = {"agents": "agents", "evaluation": "evaluation", "scenarios": "scenarios"}
"""crowdnav.<name> -> the repository folder it installs from."""


def build_tree() -> None:
    if TREE.exists():
        shutil.rmtree(TREE)
    package = TREE / "crowdnav"
    package.mkdir(parents=True)
    for entry in (ROOT / "crowdnav").iterdir():
        if entry.name != "__pycache__":
            (package / entry.name).symlink_to(os.path.relpath(entry, package))
    for name, folder in MAPPED.items():
        (package / name).symlink_to(os.path.relpath(ROOT / folder, package))


def repository_path(line: str) -> str:
    """``crowdnav/agents/x.py:3: ...`` -> ``agents/x.py:3: ...`` (and the same for evaluation/, scenarios/)."""
    return re.sub(r"^crowdnav/(agents|evaluation|scenarios)/", lambda m: f"{MAPPED[m.group(1)]}/", line)


def main() -> int:
    build_tree()
    command = [sys.executable, "-m", "mypy", "--config-file", str(ROOT / "pyproject.toml"),
               "--cache-dir", str(ROOT / "build" / "mypy_cache"), "-p", "crowdnav", *sys.argv[1:]]
    result = subprocess.run(command, cwd=TREE, capture_output=True, text=True)
    for line in (result.stdout + result.stderr).splitlines():
        print(repository_path(line))
    return result.returncode


if __name__ == "__main__":
    sys.exit(main())
