"""Every Python and shell example in README.md and docs/ runs as written, so a stale snippet turns CI red.

Each documentation file's fenced ``python`` and ``bash`` blocks run in order, in a fresh folder
that holds the files the examples refer to (``my_room.yaml``: the minimal scenario of
docs/scenarios.md; ``my_scenarios/lab.yaml``; ``my_policies.py``: the callable of
docs/evaluate.md; ``ewap_dataset/seq_eth/obsmat.txt``: a synthetic recording for the replay
recipe). Python blocks of one file share a namespace; shell commands must exit 0.

A block is marked by an HTML comment on the line before its fence:
``<!-- docs-test: slow -->`` (minutes of training: it runs with ``pytest -m slow``) or
``<!-- docs-test: skip: REASON -->`` (a cluster, a fresh machine, a fragment). The default suite
runs every unmarked block.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.cli.test_recording_cli import write_recording
from tests.paths import REPO

ROOT = REPO
FILES = ["README.md", *sorted(str(path.relative_to(ROOT)) for path in (ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"(?:<!-- docs-test: (?P<mark>slow|skip)(?::[^>]*)? -->\n)?```(?P<lang>python|bash)\n(?P<code>.*?)```", re.S)


def blocks(file: str) -> list[tuple[str, str, str | None, int]]:
    """(language, code, mark, line) of every python/bash block of ``file``."""
    text = (ROOT / file).read_text(encoding="utf-8")
    return [(m["lang"], m["code"], m["mark"], text[: m.start()].count("\n") + 1) for m in FENCE.finditer(text)]


def commands(code: str) -> list[str]:
    """The shell commands of a bash block: continuation lines joined, comments and blank lines dropped."""
    joined = code.replace("\\\n", " ")
    return [line.split("  #")[0].split(" # ")[0].strip() for line in joined.splitlines() if line.strip() and not line.lstrip().startswith("#")]


def workdir(tmp_path: Path) -> Path:
    """A folder with the files the examples refer to, made from the docs themselves where they show them."""
    scenarios = (ROOT / "docs" / "scenarios.md").read_text(encoding="utf-8")
    minimal = re.search(r"## A minimal file.*?```yaml\n(.*?)```", scenarios, re.S)[1]
    (tmp_path / "my_room.yaml").write_text(minimal, encoding="utf-8")
    (tmp_path / "my_scenarios").mkdir()
    shutil.copy(ROOT / "scenarios" / "room_furniture.yaml", tmp_path / "my_scenarios" / "lab.yaml")
    evaluate = (ROOT / "docs" / "evaluate.md").read_text(encoding="utf-8")
    shutil.copytree(ROOT / "notebooks", tmp_path / "notebooks")  # the docs run it from the repository root
    (tmp_path / "my_policies.py").write_text(re.search(r"```python\n(import numpy as np\n\n\ndef toward_goal.*?)```", evaluate, re.S)[1])
    # docs/scenarios.md's replay recipe reads an ETH recording, which cannot ship: a synthetic one in its layout and place
    (tmp_path / "ewap_dataset" / "seq_eth").mkdir(parents=True)
    write_recording(tmp_path / "ewap_dataset" / "seq_eth" / "obsmat.txt", "obsmat")
    return tmp_path


def run_file(file: str, tmp_path: Path, monkeypatch, *, include_slow: bool) -> int:
    folder = workdir(tmp_path)
    monkeypatch.chdir(folder)
    # the examples register modalities (docs/sensors.md): on a copy of the registry, not the suite's
    monkeypatch.setattr("crowdnav.sensors.base.MODALITIES", dict(__import__("crowdnav.sensors.base", fromlist=["MODALITIES"]).MODALITIES))
    monkeypatch.syspath_prepend(str(folder))
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}", "PYTHONPATH": str(folder)}
    namespace: dict = {"__name__": "__docs__"}
    ran = 0
    for lang, code, mark, line in blocks(file):
        if mark == "skip" or (mark == "slow" and not include_slow):
            continue
        if lang == "python":
            exec(compile(code, f"{file}:{line}", "exec"), namespace)  # noqa: S102 - our own documentation
        else:
            for command in commands(code):
                done = subprocess.run(["bash", "-c", command], cwd=folder, env=env, capture_output=True, text=True, timeout=900)
                assert done.returncode == 0, f"{file}:{line}: `{command}` exited {done.returncode}:\n{done.stderr[-2000:]}"
        ran += 1
    return ran


@pytest.mark.parametrize("file", FILES)
def test_documentation_examples_run(file, tmp_path, monkeypatch):
    run_file(file, tmp_path, monkeypatch, include_slow=False)


@pytest.mark.slow
@pytest.mark.parametrize("file", [file for file in FILES if any(mark == "slow" for _, _, mark, _ in blocks(file))])
def test_documentation_examples_run_with_the_slow_ones(file, tmp_path, monkeypatch):
    run_file(file, tmp_path, monkeypatch, include_slow=True)


def test_every_skipped_block_says_why_and_most_blocks_run():
    texts = {file: (ROOT / file).read_text(encoding="utf-8") for file in FILES}
    assert not any(re.search(r"<!-- docs-test: skip -->", text) for text in texts.values()), "a skip needs a reason"
    marks = [mark for file in FILES for _, _, mark, _ in blocks(file)]
    assert marks.count(None) >= len(marks) // 2
