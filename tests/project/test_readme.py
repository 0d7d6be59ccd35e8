"""The README's Python examples run as written, and its two set-up commands are the ones CI uses."""

from __future__ import annotations

import re

from tests.paths import REPO

ROOT = REPO
README = (ROOT / "README.md").read_text(encoding="utf-8")


def test_readme_python_examples_run():
    blocks = re.findall(r"```python\n(.*?)```", README, re.S)
    assert len(blocks) >= 3
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, "README.md", "exec"), namespace)  # noqa: S102 - running our own documentation


def test_ci_runs_the_readme_install_and_test_commands():
    bash_blocks = re.findall(r"```bash\n(.*?)```", README, re.S)
    install, tests = bash_blocks[0].strip(), bash_blocks[1].strip()
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    install_step = install.split(" && crowdnav ")[0].split(" && python benchmarks")[0]
    assert install_step in ci, "CI must install exactly as the README says"
    assert tests.split("&& ")[-1] in ci, "CI must run the README's test command"
