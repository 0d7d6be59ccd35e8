"""Error messages and help name an install line that works: crowdnav is on no package index, extras install from a clone."""

from __future__ import annotations

import re

from crowdnav.errors import install_line
from tests.paths import REPO

UNPUBLISHED = re.compile(r"pip3? install\s+(-U\s+)?['\"]?crowdnav\b|\bcrowdnav\[[a-z_,]+\]")
"""``pip install crowdnav``, ``pip install 'crowdnav[orca]'``, ``"crowdnav[ray]"``: the forms no index answers."""


def _offences() -> dict[str, list[str]]:
    found: dict[str, list[str]] = {}
    for folder in ("crowdnav", "agents", "evaluation", "benchmarks", ".ci"):
        for path in sorted((REPO / folder).rglob("*.py")):
            lines = [f"{number}: {line.strip()}" for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
                     if UNPUBLISHED.search(line)]
            if lines:
                found[str(path.relative_to(REPO))] = lines
    return found


def test_no_message_or_help_recommends_installing_crowdnav_from_an_index():
    offences = _offences()
    assert not offences, f"say {install_line('EXTRA')} instead (crowdnav.errors.install_line): {offences}"


def test_the_install_line_is_the_readmes():
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    for extra in ("orca", "train", "bench", "ray", "onnx", "tensorboard"):
        line = install_line(extra)
        assert line.startswith(f'pip install -e ".[{extra}]"') and f'`pip install -e ".[{extra}]"`' in readme
        assert not UNPUBLISHED.search(line)
    assert UNPUBLISHED.search("needs pip install 'crowdnav[orca]'") and UNPUBLISHED.search("pip install crowdnav")
