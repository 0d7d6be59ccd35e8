"""Where a result came from: the packages and the crowdnav commit that produced it.

Every results document (a run's ``meta.json``, ``crowdnav evaluate``'s and the baselines'
summaries) records both, so a number can be traced to the code and versions behind it.
"""

from __future__ import annotations

from pathlib import Path


def package_versions() -> dict[str, str]:
    """Versions of Python and of the packages a result depends on."""
    import platform
    from importlib import metadata

    versions = {"python": platform.python_version()}
    for name in ("crowdnav", "numpy", "torch", "stable-baselines3", "gymnasium", "shapely", "pandas"):
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def git_commit() -> str | None:
    """The commit of the crowdnav checkout (``+dirty`` with uncommitted changes), or None outside a git checkout."""
    import subprocess

    root = Path(__file__).resolve().parent.parent
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=10, check=True)
        status = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root, capture_output=True,
                                text=True, timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return None
    return commit.stdout.strip() + ("+dirty" if status.stdout.strip() else "")
